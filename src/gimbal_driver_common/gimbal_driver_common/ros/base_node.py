"""Lifecycle base node shared by every gimbal driver.

A driver subclasses :class:`GimbalDriverNode` and implements a handful of
hooks (open/close the device, poll a joint sample, send moves/jogs/stops);
this class owns everything that is the same for every device:

* the common parameters of interfaces.md, declared with descriptors and
  checked at start-up;
* the lifecycle (configure opens the link, activate starts publishing and
  accepting commands, deactivate stops the axes, cleanup/shutdown close) and
  the ``autostart`` walk to *active*;
* the device thread: polling at ``publish_rate``, ``joint_states``, and the
  reconnect loop when the link drops while active;
* ``joint_command`` validation, the jog dead-man watchdog, ``~/stop``,
  ``~/move_to`` and ``~/home`` actions, presets (device or YAML file) and
  scans (device or driver-side waypoints);
* ``/diagnostics`` (connection, joint_states frequency, the driver's own
  parts) and ``~/status``.
"""

from __future__ import annotations

import math
import signal
import sys
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from lifecycle_msgs.srv import ChangeState
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.diagnostics import FrequencyMonitor, Level
from gimbal_driver_common.joint_command import (
    CommandError,
    JointLimits,
    limits_from_parameters,
    resolve_targets,
    validate_joint_command,
)
from gimbal_driver_common.presets import PresetError, PresetStore
from gimbal_driver_common.ros.diagnostics import StatusPart, to_message
from gimbal_driver_common.ros.look_at import LookAtMixin
from gimbal_driver_common.ros.parameters import (
    ParameterError,
    ParameterRegistry,
    ValueOf,
    declare,
)
from gimbal_driver_common.scan import ScanError, ScanRequest, plan_scan
from gimbal_driver_common.transport import TransportError
from gimbal_driver_common.watchdog import JogWatchdog
from gimbal_msgs.action import Home, MoveTo
from gimbal_msgs.msg import AxisState, GimbalStatus, Preset
from gimbal_msgs.srv import ClearPreset, GotoPreset, ListPresets, SetPreset, StartScan

#: longest a STREAMED driver's device thread waits for data before checking the link
STREAM_WAIT_S = 0.05
#: Python thread switch interval in driver processes (default 5 ms)
GIL_SWITCH_INTERVAL_S = 0.001


class DeviceError(Exception):
    """A device request failed in a way a person should read (NACK, refused, timeout)."""


