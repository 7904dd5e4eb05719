"""The device contract: what a driver implements so the controller can run it.

A device adapter wraps one client (the protocol code) and speaks in SI units
and REP-103 signs: every scale, sign and unit conversion happens here, never in
the node. Like python-can's ``BusABC`` the required surface is small (open,
read, move, jog, stop); everything a device may or may not have is a small
capability object in :class:`Capabilities` instead of a switch.

The controller calls a device from more than one thread (the device thread
polls while the command thread sends), so a device must be thread-safe; the
clients serialise requests on their own link lock.

What an adapter needs from above comes through this contract, never by importing the
controller or the policies: the controller calls :meth:`Device.attach` with its
configuration (joint names and the live limits, which runtime parameters change) and its
logger before it opens the link.
"""

from __future__ import annotations

import abc
import enum
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from gimbal_driver_common.config import ControllerConfig, Logger
from gimbal_driver_common.diagnostics import StatusPart
from gimbal_driver_common.errors import Unsupported
from gimbal_driver_common.link_lock import LinkLock
from gimbal_driver_common.periodic import Period
from gimbal_driver_common.scan import ScanRequest

if TYPE_CHECKING:  # the geodesy (pymap3d) is loaded only by the adapters that report a pose
    from gimbal_driver_common.geodesy import DevicePose, GeoPoint, GeoPose

#: joint -> (target position, max speed or None for the device default)
Moves = dict[str, tuple[float, float | None]]


class AxisStateCode(enum.IntEnum):
    """``gimbal_msgs/AxisState`` state values, for ROS-free adapters whose
    :meth:`StatusReport.axis_details` reports a ``state``."""

    UNKNOWN = 0
    IDLE = 1
    MOVING = 2
    JOGGING = 3
    HOMING = 4
    SCANNING = 5
    PLAYBACK = 6
    FAULT = 7
    DISABLED = 8


@dataclass
class DeviceInfo:
    """Identity read when the link opens; feeds hardware_id and ~/status."""

    model: str = ''
    serial_number: str = ''
    firmware_version: str = ''
    hardware_id: str = ''

    def __post_init__(self) -> None:
        if not self.hardware_id:
            self.hardware_id = self.serial_number or self.model or 'unknown'


@dataclass
class JointSample:
    """One reading of the joints, in SI units, keyed by joint name.

    ``stamp`` is the wall-clock time (``time.time()``) the data arrived.
    ``moving`` holds the device's own in-motion bits where it has them; the
    controller's one "moving" rule falls back to the velocity otherwise.
    ``currents`` is the motor current (A) of the joints whose device reports one: it is
    ``~/status`` ``current``, and reaches joint_states ``effort`` only as torque, through
    the ``torque_constants`` the user sets (ros/messages.py).
    """

    positions: dict[str, float]
    velocities: dict[str, float] = field(default_factory=dict)
    currents: dict[str, float] = field(default_factory=dict)
    stamp: float = field(default_factory=time.time)
    moving: dict[str, bool] = field(default_factory=dict)


class Homing(abc.ABC):
    """The device has a homing (index search) routine."""

    @abc.abstractmethod
    def home(
        self, joints: Sequence[str], report: Callable[[str], None], cancelled: threading.Event
    ) -> str:
        """Run it for ``joints``; report progress; return a message or raise GimbalError.

        ``cancelled`` is set when the wait must end: the goal was cancelled or a newer
        motion command (``~/stop``, a move, a preset, a scan) superseded the homing. Stop
        waiting then, but send nothing: the caller stops the axes on a cancel, and after a
        supersession a stop would undo the newer command.
        """


class DevicePresets(abc.ABC):
    """Preset slots stored in the device. Slots it does not handle fall back to the YAML store."""

    def handles(self, index: int) -> bool:
        """True for the slot indexes the device stores (default: all)."""
        return True

    @abc.abstractmethod
    def set(self, index: int, name: str, positions: dict[str, float] | None) -> str:
        """Store a slot: ``positions`` None means the device's current position."""

    @abc.abstractmethod
    def goto(self, index: int, speed: float) -> str:
        """Move to a stored slot (speed 0: the device default)."""

    def target(self, index: int) -> dict[str, float] | None:
        """Where :meth:`goto` of ``index`` moves the joints, when the driver knows it
        (it becomes the axes' ``target_position`` in ~/status); None: unknown."""
        return None

    @abc.abstractmethod
    def list(self) -> list[tuple[int, str, dict[str, float]]]:
        """The stored slots as (index, name, joint positions)."""

    @abc.abstractmethod
    def clear(self, index: int | None) -> str:
        """Clear one slot (None: every slot the device holds)."""


