"""Capture pedestal client (no ROS): the request/reply link (:class:`~.link.CaptureLink`:
handshake, requests, resync, the link lock) and the parts composed on it, each handed what
it uses:

- :attr:`CaptureClient.polls` (:class:`~.device_requests.Polls`): the requests the host
  makes on its own, not asked again once the device does not know them, backed off when
  unanswered;
- :attr:`CaptureClient.batch` (:class:`~.batch.BatchedReads`): several getters in one write;
- :attr:`CaptureClient.motion` (:class:`~.motion.MotionRequests`): the motion set-ups and
  the posted stream move;
- :attr:`CaptureClient.device_requests` (:class:`~.device_requests.DeviceRequests`):
  identity, registers, scans, presets, IMU, GPS, tracking, power, digital I/O.

The client keeps the old names as one-line delegates (the device adapter, probes and tests
call them), and the keep-alive thread: a background thread (:meth:`CaptureClient.start`)
sends COM_IsKeepAliveOn whenever the link has been idle for ``keepalive_period``.
"""

from __future__ import annotations

import contextlib
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from gimbal_driver_common.link_lock import LinkLock
from gimbal_driver_common.transport import ByteStream

from .batch import BatchedReads
from .device_requests import DeviceRequests, Identity, Polls, TrackingState
from .errors import CaptureError, DeviceNack
from .link import CaptureLink
from .motion import MotionRequests, PostedMoves, StopAnswers
from .protocol import GeoPoint, PresetRecord

#: the keep-alive thread's shortest sleep (after a ping)
KEEPALIVE_TICK_S = 0.05
#: its sleep while the link is down or has no keep-alive (the first ping is due only after
#: a period of idle link)
KEEPALIVE_IDLE_S = 1.0