@dataclass
class DeviceInfo:
    """Identity read at configure time; feeds hardware_id and ~/status."""

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

    ``stamp`` is the wall-clock time (``time.time()``) at which the device
    data arrived; joint_states carry it.
    """

    positions: dict[str, float]
    velocities: dict[str, float] = field(default_factory=dict)
    efforts: dict[str, float] = field(default_factory=dict)
    stamp: float = field(default_factory=time.time)
    moving: dict[str, bool] = field(default_factory=dict)


class GimbalDriverNode(LookAtMixin, LifecycleNode):
    """Common behaviour of the pan-tilt drivers; subclasses implement the device hooks."""

    #: joint names when the ``joint_names`` parameter is not set
    DEFAULT_JOINT_NAMES: Sequence[str] = ('pan', 'tilt')
    #: per-joint limits when the parameters are not set (rad, rad/s)
    DEFAULT_POSITION_MIN: Sequence[float] = (-math.pi, -math.pi / 2)
    DEFAULT_POSITION_MAX: Sequence[float] = (math.pi, math.pi / 2)
    DEFAULT_VELOCITY_MAX: Sequence[float] = (1.0, 1.0)
    #: default ``publish_rate`` (interfaces.md says 50 Hz)
    DEFAULT_PUBLISH_RATE = 50.0
    #: patterns the driver-side scan offers (a device with its own scans overrides start_scan)
    SCAN_PATTERNS: Sequence[str] = ('sector', 'zigzag', 'square')
    #: True when poll_device only reads a cache that the client's receive thread fills:
    #: the device thread then publishes each new sample when the driver calls
    #: notify_new_data() (at most publish_rate) instead of sampling on a fixed tick, so
    #: joint_states carry no tick delay. Polled devices (request/reply) leave it False.
    STREAMED = False
    #: the (pan, tilt) joints a scan sweeps; None: `pan`/`tilt` if named so, else the first two
    SCAN_JOINTS: tuple[str, str] | None = None

    def __init__(self, node_name: str, **kwargs: object) -> None:
        super().__init__(node_name, **kwargs)
        self.parameter_registry = ParameterRegistry(self)
        self._declare_common_parameters()
        self.declare_device_parameters()
        self.device_info = DeviceInfo()
        self._state_lock = threading.RLock()
        self._connected = False
        self._active = False
        self._link_error = 'not configured'
        self._reconnects = 0
        self._latest: JointSample | None = None
        #: last position target sent per joint (shown as AxisState.target_position)
        self.commanded_targets: dict[str, float] = {}
        self._stop_event = threading.Event()
        #: wakes the device thread early (stop, or publish_rate changed)
        self._device_wake = threading.Event()
        self._data_arrived = threading.Event()
        self._periodic: list[list] = []
        self._periodic_lock = threading.Lock()
        self._housekeeping: threading.Thread | None = None
        self._housekeeping_stop = threading.Event()
        self._housekeeping_wake = threading.Event()
        self._device_thread: threading.Thread | None = None
        self._scan_thread: threading.Thread | None = None
        self._scan_stop = threading.Event()
        self._move_generation = 0
        self.jog_watchdog = JogWatchdog(self.command_timeout, self._on_jog_expired)
        self._joint_rate = FrequencyMonitor(self.publish_rate)
        self.preset_store: PresetStore | None = None
        self.service_group = ReentrantCallbackGroup()
        self._create_ros_interfaces()
        self._declare_runtime_parameters()
        self.declare_runtime_parameters()
        self.parameter_registry.check_all()
        self.parameter_registry.attach()

    # ------------------------------------------------------------------ hooks
    def declare_device_parameters(self) -> None:
        """Declare the driver's own parameters (use :meth:`declare_param`)."""

    def declare_runtime_parameters(self) -> None:
        """Mark the driver's parameters that apply at run time (use :meth:`runtime_parameter`).

        Every other parameter is refused at run time with "needs reconfigure"
        (read-only ones with "read-only").
        """

    def open_device(self) -> DeviceInfo:
        """Open the link and read the device identity; raise on failure."""
        raise NotImplementedError

    def close_device(self) -> None:
        """Close the link (called on cleanup, shutdown and before a reconnect)."""

    def poll_device(self) -> JointSample | None:
        """Return the latest joint sample (poll the device or read the client cache).

        Raise any exception when the link is lost: the base node then marks the
        device disconnected, closes it and reconnects every ``reconnect_period``.
        Return None when no new data is available yet.
        """
        raise NotImplementedError

    def link_healthy(self) -> bool:
        """For clients that watch their own link: False (or raise DeviceError with the
        reason, which then shows in the log and diagnostics) while it is down."""
        return True

    def send_moves(self, moves: dict[str, tuple[float, float | None]]) -> None:
        """Absolute moves: joint -> (target rad, max speed rad/s or None for default)."""
        raise NotImplementedError

    def send_relative_moves(
        self, offsets: dict[str, float], moves: dict[str, tuple[float, float | None]]
    ) -> bool:
        """Send a relative MoveTo as the device's own relative set-points.

        ``offsets`` are the goal's offsets; ``moves`` the absolute targets they resolve to
        (already checked against the limits) with speeds. Return False (the default) to
        have the base node send ``moves`` with :meth:`send_moves` instead.
        """
        return False

    def send_jogs(self, jogs: dict[str, float]) -> None:
        """Velocity commands: joint -> rad/s (0 stops that joint)."""
        raise NotImplementedError

    def stop_axes(self, joints: Sequence[str] | None) -> None:
        """Stop the named joints now (None: all). Must work in any state."""
        raise NotImplementedError

    def reset_faults(self) -> str:
        """Clear latched faults; return a message. Raise DeviceError if impossible."""
        raise DeviceError('this device has no fault-reset command')

    def home(
        self, joints: Sequence[str], report: Callable[[str], None], cancelled: threading.Event
    ) -> str:
        """Run the homing routine; return a message, raise DeviceError on failure."""
        raise DeviceError('this device has no homing routine')

    def device_status_parts(self) -> list[StatusPart]:
        """Decoded device registers as diagnostics parts (one per axis plus device)."""
        return []

    def device_mode(self) -> str:
        return ''

    def axis_details(self, joint: str) -> dict[str, object]:
        """Extra AxisState fields for ``joint``: state, calibrated, homed, active_errors."""
        return {}

    def device_errors(self) -> list[str]:
        return []

    # Device presets: a driver whose device stores presets sets DEVICE_PRESETS = True
    # and implements these four; otherwise the YAML store is used.
    DEVICE_PRESETS = False

    def device_set_preset(self, index: int, name: str, positions: dict[str, float] | None) -> str:
        raise DeviceError('no device presets')

    def device_goto_preset(self, index: int, speed: float) -> str:
        raise DeviceError('no device presets')

    def device_list_presets(self) -> list[Preset]:
        raise DeviceError('no device presets')

    def device_clear_preset(self, index: int | None) -> str:
        raise DeviceError('no device presets')

    # Device scans: override to run the device's own scan; default is driver-side.
    def start_device_scan(self, request: ScanRequest) -> str | None:
        """Start a device scan and return a message, or None to use the driver-side scan."""
        return None

    def stop_device_scan(self) -> None:
        """Stop a device scan (called by ~/stop_scan and ~/stop)."""

    # --------------------------------------------------------------- helpers
    def declare_param(self, name: str, default: object, description: str, **kwargs):
        """Declare a parameter with a descriptor; see :func:`ros.parameters.declare`."""
        return declare(self, name, default, description, **kwargs)

    def runtime_parameter(
        self, name: str, apply: Callable[[object], None] | str,
        send: Callable[[object], None] | None = None,
        busy: Callable[[], str | None] | None = None,
        check: Callable[[object], None] | None = None,
    ) -> None:
        """Let ``ros2 param set`` change ``name`` while the node runs.

        ``apply`` stores the accepted value (a string: the attribute to assign);
        ``send`` pushes it to the device while connected (an exception refuses the
        set with the device's reply); ``busy`` says why it cannot change right now;
        ``check`` is the same value check the driver runs at start-up.
        """
        if isinstance(apply, str):
            attribute = apply

            def apply(value: object) -> None:
                setattr(self, attribute, value)

        self.parameter_registry.make_runtime(name, apply, send=send, busy=busy, check=check)

    def parameter_check(self, names: Sequence[str], check: Callable[[ValueOf], None]) -> None:
        """A check over several parameters, run at start-up and on every set of one of them."""
        self.parameter_registry.add_check(names, check)

    @property
    def connected(self) -> bool:
        return self._connected

    @property
    def active(self) -> bool:
        return self._active

    @property
    def latest_sample(self) -> JointSample | None:
        return self._latest

    def current_positions(self) -> dict[str, float]:
        sample = self._latest
        return dict(sample.positions) if sample else {}

    def _declare_common_parameters(self) -> None:
        self.joint_names: list[str] = declare(
            self, 'joint_names', list(self.DEFAULT_JOINT_NAMES),
            'names used in joint_states and commands', read_only=True, element_type=str,
        )
        if not self.joint_names or len(set(self.joint_names)) != len(self.joint_names):
            raise ParameterError(
                f'parameter joint_names: need unique names, got {self.joint_names}'
            )
        n = len(self.joint_names)

        def per_joint(values: Sequence[float]) -> list[float]:
            values = list(values)
            return values if len(values) == n else (values + values[-1:] * n)[:n]

        self.publish_rate = declare(
            self, 'publish_rate', float(self.DEFAULT_PUBLISH_RATE),
            'joint_states rate in Hz', value_range=(0.1, 1000.0),
        )
        self.diagnostics_period = declare(
            self, 'diagnostics_period', 1.0, 'seconds between /diagnostics messages',
            value_range=(0.05, 60.0),
        )
        self.command_timeout = declare(
            self, 'command_timeout', 0.5,
            'jog dead-man timeout in s: a jog stops if no joint_command arrives in time '
            '(<= 0 disables)', value_range=(-1.0, 3600.0),
        )
        self.reconnect_period = declare(
            self, 'reconnect_period', 1.0, 'seconds between reconnect attempts',
            value_range=(0.05, 600.0),
        )
        position_min = declare(
            self, 'position_min', per_joint(self.DEFAULT_POSITION_MIN),
            'lowest position per joint (rad, m for linear axes)',
        )
        position_max = declare(
            self, 'position_max', per_joint(self.DEFAULT_POSITION_MAX),
            'highest position per joint (rad, m for linear axes)',
        )
        velocity_max = declare(
            self, 'velocity_max', per_joint(self.DEFAULT_VELOCITY_MAX),
            'highest speed per joint (rad/s, m/s for linear axes)',
        )
        values = {'position_min': position_min, 'position_max': position_max,
                  'velocity_max': velocity_max}
        self.limits: dict[str, JointLimits] = self._limits_from(values.__getitem__)
        self.presets_file = declare(
            self, 'presets_file', '', 'YAML file where driver-side presets persist ("" = memory)'
        )
        self.goal_tolerance = declare(
            self, 'goal_tolerance', 0.01, 'rad: a move is done when every joint is this close',
            value_range=(1e-6, 1.0),
        )
        self.move_timeout = declare(
            self, 'move_timeout', 60.0, 's: a MoveTo goal fails if not reached in time',
            value_range=(0.1, 3600.0),
        )
        self.autostart = declare(
            self, 'autostart', True,
            'walk the lifecycle to active by itself (false for managed bring-up)',
        )

    # ------------------------------------------------- run-time parameters
    def _limits_from(self, value_of: ValueOf) -> dict[str, JointLimits]:
        """Per-joint limits from position_min/position_max/velocity_max (start-up and set)."""
        try:
            return limits_from_parameters(
                self.joint_names, value_of('position_min'), value_of('position_max'),
                value_of('velocity_max'),
            )
        except ValueError as exc:
            raise ParameterError(f'joint limits: {exc}') from exc

    def _status_period(self) -> float:
        return 1.0 / min(self.publish_rate, 10.0)

    def _watchdog_period(self) -> float:
        """Check jogs 4 times per timeout (at least every 50 ms); slowly while disabled."""
        return min(0.05, self.command_timeout / 4) if self.command_timeout > 0 else 0.5

    def axes_busy(self) -> str | None:
        """Why the axes are not idle (jogging, moving, a driver-side scan), or None.

        For parameters that may only change while nothing moves (e.g. unit scales).
        """
        jogging = self.jog_watchdog.jogging
        if jogging:
            return f'jogging {jogging}'
        if self._scan_thread is not None and self._scan_thread.is_alive():
            return 'a driver-side scan is running'
        sample = self._latest
        moving = sorted(n for n, m in sample.moving.items() if m) if sample else []
        if moving:
            return f'moving {moving}'
        return None

    def _declare_runtime_parameters(self) -> None:
        """The common parameters that take effect when set (interfaces.md table)."""

        def set_publish_rate(rate: float) -> None:
            self.publish_rate = rate
            self._joint_rate.expected_hz = rate
            self.set_periodic_period(self._publish_status, self._status_period())
            self._device_wake.set()  # the device thread picks up the new period now

        def set_diagnostics_period(period: float) -> None:
            self.diagnostics_period = period
            self.set_periodic_period(self._publish_diagnostics, period)

        def set_command_timeout(timeout: float) -> None:
            self.command_timeout = timeout
            self.jog_watchdog.timeout_s = timeout
            self.set_periodic_period(self.jog_watchdog.check, self._watchdog_period())

        def set_limits(_: object) -> None:
            self.limits = self._limits_from(self.parameter_registry.current)

        self.runtime_parameter('publish_rate', set_publish_rate)
        self.runtime_parameter('diagnostics_period', set_diagnostics_period)
        self.runtime_parameter('command_timeout', set_command_timeout)
        for name in ('reconnect_period', 'goal_tolerance', 'move_timeout'):
            self.runtime_parameter(name, name)
        limit_names = ('position_min', 'position_max', 'velocity_max')
        for name in limit_names:
            self.runtime_parameter(name, set_limits)
        self.parameter_check(limit_names, self._limits_from)

    # --------------------------------------------------------- ROS interfaces
    def _create_ros_interfaces(self) -> None:
        self._guard_change_state_service()
        state_qos = QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST
        )
        self._joint_pub = self.create_publisher(JointState, 'joint_states', state_qos)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._status_pub = self.create_publisher(GimbalStatus, '~/status', 10)
        self.create_subscription(
            JointState, 'joint_command', self._on_joint_command, 1,
            callback_group=MutuallyExclusiveCallbackGroup(),
        )
        group = self.service_group
        self.create_service(Trigger, '~/stop', self._on_stop, callback_group=group)
        self.create_service(
            Trigger, '~/reset_faults', self._on_reset_faults, callback_group=group
        )
        self.create_service(SetPreset, '~/set_preset', self._on_set_preset, callback_group=group)
        self.create_service(
            GotoPreset, '~/goto_preset', self._on_goto_preset, callback_group=group
        )
        self.create_service(
            ListPresets, '~/list_presets', self._on_list_presets, callback_group=group
        )
        self.create_service(
            ClearPreset, '~/clear_preset', self._on_clear_preset, callback_group=group
        )
        self.create_service(StartScan, '~/start_scan', self._on_start_scan, callback_group=group)
        self.create_service(Trigger, '~/stop_scan', self._on_stop_scan, callback_group=group)
        self._move_server = ActionServer(
            self, MoveTo, '~/move_to', execute_callback=self._execute_move,
            goal_callback=self._accept_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=group,
        )
        self._home_server = ActionServer(
            self, Home, '~/home', execute_callback=self._execute_home,
            goal_callback=self._accept_goal, cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=group,
        )
        self._setup_look_at()  # ~/look_at (ros/look_at.py) runs through _execute_move
        self.add_periodic(self.diagnostics_period, self._publish_diagnostics)
        self.add_periodic(self._status_period(), self._publish_status)
        self.add_periodic(self._watchdog_period(), self.jog_watchdog.check)

    def add_periodic(self, period: float, callback: Callable[[], object]) -> None:
        """Run ``callback`` every ``period`` s on the node's housekeeping thread.

        Used instead of executor timers: every wake-up of rclpy's MultiThreadedExecutor
        rebuilds its wait set in Python and competes for the GIL with the device thread,
        which showed as CPU and joint_states latency. Callbacks must be thread-safe.
        """
        with self._periodic_lock:
            self._periodic.append([period, time.monotonic() + period, callback])
        if self._housekeeping is None:
            self._housekeeping = threading.Thread(
                target=self._housekeeping_loop, name='housekeeping', daemon=True)
            self._housekeeping.start()

    def set_periodic_period(self, callback: Callable[[], object], period: float) -> None:
        """Change how often a job added with :meth:`add_periodic` runs; next run in ``period``."""
        with self._periodic_lock:
            for entry in self._periodic:
                if entry[2] == callback:
                    entry[0], entry[1] = period, time.monotonic() + period
        self._housekeeping_wake.set()

    def _housekeeping_loop(self) -> None:
        while not self._housekeeping_stop.is_set():
            now = time.monotonic()
            with self._periodic_lock:
                due = [entry for entry in self._periodic if entry[1] <= now]
                for entry in due:
                    entry[1] = max(entry[1] + entry[0], now)
                next_due = min(entry[1] for entry in self._periodic)
            for _, _, callback in due:
                if not self.context.ok():
                    return
                try:
                    callback()
                except Exception as exc:  # noqa: BLE001 - keep the other periodic jobs alive
                    self.get_logger().error(
                        f'periodic {getattr(callback, "__name__", callback)} failed: {exc}',
                        throttle_duration_sec=10.0)
            if self._housekeeping_wake.wait(max(0.0, next_due - time.monotonic())):
                self._housekeeping_wake.clear()

    def destroy_node(self) -> None:
        self._housekeeping_stop.set()
        self._housekeeping_wake.set()
        if self._housekeeping is not None and self._housekeeping is not threading.current_thread():
            self._housekeeping.join(timeout=2.0)
        super().destroy_node()

    # -------------------------------------------------------------- lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        try:
            self.preset_store = PresetStore(self.presets_file)
        except PresetError as exc:
            self.get_logger().error(str(exc))
            return TransitionCallbackReturn.FAILURE
        try:
            self._open()
        except Exception as exc:  # noqa: BLE001 - any failure means "device not there"
            self._link_error = str(exc)
            self.get_logger().error(f'configure failed: cannot reach the device: {exc}')
            self._safe_close()
            return TransitionCallbackReturn.FAILURE
        self._stop_event.clear()
        self._device_wake.clear()
        self._device_thread = threading.Thread(
            target=self._device_loop, name='device', daemon=True
        )
        self._device_thread.start()
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = True
        self.get_logger().info('active: publishing joint_states and accepting commands')
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._halt('deactivating')
        self._active = False
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._stop_device_thread()
        self._safe_close()
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self._active:
            self._halt('shutting down')
        self._active = False
        self._stop_device_thread()
        self._safe_close()
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._halt('lifecycle error')
        self._stop_device_thread()
        self._safe_close()
        return TransitionCallbackReturn.SUCCESS

    def _open(self) -> None:
        info = self.open_device()
        self.device_info = info if isinstance(info, DeviceInfo) else DeviceInfo()
        with self._state_lock:
            self._connected = True
            self._link_error = ''
        self.get_logger().info(
            f'connected to {self.device_info.model or "device"} '
            f'(serial {self.device_info.serial_number or "?"}, '
            f'firmware {self.device_info.firmware_version or "?"})'
        )

    def _safe_close(self) -> None:
        with self._state_lock:
            self._connected = False
        try:
            self.close_device()
        except Exception as exc:  # noqa: BLE001 - closing must never raise out
            self.get_logger().debug(f'close_device: {exc}')

    def _stop_device_thread(self) -> None:
        self._stop_event.set()
        self._device_wake.set()
        self._scan_stop.set()
        thread = self._device_thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout=5.0)
        self._device_thread = None

    def _halt(self, why: str) -> None:
        """Stop every axis and everything that would move it again."""
        self.jog_watchdog.cancel()
        self._scan_stop.set()
        self._move_generation += 1
        if not self._connected:
            return
        try:
            self.stop_device_scan()
        except Exception as exc:  # noqa: BLE001
            self.get_logger().warning(f'{why}: stopping the device scan failed: {exc}')
        try:
            self.stop_axes(None)
            self.get_logger().info(f'{why}: axes stopped')
        except Exception as exc:  # noqa: BLE001
            self.get_logger().error(f'{why}: stopping the axes failed: {exc}')

    # ---------------------------------------------------------- device thread
    def _device_loop(self) -> None:
        """Poll (or, for STREAMED drivers, wait for) samples and publish joint_states."""
        period = 1.0 / self.publish_rate
        next_tick = time.monotonic()
        last_publish = -math.inf
        last_stamp: float | None = None
        while not self._stop_event.is_set():
            if period != 1.0 / self.publish_rate:  # publish_rate changed at run time
                period = 1.0 / self.publish_rate
                next_tick = time.monotonic()
            if not self._connected:
                self._try_reconnect()
                continue
            if self.STREAMED:
                # Publish each new sample as it arrives, at most publish_rate (10 % slack so
                # a device streaming at exactly that rate is not throttled by jitter).
                hold = last_publish + 0.9 * period - time.monotonic()
                if hold > 0 and self._wait_device_wake(hold):
                    continue
                if self._data_arrived.wait(STREAM_WAIT_S):
                    self._data_arrived.clear()
            try:
                if not self.link_healthy():
                    raise DeviceError('the client reports its link is down')
                sample = self.poll_device()
            except Exception as exc:  # noqa: BLE001 - any failure is a lost link
                self._on_link_lost(exc)
                continue
            fresh = sample is not None and not (self.STREAMED and sample.stamp == last_stamp)
            if fresh:
                self._latest = sample
                last_stamp = sample.stamp
                if self._active and self.context.ok():
                    self._publish_joint_state(sample)
                    last_publish = time.monotonic()
            if self.STREAMED:
                continue
            next_tick += period
            delay = next_tick - time.monotonic()
            if delay < -period:  # fell behind (slow device): do not burst to catch up
                next_tick = time.monotonic()
                delay = 0.0
            self._wait_device_wake(max(delay, 0.0))

    def _wait_device_wake(self, timeout: float) -> bool:
        """Sleep up to ``timeout``; True when woken early (stopping or publish_rate changed)."""
        woken = self._device_wake.wait(timeout)
        if woken and not self._stop_event.is_set():
            self._device_wake.clear()
        return woken

    def notify_new_data(self) -> None:
        """Wake the device thread: a STREAMED driver's client calls this on each new frame."""
        self._data_arrived.set()

    def _on_link_lost(self, exc: BaseException) -> None:
        with self._state_lock:
            self._connected = False
            self._link_error = f'link lost: {exc}'
        self.jog_watchdog.cancel()
        self.get_logger().error(
            f'device link lost ({exc}); reconnecting every {self.reconnect_period:g} s'
        )
        self._publish_diagnostics()
        self._safe_close()

    def _try_reconnect(self) -> None:
        if self._stop_event.wait(self.reconnect_period):
            return
        try:
            self._open()
        except Exception as exc:  # noqa: BLE001
            self._link_error = f'reconnecting: {exc}'
            self.get_logger().warning(
                f'reconnect failed: {exc}', throttle_duration_sec=10.0
            )
            self._safe_close()
            return
        self._reconnects += 1
        self.get_logger().info(f'reconnected (reconnect #{self._reconnects})')
        self._publish_diagnostics()

    def _publish_joint_state(self, sample: JointSample) -> None:
        msg = JointState()
        sec = math.floor(sample.stamp)
        msg.header.stamp.sec = int(sec)
        msg.header.stamp.nanosec = int((sample.stamp - sec) * 1e9)
        names = [n for n in self.joint_names if n in sample.positions]
        msg.name = names
        msg.position = [float(sample.positions[n]) for n in names]
        msg.velocity = [float(sample.velocities.get(n, math.nan)) for n in names]
        if sample.efforts:
            msg.effort = [float(sample.efforts.get(n, math.nan)) for n in names]
        self._joint_pub.publish(msg)
        self._joint_rate.tick()

    # -------------------------------------------------------------- commands
    def command_refusal(self) -> str | None:
        """Why commands cannot be served now (inactive, disconnected), or None."""
        if not self._active:
            return 'node is not active (lifecycle); activate it first'
        if not self._connected:
            return f'device not connected ({self._link_error})'
        return None

    def axis_refusal(self, joints: Sequence[str]) -> str | None:
        """Why the named joints cannot move now (drive off, faulted), or None.

        Drivers whose device reports per-axis power or fault state override
        this; the base node asks it before any motion command (joint_command
        moves and non-zero jogs, move_to, goto_preset, start_scan) and sends
        nothing when it answers with a reason. Stops are never refused.
        """
        return None

    def expected_joint_rate(self) -> float:
        """joint_states rate the frequency check expects (Hz): ``publish_rate``.

        A STREAMED driver whose device sends slower than ``publish_rate`` (and that
        reports the rate the device agreed to or actually uses) overrides this, so a
        healthy device is not reported as too slow.
        """
        return self.publish_rate

    def motion_refusal(self, joints: Sequence[str]) -> str | None:
        """command_refusal() or axis_refusal(joints): the one check before motion."""
        return self.command_refusal() or self.axis_refusal(list(joints))

    def _on_joint_command(self, msg: JointState) -> None:
        refusal = self.command_refusal()
        if refusal:
            self.get_logger().warning(
                f'joint_command ignored: {refusal}', throttle_duration_sec=2.0
            )
            return
        try:
            plan = validate_joint_command(msg.name, msg.position, msg.velocity, self.limits)
        except CommandError as exc:
            self.get_logger().warning(f'joint_command rejected, nothing sent: {exc}')
            return
        movers = list(plan.moves) + [j for j, v in plan.jogs.items() if v != 0.0]
        refusal = self.axis_refusal(movers) if movers else None
        if refusal:
            self.get_logger().warning(
                f'joint_command refused, nothing sent: {refusal}', throttle_duration_sec=2.0
            )
            return
        try:
            if plan.moves:
                self._stop_scan_silently()
                self.jog_watchdog.cancel(plan.moves)
                self.send_moves(plan.moves)
                self.commanded_targets.update({k: v[0] for k, v in plan.moves.items()})
            if plan.jogs:
                self._stop_scan_silently()
                self.send_jogs(plan.jogs)
                moving = [j for j, v in plan.jogs.items() if v != 0.0]
                self.jog_watchdog.feed(moving)
                self.jog_watchdog.cancel([j for j, v in plan.jogs.items() if v == 0.0])
        except Exception as exc:  # noqa: BLE001
            self.get_logger().error(f'joint_command failed on the device: {exc}')

    def _on_jog_expired(self, joints: list[str]) -> None:
        self.get_logger().warning(
            f'jog of {joints} expired (no joint_command for {self.command_timeout:g} s): stopping'
        )
        if not self._connected:
            return
        try:
            self.stop_axes(joints)
        except Exception as exc:  # noqa: BLE001
            self.get_logger().error(f'stopping expired jog failed: {exc}')

    def _on_stop(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.jog_watchdog.cancel()
        self._scan_stop.set()
        self._move_generation += 1
        if not self._connected:
            response.success = False
            response.message = f'device not connected ({self._link_error}); nothing to stop'
            return response
        try:
            self.stop_device_scan()
            self.stop_axes(None)
        except Exception as exc:  # noqa: BLE001
            response.success = False
            response.message = f'stop failed: {exc}'
            self.get_logger().error(response.message)
            return response
        response.success = True
        response.message = 'all axes stopped; scans, moves and jogs cancelled'
        return response

    def _on_reset_faults(
        self, request: Trigger.Request, response: Trigger.Response
    ) -> Trigger.Response:
        return self.serve_request(response, self.reset_faults)

    def serve_request(self, response: Trigger.Response, action: Callable[[], str]) -> object:
        """Answer a service with ``success``/``message`` from ``action()``.

        Drivers use it for their own services: the request is refused while the
        node is inactive or disconnected, and any exception becomes
        ``success=false`` with a message instead of escaping into rclpy.
        """
        refusal = self.command_refusal()
        if refusal:
            response.success, response.message = False, refusal
            return response
        try:
            response.message = action() or 'done'
            response.success = True
        except (DeviceError, CommandError, ScanError, PresetError) as exc:
            response.success, response.message = False, str(exc)
        except (TransportError, TimeoutError) as exc:
            # the link dropped or the device went silent during the request: expected under
            # faults (the device loop reconnects), so an answer and no traceback in the log
            response.success, response.message = False, f'device link: {exc}'
        except Exception as exc:  # noqa: BLE001 - services answer, never raise
            response.success, response.message = False, f'{type(exc).__name__}: {exc}'
            if self._link_down():
                # a driver's own link exception while the link dropped: expected under
                # faults, the device loop reconnects; the answer says it, no traceback
                response.message = f'device link lost during the request: {exc}'
            else:
                self.get_logger().error(traceback.format_exc())
        return response

    def _guard_change_state_service(self) -> None:
        """Answer an impossible lifecycle transition with success=false instead of dying.

        rclpy's ``~/change_state`` handler lets the RCLError of a transition the current
        state does not have (``configure`` while active, an unknown id) escape into the
        executor, which ends the spin and with it the node (found by `make soak`).
        """
        service = getattr(self, '_service_change_state', None)
        if service is None:
            return
        handler = service.callback

        def guarded(request: ChangeState.Request, response: ChangeState.Response):
            try:
                return handler(request, response)
            except _rclpy.RCLError as exc:
                transition = request.transition.label or request.transition.id
                self.get_logger().warning(
                    f'lifecycle transition {transition!r} refused in state '
                    f'{self._state_machine.current_state[1]!r}: {exc}')
                response.success = False
                return response

        service.callback = guarded

    def _link_down(self) -> bool:
        try:
            return not self._connected or not self.link_healthy()
        except Exception:  # noqa: BLE001 - a broken client counts as a link that is down
            return True

    # ------------------------------------------------------------- move / home
    def _accept_goal(self, goal: object) -> GoalResponse:
        return GoalResponse.ACCEPT

    def _execute_move(self, goal_handle):
        goal = goal_handle.request
        result = MoveTo.Result()
        names = list(goal.joint_names)
        refusal = self.motion_refusal(names)
        try:
            if refusal:
                raise DeviceError(refusal)
            targets = resolve_targets(
                names, list(goal.positions), self.current_positions(), self.limits,
                relative=goal.relative,
            )
            speeds = list(goal.velocities) if goal.velocities else []
            if speeds and len(speeds) != len(names):
                raise CommandError(f'{len(names)} joints but {len(speeds)} velocities')
            moves: dict[str, tuple[float, float | None]] = {}
            for i, name in enumerate(names):
                speed = abs(speeds[i]) if speeds and speeds[i] else None
                if speed is not None and speed > self.limits[name].velocity_max:
                    raise CommandError(
                        f'joint {name!r}: speed {speed:.4f} exceeds velocity_max '
                        f'{self.limits[name].velocity_max:.4f}'
                    )
                moves[name] = (targets[name], speed)
            self._stop_scan_silently()
            self.jog_watchdog.cancel(names)
            offsets = dict(zip(names, map(float, goal.positions), strict=True))
            if not (goal.relative and self.send_relative_moves(offsets, moves)):
                self.send_moves(moves)
            self.commanded_targets.update(targets)
        except Exception as exc:  # noqa: BLE001
            goal_handle.abort()
            result.success, result.message = False, f'move refused, nothing sent: {exc}'
            result.positions = [self.current_positions().get(n, math.nan) for n in names]
            return result
        tolerance = goal.tolerance if goal.tolerance > 0 else self.goal_tolerance
        generation = self._move_generation
        deadline = time.monotonic() + self.move_timeout
        feedback = MoveTo.Feedback()
        outcome = ''
        while True:
            time.sleep(0.02)
            current = self.current_positions()
            feedback.positions = [current.get(n, math.nan) for n in names]
            goal_handle.publish_feedback(feedback)
            if goal_handle.is_cancel_requested:
                self._stop_quietly(names)
                outcome = 'cancelled'
                break
            if generation != self._move_generation:
                outcome = 'stopped (~/stop or a new command)'
                break
            if not self._connected:
                outcome = f'device link lost ({self._link_error})'
                break
            sample = self._latest
            reached = all(
                abs(current.get(n, math.inf) - targets[n]) <= tolerance for n in names
            )
            settled = not (sample and any(sample.moving.get(n, False) for n in names))
            if reached and settled:
                outcome = 'reached'
                break
            if time.monotonic() > deadline:
                self._stop_quietly(names)
                outcome = f'not reached within move_timeout {self.move_timeout:g} s'
                break
        result.positions = feedback.positions
        result.success = outcome == 'reached'
        result.message = outcome
        if outcome == 'cancelled':
            goal_handle.canceled()
        elif result.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def _execute_home(self, goal_handle):
        joints = list(goal_handle.request.joint_names) or list(self.joint_names)
        result = Home.Result()
        unknown = [j for j in joints if j not in self.limits]
        refusal = self.command_refusal() or (
            f'unknown joint(s) {unknown}; this device has {self.joint_names}' if unknown else None
        )
        if refusal:
            goal_handle.abort()
            result.success, result.message = False, refusal
            return result
        cancelled = threading.Event()
        feedback = Home.Feedback()

        def report(state: str) -> None:
            if goal_handle.is_cancel_requested:
                cancelled.set()
            feedback.state = state
            goal_handle.publish_feedback(feedback)

        self._stop_scan_silently()
        self.jog_watchdog.cancel(joints)
        try:
            result.message = self.home(joints, report, cancelled) or 'homed'
            result.success = True
        except Exception as exc:  # noqa: BLE001
            result.success, result.message = False, str(exc)
        if goal_handle.is_cancel_requested or cancelled.is_set():
            self._stop_quietly(joints)
            goal_handle.canceled()
            result.success = False
            result.message = 'homing cancelled'
        elif result.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def _stop_quietly(self, joints: Sequence[str] | None) -> None:
        try:
            self.stop_axes(joints)
        except Exception as exc:  # noqa: BLE001
            self.get_logger().error(f'stop failed: {exc}')

    # ---------------------------------------------------------------- presets
    def _on_set_preset(self, request, response):
        def action() -> str:
            if request.use_current_position:
                positions = self.current_positions()
                if not positions:
                    raise DeviceError('no joint position received yet')
                positions = {n: positions[n] for n in self.joint_names if n in positions}
            else:
                if len(request.joint_names) != len(request.positions):
                    raise CommandError(
                        f'{len(request.joint_names)} joint names but '
                        f'{len(request.positions)} positions'
                    )
                validate_joint_command(
                    request.joint_names, list(request.positions), [], self.limits
                )
                positions = dict(zip(request.joint_names, request.positions, strict=True))
            if self.DEVICE_PRESETS:
                return self.device_set_preset(
                    request.index, request.name,
                    None if request.use_current_position else positions,
                )
            assert self.preset_store is not None
            self.preset_store.set(request.index, request.name, positions)
            return f'preset {request.index} stored: ' + ', '.join(
                f'{k}={v:.4f}' for k, v in positions.items()
            )

        return self.serve_request(response, action)

    def _on_goto_preset(self, request, response):
        def action() -> str:
            if request.speed < 0 or not math.isfinite(request.speed):
                raise CommandError(f'speed {request.speed} must be >= 0 rad/s')
            if self.DEVICE_PRESETS:
                refusal = self.axis_refusal(list(self.joint_names))
                if refusal:
                    raise DeviceError(refusal)
                self._stop_scan_silently()
                return self.device_goto_preset(request.index, request.speed)
            assert self.preset_store is not None
            preset = self.preset_store.get(request.index)
            names = [n for n in preset.positions if n in self.limits]
            refusal = self.axis_refusal(names)
            if refusal:
                raise DeviceError(refusal)
            speeds = [request.speed] * len(names) if request.speed > 0 else []
            plan = validate_joint_command(
                names, [preset.positions[n] for n in names], speeds, self.limits
            )
            self._stop_scan_silently()
            self.jog_watchdog.cancel(names)
            self.send_moves(plan.moves)
            self.commanded_targets.update({k: v[0] for k, v in plan.moves.items()})
            return f'moving to preset {request.index} ({preset.name})'

        return self.serve_request(response, action)

    def _on_list_presets(self, request, response):
        try:
            if self.DEVICE_PRESETS:
                refusal = self.command_refusal()
                if refusal:
                    raise DeviceError(refusal)
                response.presets = self.device_list_presets()
            else:
                assert self.preset_store is not None
                response.presets = [
                    Preset(
                        index=p.index, name=p.name, joint_names=list(p.positions),
                        positions=list(p.positions.values()),
                    )
                    for p in self.preset_store.list()
                ]
            response.success = True
            response.message = f'{len(response.presets)} preset(s)'
        except Exception as exc:  # noqa: BLE001
            response.success, response.message = False, str(exc)
        return response

    def _on_clear_preset(self, request, response):
        def action() -> str:
            index = None if request.all else request.index
            if self.DEVICE_PRESETS:
                return self.device_clear_preset(index)
            assert self.preset_store is not None
            self.preset_store.clear(index)
            return 'all presets cleared' if index is None else f'preset {index} cleared'

        if not self.DEVICE_PRESETS and self.preset_store is not None:
            # Driver-side presets can be edited without a device.
            try:
                response.message = action()
                response.success = True
            except PresetError as exc:
                response.success, response.message = False, str(exc)
            return response
        return self.serve_request(response, action)

    # ------------------------------------------------------------------ scans
    def _on_start_scan(self, request, response):
        def action() -> str:
            scan = ScanRequest.from_msg(request)
            refusal = self.axis_refusal(self.scan_joints())
            if refusal:
                raise DeviceError(refusal)
            message = self.start_device_scan(scan)
            if message is not None:
                return message
            waypoints = plan_scan(
                scan, self.scan_joints(), self.current_positions(), self.limits,
                self.SCAN_PATTERNS,
            )
            self._stop_scan_silently()
            self._scan_stop = threading.Event()
            self._scan_thread = threading.Thread(
                target=self._run_scan, args=(waypoints, scan, self._scan_stop),
                name='scan', daemon=True,
            )
            self._scan_thread.start()
            return f'{scan.pattern} scan started over {len(waypoints)} waypoints (driver-side)'

        return self.serve_request(response, action)

    def _on_stop_scan(self, request, response):
        def action() -> str:
            self._scan_stop.set()
            self.stop_device_scan()
            self.stop_axes(None)
            return 'scan stopped'

        return self.serve_request(response, action)

    def scan_joints(self) -> list[str]:
        """The joints a driver-side scan sweeps as pan and tilt."""
        if self.SCAN_JOINTS is not None:
            return list(self.SCAN_JOINTS)
        if 'pan' in self.joint_names and 'tilt' in self.joint_names:
            return ['pan', 'tilt']
        return list(self.joint_names[:2])

    def _stop_scan_silently(self) -> None:
        if self._scan_thread is not None and self._scan_thread.is_alive():
            self._scan_stop.set()

    def _run_scan(
        self, waypoints: list[dict[str, float]], scan: ScanRequest, stop: threading.Event
    ) -> None:
        """Visit the waypoints in a loop until stopped (driver-side scan)."""
        index = 0
        while not stop.is_set() and self._connected:
            target = waypoints[index % len(waypoints)]
            pan = self.scan_joints()[0]
            speeds = {name: (scan.speed if name == pan else None) for name in target}
            try:
                self.send_moves({n: (p, speeds[n]) for n, p in target.items()})
                self.commanded_targets.update(target)
            except Exception as exc:  # noqa: BLE001
                self.get_logger().error(f'scan aborted: {exc}')
                return
            deadline = time.monotonic() + self.move_timeout
            while not stop.is_set() and time.monotonic() < deadline:
                current = self.current_positions()
                if all(abs(current.get(n, math.inf) - p) <= self.goal_tolerance * 2
                       for n, p in target.items()):
                    break
                stop.wait(0.02)
            stop.wait(scan.dwell)
            index += 1

    # ------------------------------------------------------------ diagnostics
    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        self._joint_rate.sample(now)
        parts: list[StatusPart] = []
        connection = StatusPart('connection')
        connection.values = [
            ('connected', str(self._connected)),
            ('lifecycle', 'active' if self._active else 'inactive'),
            ('reconnects', str(self._reconnects)),
            ('model', self.device_info.model),
            ('serial_number', self.device_info.serial_number),
            ('firmware', self.device_info.firmware_version),
        ]
        if self._connected:
            connection.message = 'connected'
        else:
            connection.level = Level.ERROR
            connection.message = f'disconnected: {self._link_error}'
        parts.append(connection)
        if self._active and self._connected:
            self._joint_rate.expected_hz = self.expected_joint_rate()
            level, message = self._joint_rate.status()
            parts.append(
                StatusPart(
                    'joint_states frequency', level, message,
                    [('expected_hz', f'{self._joint_rate.expected_hz:g}'),
                     ('measured_hz', f'{self._joint_rate.rate_hz:.2f}')],
                )
            )
        if self._connected:
            try:
                parts.extend(self.device_status_parts())
            except Exception as exc:  # noqa: BLE001
                parts.append(StatusPart('device', Level.WARN, f'status unavailable: {exc}'))
        else:
            for name in self.joint_names:
                parts.append(StatusPart(name, Level.STALE, 'no data: device disconnected'))
        array = DiagnosticArray()
        array.header.stamp = self.get_clock().now().to_msg()
        node_name = self.get_name()
        array.status = [to_message(node_name, self.device_info.hardware_id, p) for p in parts]
        self._diag_pub.publish(array)

    def _publish_status(self) -> None:
        msg = GimbalStatus()
        msg.header.stamp = self.get_clock().now().to_msg()
        if self._connected:
            msg.connection = GimbalStatus.CONNECTION_CONNECTED
        elif self._reconnects or self._link_error.startswith(('link lost', 'reconnecting')):
            msg.connection = GimbalStatus.CONNECTION_CONNECTING
        else:
            msg.connection = GimbalStatus.CONNECTION_DISCONNECTED
        msg.link = self.link_description()
        msg.device_model = self.device_info.model
        msg.serial_number = self.device_info.serial_number
        msg.firmware_version = self.device_info.firmware_version
        msg.reconnects = self._reconnects
        try:
            msg.mode = self.device_mode() if self._connected else ''
            msg.active_errors = self.device_errors() if self._connected else []
        except Exception as exc:  # noqa: BLE001
            msg.active_errors = [f'status unavailable: {exc}']
        sample = self._latest
        jogging = set(self.jog_watchdog.jogging)
        for name in self.joint_names:
            axis = AxisState(name=name)
            axis.position = sample.positions.get(name, math.nan) if sample else math.nan
            axis.velocity = sample.velocities.get(name, math.nan) if sample else math.nan
            axis.effort = sample.efforts.get(name, math.nan) if sample else math.nan
            axis.target_position = self.commanded_targets.get(name, math.nan)
            if not self._connected:
                axis.state = AxisState.STATE_UNKNOWN
            elif name in jogging:
                axis.state = AxisState.STATE_JOGGING
            elif sample and sample.moving.get(name):
                axis.state = AxisState.STATE_MOVING
            else:
                axis.state = AxisState.STATE_IDLE
            try:
                for key, value in self.axis_details(name).items():
                    setattr(axis, key, value)
            except Exception as exc:  # noqa: BLE001
                axis.active_errors = [f'status unavailable: {exc}']
            msg.axes.append(axis)
        self._status_pub.publish(msg)

    def link_description(self) -> str:
        """Endpoint shown in ~/status (never a password)."""
        return ''


def run_driver(node_class: type[GimbalDriverNode], args: Sequence[str] | None = None) -> int:
    """Entry point body for a driver executable: construct, autostart, spin, stop cleanly.

    rclpy's own SIGINT handler would shut the context down before ``on_shutdown`` runs,
    losing the "axes stopped" log and any last message; so signals are handled here. The
    executor spins in a worker thread and the main thread waits on an Event, which (unlike
    a blocking rcl_wait) lets the Python signal handler run at once.
    """
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    # The device thread must not wait the default 5 ms for the GIL while a receive thread
    # (e.g. python-can's byte-wise slcan reader) is busy: that showed as joint_states latency.
    sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    stop = threading.Event()

    def request_stop(signum: int, frame: object) -> None:
        stop.set()

    signal.signal(signal.SIGINT, request_stop)
    signal.signal(signal.SIGTERM, request_stop)  # launch sends SIGTERM after SIGINT
    try:
        node = node_class()
    except ParameterError as exc:
        rclpy.logging.get_logger(node_class.__name__).fatal(f'invalid parameter: {exc}')
        rclpy.try_shutdown()
        return 2
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    spinner = threading.Thread(target=_spin, args=(executor, stop), name='executor',
                               daemon=True)
    spinner.start()
    if node.autostart:
        threading.Thread(target=_autostart, args=(node,), daemon=True).start()
    while not stop.wait(1.0):
        pass
    node.on_shutdown(None)
    node.destroy_node()
    executor.shutdown(timeout_sec=1.0)
    rclpy.try_shutdown()
    spinner.join(timeout=2.0)
    return 0


def _spin(executor: MultiThreadedExecutor, stop: threading.Event) -> None:
    try:
        executor.spin()
    except (ExternalShutdownException, KeyboardInterrupt):
        pass
    finally:
        stop.set()


def _autostart(node: GimbalDriverNode) -> None:
    """Configure (retrying while the device is absent) and activate."""
    logger = node.get_logger()
    while rclpy.ok():
        state = node._state_machine.current_state[1]
        if state == 'unconfigured':
            if node.trigger_configure() == TransitionCallbackReturn.SUCCESS:
                continue
            logger.warning(f'autostart: retrying configure in {node.reconnect_period:g} s')
            time.sleep(node.reconnect_period)
        elif state == 'inactive':
            node.trigger_activate()
            return
        else:
            return
