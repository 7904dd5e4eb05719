"""A streamed device's samples, taken on the thread that receives them.

A device that streams (the turret's CAN broadcasts, kOS notifications, U-Camera's
angle reports) calls :meth:`Device.notify_data` on its receive thread for each new
sample. Waking the controller's device thread to read and publish it put one more
thread hand-off, with its scheduling delay, between the frame and the subscriber
(issue 44 item 6: the turret's and Kessler's ``sim_to_subscriber`` p99 was 3.2-3.7x the
bare rclpy pub/sub p99, Capture's, taken on its reader, 1.6x). So the sample is read
from the device's receive cache and handed to the controller right there, as Capture's
reader hands on its poll (:meth:`Device.request_read`).

The device thread still owns the link and the pacing: the receive thread declines (and
wakes it) when it is not connected, a read raises, or the sample came sooner than the
publish period allows (the device thread publishes it once due, so a device streaming
at ``publish_rate`` with jitter keeps the rate); and the device thread reads itself
when no sample was taken for a while (a quiet stream: a silent node is found there).
One lock orders the two readers, so samples are taken in order and each once.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable

from gimbal_driver_common.device import Device, JointSample
from gimbal_driver_common.errors import GimbalError, LinkError, device_boundary

#: the rate cap is a virtual schedule (GCRA, the "leaky bucket" of ITU-T I.371): a slot
#: every PUBLISH_SPACING publish periods (up to 1/0.9 of publish_rate, as the cap always
#: allowed, so a device a little faster than publish_rate is not held back by drift),
#: and a sample may go PUBLISH_TOLERANCE periods before its slot, so one early after a late
#: one goes at once. The cap was "0.9 period after the last publication": the turret's
#: broadcasts, which reach the node 15 ms after one and 25 ms after the next at 50 Hz,
#: then waited about 3 ms each in the device thread's hold, half of them (the node's own
#: p99 4.7 ms; the bench's trace, bench/README.md). A schedule at exactly publish_rate
#: held every sample of a device streaming a hair faster by a growing share of a period
#: (U-Camera's p50 6.6 ms in a full bench).
PUBLISH_SPACING = 0.9
PUBLISH_TOLERANCE = 0.5


class StreamedSamples:
    """Reads and takes a streamed device's samples, at most ``publish_rate``."""

    def __init__(self, device: Device, take: Callable[[JointSample, float], bool],
                 taking: Callable[[], bool], period: Callable[[], float],
                 read_clock: Callable[[], float],
                 monotonic: Callable[[], float] = time.monotonic) -> None:
        """``take(sample, read_at)`` is the controller's (True: published); ``taking()``
        says whether the link is up for the receive thread; ``period()`` is the publish
        period; ``read_clock`` stamps a read for the stop confirmation; ``monotonic``
        paces (tests inject one)."""
        self.device = device
        self._take = take
        self._taking = taking
        self._period = period
        self._read_clock = read_clock
        self._monotonic = monotonic
        self._lock = threading.Lock()
        self._last_stamp: float | None = None
        #: the publish slot of the next sample on the publish_rate schedule (monotonic)
        self._slot = -math.inf
        #: when a sample was last taken, or the device thread last looked (monotonic)
        self.last_look = monotonic()

    def on_data(self) -> bool:
        """The receive thread's :meth:`Device.notify_data`: the latest sample taken here
        (True), or False: the device thread wakes and takes it (a sample too soon, which
        it publishes once due; the link down; a read that raised)."""
        if not self._taking():
            return False
        try:
            return self.take(when_due=True)
        except GimbalError:
            return False

    def hold(self) -> float:
        """Seconds until a sample may be published (<= 0: now): its slot on the schedule,
        less the tolerance."""
        return self._slot - PUBLISH_TOLERANCE * self._period() - self._monotonic()

    def take(self, when_due: bool = False) -> bool:
        """Read the latest sample and take it unless taken already; with ``when_due``,
        only once :meth:`hold` has passed (False: not yet). Raise GimbalError (the link's
        reason) for the device thread to handle."""
        with self._lock:
            if when_due and self.hold() > 0:
                return False
            with device_boundary():
                if not self.device.link_healthy():
                    raise LinkError('the client reports its link is down')
                read_at = self._read_clock()
                sample = self.device.read()
            now = self.last_look = self._monotonic()
            if sample is None or sample.stamp == self._last_stamp:
                return True
            self._last_stamp = sample.stamp
            if self._take(sample, read_at):
                self._slot = max(now, self._slot) + PUBLISH_SPACING * self._period()
            return True

    def wait(self, quiet: float) -> bool:
        """The device thread's wait: True when it should take a sample itself (woken,
        because the receive thread declined, or no sample taken for ``quiet`` s)."""
        woken = self.device.wait_for_data(max(self.last_look + quiet - self._monotonic(), 0.0))
        if woken:
            return True
        now = self._monotonic()
        if now - self.last_look < quiet:
            return False  # samples are coming in on the receive thread
        self.last_look = now
        return True