class DeviceScans(abc.ABC):
    """Scans the device runs itself; patterns it does not know run driver-side."""

    patterns: Sequence[str] = ()
    #: True when the device's whole stop (``Device.stop(None)``) already ends its scans:
    #: a stop of every axis (~/stop, a resent stop) then does not call :meth:`stop` after
    #: it, which would send the same stop twice (Capture's stop ends with SCN_StopScan)
    stopped_by_device_stop: bool = False

    @abc.abstractmethod
    def start(self, request: ScanRequest) -> str:
        """Start a device scan; return a message."""

    @abc.abstractmethod
    def stop(self) -> None:
        """Stop it (called by ~/stop_scan, ~/stop and every new motion command)."""


class StatusReport(abc.ABC):
    """Decoded device registers for /diagnostics and ~/status."""

    @abc.abstractmethod
    def parts(self) -> list[StatusPart]:
        """Diagnostics parts: one per axis plus the device; OK on a healthy device."""

    def mode(self) -> str:
        return ''

    def errors(self) -> list[str]:
        return []

    def axis_details(self, joint: str) -> dict[str, object]:
        """Extra AxisState fields for ``joint`` (state, calibrated, homed, active_errors).

        ``state`` may be given by name ('fault', 'disabled', 'playback', ...: AxisState's
        STATE_* without the prefix), so an adapter needs no ROS import.
        """
        return {}


class Geolocation(abc.ABC):
    """The device knows where it stands and which way it faces (GNSS, heading, attitude)."""

    @abc.abstractmethod
    def pose(self) -> DevicePose:
        """Position and orientation with their source, time and accuracy; a part the
        device does not know now is None with the reason in ``missing``. May ask the
        device (raise GimbalError when it cannot answer)."""


class TargetPointing(abc.ABC):
    """The device points at a geographic target itself (Capture GPS_SetTargetLLA +
    GPS_GoToTarget), from the pose it holds; ~/look_at_geo uses it like presets and scans
    use the device's own implementation, after checking the limits on its own solution."""

    def refusal(self, pose: GeoPose, speed: float) -> str | None:
        """Why the device's pointing cannot serve this goal (the pose is not the one the
        device aims from, it cannot take a speed), or None; the driver then moves itself."""
        return None

    @abc.abstractmethod
    def point_at(self, target: GeoPoint) -> str:
        """Send the target and start the device's own pointing; return a message."""


@dataclass
class ProcedureProgress:
    """One look at a running :class:`DeviceProcedure`: feedback for people, and the
    result message once the device is done (None: not yet)."""

    feedback: str = ''
    result: str | None = None


class DeviceProcedure(abc.ABC):
    """A procedure the device runs by itself and that needs the pedestal to itself
    (Capture's IMU levelling, its gyro drift measurement). The adapter knows how to start
    it and how far along it is; the core's guarded policy (``guarded.GuardedProcedures``)
    refuses it while anything else moves the axes, polls it and ends it on a cancel, a
    newer motion command, link loss or its timeout. An adapter builds one per request."""

    #: how messages name it ("device link lost during {name}")
    name: str = 'the device procedure'
    #: how the refusal names the procedures that run one at a time ("refused: {group} is
    #: already running")
    group: str = 'a device procedure'
    #: the message when a cancel or a newer motion command ends it
    cancelled: str = 'cancelled'
    #: the message when a newer motion command ends it (its joints are not stopped: the
    #: newer command owns them); None: :attr:`cancelled`
    superseded: str | None = None
    #: the joints the device moves: it is done once they also rest; a cancel or a timeout
    #: stops them. Empty: it moves none
    joints: Sequence[str] = ()
    #: a measurement: nothing may move while it runs, any motion ends it untrusted
    hold_still: bool = False
    #: s it may take (None: :meth:`poll` ends it), and the message when it did not finish
    timeout: float | None = None
    timed_out: str = 'not finished in time'
    #: s between two polls
    period: float = 0.1

    def busy(self) -> str | None:
        """Why the device is busy with a motion program of its own (a scan, a loop), or
        None: the policy refuses to start then."""
        return None

    @abc.abstractmethod
    def start(self) -> None:
        """Check and start it on the device; raise GimbalError (nothing started) if not."""

    @abc.abstractmethod
    def poll(self, elapsed: float) -> ProcedureProgress:
        """How far along it is, ``elapsed`` s after :meth:`start` returned."""