class CaptureClient(CaptureLink):
    """Thread-safe session with one Capture controller over any :class:`ByteStream`: the
    link, with its parts as attributes."""

    def __init__(
        self,
        stream_factory: Callable[[], ByteStream],
        group: int = 0,
        timeout: float = 0.5,
        greeting_timeout: float = 0.5,
        expect_greeting: bool = True,
        keepalive_period: float = 0.0,
        keepalive_count: int = 3,
        resync_gap: float = 0.05,
        max_timeouts: int = 3,
        batch_reads: bool = True,
        link_lock: LinkLock | None = None,
    ) -> None:
        super().__init__(stream_factory, group=group, timeout=timeout,
                         greeting_timeout=greeting_timeout, expect_greeting=expect_greeting,
                         keepalive_period=keepalive_period, keepalive_count=keepalive_count,
                         resync_gap=resync_gap, max_timeouts=max_timeouts,
                         link_lock=link_lock)
        self.polls = Polls(self)
        self.batch = BatchedReads(self, self.polls, batch_reads)
        self.motion = MotionRequests(self, self.setups, self.polls, self.batch)
        self.device_requests = DeviceRequests(self, self.polls, self.batch, self.motion)
        self._worker: threading.Thread | None = None
        self._stop = threading.Event()

    # ------------------------------------------------------------ keep-alive
    def start(self) -> None:
        """Start the keep-alive thread (needed only with ``keepalive_period`` > 0)."""
        if self._worker is not None and self._worker.is_alive():
            return
        self._stop.clear()
        self._worker = threading.Thread(target=self._run, name='capture-keepalive', daemon=True)
        self._worker.start()

    def stop(self, send_disconnect: bool = False) -> None:
        self._stop.set()
        if self._worker is not None and self._worker is not threading.current_thread():
            self._worker.join(timeout=2.0)
        self._worker = None
        self.close(send_disconnect)

    def _run(self) -> None:
        """Ping the link once it has been idle for ``keepalive_period``. The thread sleeps
        until then, not in 50 ms ticks: while the joint poll keeps the link busy it wakes
        once a period (a 50 ms tick was 20 wake-ups a second, 0.13 % of a core, for
        nothing; issue 47)."""
        wait = KEEPALIVE_TICK_S
        while not self._stop.wait(wait):
            period = self.keepalive_period
            if not (self.connected and self.keepalive_on) or period <= 0:
                wait = min(period, KEEPALIVE_IDLE_S) if period > 0 else KEEPALIVE_IDLE_S
                continue
            idle_for = time.monotonic() - self.last_activity
            if idle_for < period:
                wait = max(period - idle_for, KEEPALIVE_TICK_S)
                continue
            wait = KEEPALIVE_TICK_S
            # asked directly, not as an optional poll: the ping is the supervision, and
            # the polls' back-off (1 s, doubling) after one lost answer would leave an
            # idle link silent past the controller's keepalive_count periods
            with contextlib.suppress(CaptureError):
                self.request('COM_IsKeepAliveOn', optional=True)

    # ------------------------------------------- the parts under their old names
    @property
    def batch_reads(self) -> bool:
        return self.batch.batch_reads

    @property
    def batching(self) -> bool:
        return self.batch.batching

    def read_many(self, reads: Sequence[tuple[str, int | None]],
                  optional: bool = False) -> list[Any]:
        return self.batch.read_many(reads, optional)

    def ask_many(self, reads: Sequence[tuple[str, int | None]],
                 on_values: Callable[[list[Any]], object]) -> bool:
        return self.batch.ask_many(reads, on_values)

    def explain_nack(self, exc: DeviceNack) -> DeviceNack:
        return self.polls.explain_nack(exc)

    def run(self, name: str, axis: int | None = None, value: Any = None) -> Any:
        return self.polls.run(name, axis, value)

    def poll(self, name: str, axis: int | None = None) -> Any:
        return self.polls.poll(name, axis)

    def optional(self, name: str, axis: int | None = None) -> Any:
        return self.polls.optional(name, axis)

    def move_absolute(self, axis: int, position_deg: float, speed_deg_s: float,
                      acceleration: float) -> None:
        self.motion.move_absolute(axis, position_deg, speed_deg_s, acceleration)

    def post_moves(self, moves: dict[int, tuple[float, float, float]]) -> PostedMoves | None:
        return self.motion.post_moves(moves)

    def settle_posted(self, posted: PostedMoves) -> bool:
        return self.motion.settle_posted(posted)

    def jog(self, axis: int, velocity_deg_s: float, acceleration: float) -> None:
        self.motion.jog(axis, velocity_deg_s, acceleration)

    def stop_axis(self, axis: int) -> None:
        self.motion.stop_axis(axis)

    def identity(self) -> Identity:
        return self.device_requests.identity()

    def read_axis(self, axis: int, with_current: bool = False) -> tuple[float, float, float | None]:
        return self.device_requests.read_axis(axis, with_current)

    def stop_all(self, axes: list[int]) -> StopAnswers:
        return self.device_requests.stop_all(axes)

    def stop_axes(self, axes: Sequence[int], programs: bool = False) -> StopAnswers:
        return self.motion.stop_axes(axes, programs)

    def reset_faults(self, axis: int) -> None:
        self.device_requests.reset_faults(axis)

    def registers(self, axis: int | None, also: Sequence[str] = ()) -> dict[str, Any]:
        return self.device_requests.registers(axis, also)

    def error_strings(self, csr: int) -> dict[str, str]:
        return self.device_requests.error_strings(csr)

    def configure_scan(self, yaw_min: float, yaw_max: float, pitch_min: float, steps: int,
                       step_height: float, speed: float) -> None:
        self.device_requests.configure_scan(yaw_min, yaw_max, pitch_min, steps, step_height,
                                            speed)

    def start_scan(self, pattern: str) -> None:
        self.device_requests.start_scan(pattern)

    def set_preset(self, index: int, name: str, angles: list[float]) -> None:
        self.device_requests.set_preset(index, name, angles)

    def get_preset(self, index: int) -> PresetRecord:
        return self.device_requests.get_preset(index)

    def preset_indices(self) -> list[int]:
        return self.device_requests.preset_indices()

    def imu(self) -> dict[str, float]:
        return self.device_requests.imu()

    def gps_fix(self) -> tuple[bool, float, float] | None:
        return self.device_requests.gps_fix()

    def goto_lla(self, target: int, point: GeoPoint) -> None:
        self.device_requests.goto_lla(target, point)

    def set_tracking(self, camera: int, mode: int) -> None:
        self.device_requests.set_tracking(camera, mode)

    def tracking_state(self, camera: int) -> TrackingState:
        return self.device_requests.tracking_state(camera)

    def set_axis_power(self, axis: int, on: bool) -> None:
        self.device_requests.set_axis_power(axis, on)

    def digital_io(self, numbers: list[int]) -> dict[int, bool]:
        return self.device_requests.digital_io(numbers)

    def set_digital_output(self, number: int, on: bool) -> None:
        self.device_requests.set_digital_output(number, on)

    def gps_heading(self) -> tuple[bool, float]:
        return self.device_requests.gps_heading()

    def stored_targets(self) -> dict[int, GeoPoint]:
        return self.device_requests.stored_targets()