@dataclass
class PostedWrite:
    """A joint_command a device wrote without waiting (:meth:`Device.post`)."""

    moves: Moves = field(default_factory=dict)
    jogs: dict[str, float] = field(default_factory=dict)
    #: answers the command path settles later (:meth:`Device.settle`); 0: write-only
    replies: int = 0
    #: the adapter's own record of what it wrote and which answers to expect, for its
    #: :meth:`Device.settle` (the core only carries it)
    expected: object = None


@dataclass
class Capabilities:
    """What the device offers beyond the contract; None means "not on this device"."""

    homing: Homing | None = None
    presets: DevicePresets | None = None
    scans: DeviceScans | None = None
    status: StatusReport | None = None
    geolocation: Geolocation | None = None
    target_pointing: TargetPointing | None = None
    #: device-specific objects the driver's node exposes (name -> object)
    extras: dict[str, object] = field(default_factory=dict)


class Device(abc.ABC):
    """One device, in SI units and REP-103 signs."""

    #: True when :meth:`read` returns data a receive thread streams in: the controller
    #: then takes each sample on :meth:`notify_data` instead of on a fixed polling tick.
    streamed: bool = False

    def __init__(self) -> None:
        self.capabilities = Capabilities()
        #: the controller's configuration (joint names, live limits, rates); see attach()
        self.config: ControllerConfig | None = None
        #: the node's logger once attached (a module logger until then)
        self.log: Logger = logging.getLogger(type(self).__module__)
        #: the one lock of a request/reply link (:mod:`gimbal_driver_common.link_lock`):
        #: the adapter hands it to its client, the command path sends under it
        self.link_lock = LinkLock()
        self._data_arrived = threading.Event()
        self._on_data: Callable[[], bool] = lambda: False
        self._on_targets: Callable[[dict[str, float]], None] = lambda targets: None
        self._run_background: Callable[[], None] = lambda: None

    def attach(self, config: ControllerConfig, log: Logger,
               on_targets: Callable[[dict[str, float]], None] | None = None) -> None:
        """Called by the controller that runs this device, before :meth:`open`;
        ``on_targets`` receives what :meth:`report_targets` reports."""
        self.config, self.log = config, log
        if on_targets is not None:
            self._on_targets = on_targets

    def read_background_now(self) -> None:
        """Have the controller run :meth:`background_reads` at once (then on their
        periods again): a command changed what they read. Nothing before :meth:`open`."""
        self._run_background()

    def on_background_wake(self, run: Callable[[], None]) -> None:
        """The controller's way to run the background reads at once (its sensors thread)."""
        self._run_background = run

    def report_targets(self, targets: dict[str, float]) -> None:
        """Targets the device took on its own (a device preset, a geo-pointing, levelling,
        new units): the controller records them (AxisState.target_position). The one way
        a device reports targets; it never writes controller state."""
        self._on_targets(dict(targets))

    @abc.abstractmethod
    def open(self) -> DeviceInfo:
        """Open the link and read the identity; raise GimbalError when the device is not there."""

    def close(self) -> None:
        """Close the link; must never raise, called before every reconnect."""
        return None

    @abc.abstractmethod
    def read(self) -> JointSample | None:
        """The latest joint sample (poll, or read the receive cache); None: nothing new yet.

        Raise :class:`~gimbal_driver_common.errors.LinkError` when the link is lost.
        """

    def request_read(self, deliver: Callable[[JointSample], object]) -> bool:
        """The joint poll without waiting for its answer, for a request/reply device whose
        reader thread can take the sample: write the request now and have the reader call
        ``deliver(sample)`` with it (the controller's device thread then wakes once a
        sample, for the request, instead of again for the answer the reader hands over).
        True: asked, or a request in flight is still waiting for its answer; False (this
        default): the controller polls with :meth:`read`. Raise as :meth:`read` does, here
        or at the next call for an answer that failed."""
        return False

    def background_reads(self) -> list[tuple[Period, Callable[[], None]]]:
        """Reads besides the joint sample that may wait for the device (registers, a
        status the driver keeps): ``(period s, job)``, the period a number or a function
        read at each run (a run-time parameter); :meth:`read_background_now` runs them
        at once. The controller runs them on its
        ``sensors`` thread while the link is up, never in the joint poll, so one slow or
        silent answer does not hold up joint_states. Each job handles its own device
        errors; a lost link ends it (the controller skips it until reconnected)."""
        return []

    @abc.abstractmethod
    def move(self, moves: Moves) -> None:
        """Absolute position moves (targets already checked against the limits)."""

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite | None:
        """Write a joint_command now, from the callback's thread, without waiting for any
        answer: what was written and how many answers to settle later, or None (nothing
        written: the command thread sends it with :meth:`move` and :meth:`jog`).

        Must never wait for the device (the callback calls it while holding
        :attr:`link_lock`, so no other exchange is on the link). A device whose moves and
        jogs only write (a CAN frame, a serial packet) returns :meth:`write_now`; a device
        that answers posts what needs no set-up, counts the answers in
        :attr:`PostedWrite.replies` and says which in :attr:`PostedWrite.expected`; its
        client must take :attr:`link_lock` around every exchange, so that the lock
        settles the post before anyone else writes."""
        return None

    def write_now(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite:
        """:meth:`post` for a device whose :meth:`move` and :meth:`jog` wait for no answer."""
        if moves:
            self.move(moves)
        if jogs:
            self.jog(jogs)
        return PostedWrite(dict(moves), dict(jogs), replies=0)

    def settle(self, posted: PostedWrite) -> bool:
        """Read the answers of a :meth:`post` (the next holder of :attr:`link_lock`, before
        its own exchange; :mod:`gimbal_driver_common.link_lock`):
        True when every answer came; False when some were lost (the command path sends
        the moves again unless a stop or a newer move went out). Raises the device's
        refusal. Only called for a post with ``replies`` > 0."""
        raise NotImplementedError(f'{type(self).__name__} posts writes but cannot settle them')

    def move_relative(self, offsets: dict[str, float], moves: Moves) -> bool:
        """Send a relative move as the device's own relative set-points; False: use move()."""
        return False

    @abc.abstractmethod
    def jog(self, velocities: dict[str, float]) -> None:
        """Velocity commands in rad/s (0 stops that joint)."""

    @abc.abstractmethod
    def stop(self, joints: Sequence[str] | None = None) -> None:
        """Stop the named joints now (None: all); must work in any device state."""

    def reset_faults(self) -> str:
        raise Unsupported('this device has no fault-reset command')

    def refusal(self, joints: Sequence[str]) -> str | None:
        """Why these joints cannot move now (drive off, faulted), or None."""
        return None

    def link_healthy(self) -> bool:
        """For clients that watch their own link: False (or raise with the reason) when down."""
        return True

    def on_stream_data(self, take: Callable[[], bool]) -> None:
        """The controller's taker of a streamed sample (:mod:`~.streamed_samples`):
        :meth:`notify_data` calls it; False wakes :meth:`wait_for_data` instead."""
        self._on_data = take

    def notify_data(self) -> None:
        """A streamed device's receive thread calls this on each new sample (the sample
        is read and published on that thread), and when its link drops (the controller's
        device thread wakes and finds out)."""
        if not self._on_data():
            self._data_arrived.set()

    def wait_for_data(self, timeout: float) -> bool:
        """Block until :meth:`notify_data` was called (True) or ``timeout`` passed.

        Cleared only when it fired: a notice that comes between a wait's timeout and a
        clear would be lost, and the declined sample left until the next one."""
        arrived = self._data_arrived.wait(timeout)
        if arrived:
            self._data_arrived.clear()
        return arrived

    def expected_rate(self, publish_rate: float) -> float:
        """The joint_states rate the frequency check expects; a device that streams slower
        than ``publish_rate`` (and says so) overrides it, so a healthy device reads OK."""
        return publish_rate

    def description(self) -> str:
        """The endpoint shown in ~/status (never a password)."""
        return ''
