"""The lifecycle node: a thin adapter from ROS onto a :class:`GimbalController`.

A driver subclasses :class:`GimbalDriverNode`, declares its parameters and
returns its device adapter from :meth:`make_device`; everything the same for
every device (link supervision, commands, moves, scans, presets, the jog
watchdog) lives in the ROS-free controller and policies. This class only maps
parameters, topics, services and actions onto them and builds the messages.

Threading (ARCHITECTURE.md, "Threads"): ``joint_command`` validates and queues, and the
controller's command thread sends (newest wins), so the subscription callback never
waits for a device reply; only a device whose sends wait for no reply is written to
from the callback itself. Services and actions share a reentrant group run by the
executor's pool (``ros/run.py``), so ``~/stop`` answers while a ``move_to`` waits. Periodic jobs run
on two plain threads: ``periodic`` (jog watchdog, diagnostics, ~/status) and
``sensor_jobs`` (a driver's extra topics that read the device).
"""

from __future__ import annotations

import math
import time
import traceback
from collections.abc import Callable, Iterable, Sequence
from typing import Any, Protocol, TypeVar

from diagnostic_msgs.msg import DiagnosticArray
from rclpy.action import ActionServer, CancelResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from gimbal_driver_common.command_stream import CommandStream
from gimbal_driver_common.controller import GimbalController
from gimbal_driver_common.device import Device, DeviceInfo, JointSample
from gimbal_driver_common.diagnostics import FrequencyMonitor
from gimbal_driver_common.errors import DeviceRefused, GimbalError, InvalidRequest
from gimbal_driver_common.guarded import GuardedProcedures
from gimbal_driver_common.joint_command import JointLimits
from gimbal_driver_common.periodic import Periodic
from gimbal_driver_common.policies import DRIVER_SCAN_PATTERNS, Motion
from gimbal_driver_common.presets import PresetStore
from gimbal_driver_common.rejections import CommandRejections
from gimbal_driver_common.ros import messages
from gimbal_driver_common.ros.actions import (
    MotionActions,
    OpenGoals,
    guard_change_state_service,
)
from gimbal_driver_common.ros.common_parameters import declare_common_parameters, limits_from
from gimbal_driver_common.ros.log_bridge import install_log_bridge
from gimbal_driver_common.ros.look_at import LookAtServer
from gimbal_driver_common.ros.look_at_geo import LookAtGeoServer
from gimbal_driver_common.ros.parameters import ParameterRegistry, declare
from gimbal_driver_common.ros.run import InlineCallbackGroup, run_driver
from gimbal_driver_common.scan import ScanRequest
from gimbal_msgs.action import Home, MoveTo
from gimbal_msgs.msg import GimbalStatus, Preset
from gimbal_msgs.srv import ClearPreset, GotoPreset, ListPresets, SetPreset, StartScan

__all__ = ['GimbalDriverNode', 'run_driver']


class Answer(Protocol):
    """A service response with std_srvs/Trigger's ``success`` and ``message`` (Trigger,
    SetPreset, a driver's own services ...)."""

    success: bool
    message: str


AnswerT = TypeVar('AnswerT', bound=Answer)

#: command_refusal() before configure
NOT_CONFIGURED = 'node is not active (lifecycle: not configured); configure and activate it first'


class GimbalDriverNode(LifecycleNode):
    """Common ROS interface of the pan-tilt drivers; a driver adds :meth:`make_device`.

    Its action parts, each handed this node (its public side, typed in the part's module):
    :attr:`motion_actions` (``~/move_to``, ``~/home``, guarded procedures),
    :attr:`look_at_server` (``~/look_at``) and :attr:`look_at_geo_server`
    (``~/look_at_geo``)."""

    #: joint names when the ``joint_names`` parameter is not set
    DEFAULT_JOINT_NAMES: Sequence[str] = ('pan', 'tilt')
    #: per-joint limits when the parameters are not set (rad, rad/s)
    DEFAULT_POSITION_MIN: Sequence[float] = (-math.pi, -math.pi / 2)
    DEFAULT_POSITION_MAX: Sequence[float] = (math.pi, math.pi / 2)
    DEFAULT_VELOCITY_MAX: Sequence[float] = (1.0, 1.0)
    #: default ``publish_rate`` (docs/interface.md says 50 Hz)
    DEFAULT_PUBLISH_RATE = 50.0
    #: default ``stop_deceleration`` (rad/s^2): the gentlest braking of this device's axes
    DEFAULT_STOP_DECELERATION = 0.5
    #: the (pan, tilt) joints a scan sweeps; None: `pan`/`tilt` if named so, else the first two
    SCAN_JOINTS: tuple[str, str] | None = None
    #: patterns the driver-side scan offers (a device's own scans come from its capability)
    SCAN_PATTERNS: Sequence[str] = DRIVER_SCAN_PATTERNS
    #: Python loggers bridged to this node's ROS logger besides ``gimbal_driver_common`` and
    #: the driver's own package (ros/log_bridge.py)
    LIBRARY_LOGGERS: Sequence[str] = ()
    #: ~/look_at's default description: share/<package>/urdf/<this>; None: <package>.urdf
    DESCRIPTION_NAME: str | None = None
    #: the ``joint_names`` parameter (``declare_common_parameters`` sets it)
    joint_names: list[str]
    #: the other common parameters of docs/interface.md, set the same way
    publish_rate: float
    diagnostics_period: float
    command_timeout: float
    reconnect_period: float
    presets_file: str
    goal_tolerance: float
    move_timeout: float
    motion_start_timeout: float
    stop_deceleration: float
    stop_margin: float
    autostart: bool
    #: N*m/A by joint (``torque_constants``): joint_states effort = current x this
    torque_constants: dict[str, float]

    def __init__(self, node_name: str, **kwargs: Any) -> None:  # rclpy Node's keywords
        super().__init__(node_name, **kwargs)
        self.parameter_registry = ParameterRegistry(self)
        self.config = declare_common_parameters(self)
        self.declare_device_parameters()
        self.controller: GimbalController | None = None
        self.motion: Motion | None = None
        #: the guarded device procedures (levelling, drift measurement): one at a time
        self.procedures: GuardedProcedures | None = None
        self.periodic = Periodic(on_error=self.get_logger().error)
        #: a driver's jobs that do device I/O (sensor topics): off the watchdog's thread
        self.sensor_jobs = Periodic(on_error=self.get_logger().error, name='sensors')
        #: refused joint_commands by reason (the ``joint_command`` diagnostics part), kept
        #: across configure/cleanup
        self.rejections = CommandRejections(self.get_logger())
        #: joint_command's delivery gaps (a dead-man stop the client did not cause)
        self.command_stream = CommandStream(self.get_logger(),
                                            lambda: self.config.command_timeout)
        self._active = False
        #: the lifecycle state this node's transitions left it in (rclpy keeps its own
        #: state machine private): unconfigured, inactive, active or finalized
        self.lifecycle_state = 'unconfigured'
        self._joint_rate = FrequencyMonitor(self.publish_rate)
        self.service_group = ReentrantCallbackGroup()
        #: goals accepted and not ended: run_driver lets them answer before it stops spinning
        self.open_goals = OpenGoals()
        self._create_ros_interfaces()
        self._declare_common_runtime_parameters()
        self.declare_runtime_parameters()
        self.parameter_registry.check_all()
        self.parameter_registry.attach()
        #: the core's and the driver's Python log records -> this node's logger (/rosout);
        #: installed last, so a node refused for its parameters leaves none behind
        self.log_bridge = install_log_bridge(self.get_logger(), type(self).__module__,
                                             self.LIBRARY_LOGGERS)

    # ------------------------------------------------------------------ hooks
    def declare_device_parameters(self) -> None:
        """Declare the driver's own parameters (use :meth:`declare_param`)."""

    def declare_runtime_parameters(self) -> None:
        """Mark the driver's parameters that apply at run time (use :meth:`runtime_parameter`)."""

    def make_device(self) -> Device:
        """Build the device adapter from the parameters (configure); raise GimbalError."""
        raise NotImplementedError

    def device_ready(self, device: Device) -> None:
        """Called after configure connected: start the driver's own periodic jobs etc."""

    # --------------------------------------------------------------- helpers
    def create_services(self, services: Iterable[tuple[type, str, Callable[..., Any]]]) -> None:
        """(type, name, callback) services in the reentrant service group: a service that
        waits on the device does not hold up ``~/stop`` or the others."""
        for srv_type, name, callback in services:
            self.create_service(srv_type, name, callback, callback_group=self.service_group)

    def create_accepting_action_server(self, action_type: type, name: str,
                                       execute: Callable[..., Any],
                                       on_cancel: Callable[[], None] = lambda: None,
                                       ) -> ActionServer:
        """An action server in the service group that accepts every goal and every cancel
        request (calling ``on_cancel``, so a waiting goal can look at once); ``execute``
        refuses a goal by aborting it with a message saying why."""
        def accept_cancel(_goal: object) -> CancelResponse:
            on_cancel()
            return CancelResponse.ACCEPT

        return ActionServer(self, action_type, name,
                            execute_callback=self.open_goals.tracked(execute),
                            goal_callback=self.open_goals.admit,
                            cancel_callback=accept_cancel, callback_group=self.service_group)

    def declare_param(self, name: str, default: object, description: str, **kwargs):
        """Declare a parameter with a descriptor; see :func:`ros.parameters.declare`."""
        return declare(self, name, default, description, **kwargs)

    def runtime_parameter(
        self, name: str, apply: Callable[[Any], None] | str,
        send: Callable[[Any], None] | None = None,
        busy: Callable[[], str | None] | None = None,
        check: Callable[[Any], object] | None = None,
    ) -> None:
        """Let ``ros2 param set`` change ``name`` while the node runs (see ParameterRegistry).

        ``apply`` stores the value (a string: the attribute to assign); ``send``
        pushes it to the device while connected; ``busy`` says why it cannot
        change now; ``check`` is the start-up value check. The value is of the
        parameter's declared type (float, list[str] ...), hence ``Any`` here.
        """
        if isinstance(apply, str):
            attribute = apply

            def apply(value: object) -> None:
                setattr(self, attribute, value)

        self.parameter_registry.make_runtime(name, apply, send=send, busy=busy, check=check)

    def parameter_check(self, names: Sequence[str], check: Callable) -> None:
        """A check over several parameters, run at start-up and on every set of one of them."""
        self.parameter_registry.add_check(names, check)

    @property
    def device(self) -> Device | None:
        return self.controller.device if self.controller else None

    @property
    def connected(self) -> bool:
        return bool(self.controller and self.controller.connected)

    @property
    def active(self) -> bool:
        return self._active

    def current_positions(self) -> dict[str, float]:
        return self.controller.positions() if self.controller else {}

    def command_refusal(self) -> str | None:
        """Why commands cannot be served now (inactive, disconnected), or None."""
        if self.controller is None:
            return NOT_CONFIGURED
        return self.controller.refusal()

    def configured(self) -> GimbalController:
        """The controller configure built; before it (or after cleanup) a refusal that
        says so, for a request path that needs the controller itself."""
        if self.controller is None:
            raise DeviceRefused(NOT_CONFIGURED)
        return self.controller

    def motion_refusal(self, joints: Sequence[str]) -> str | None:
        """command_refusal() or the device's reason these joints cannot move."""
        if self.controller is None:
            return self.command_refusal()
        return self.controller.refusal(list(joints))

    def serve_request(self, response: AnswerT, action: Callable[[], str]) -> AnswerT:
        """Answer a service with ``success``/``message`` from ``action()``.

        Refused while inactive or disconnected; a GimbalError becomes
        ``success=false`` with its message; anything else too, with a traceback
        in the log unless the link dropped meanwhile.
        """
        refusal = self.command_refusal()
        if refusal:
            response.success, response.message = False, refusal
            return response
        return self._answer(response, action)

    def _answer(self, response: AnswerT, action: Callable[[], str]) -> AnswerT:
        try:
            response.message = action() or 'done'
            response.success = True
        except GimbalError as exc:
            response.success, response.message = False, str(exc)
        except Exception as exc:  # noqa: BLE001 - services answer, never raise
            response.success, response.message = False, f'{type(exc).__name__}: {exc}'
            if self.connected:
                self.get_logger().error(traceback.format_exc())
        return response

    @property
    def limits(self) -> dict[str, JointLimits]:
        return self.config.limits

    # ------------------------------------------------------------ parameters
    def _declare_common_runtime_parameters(self) -> None:
        def set_publish_rate(rate: float) -> None:
            self.config.publish_rate = self.publish_rate = rate
            self._joint_rate.expected_hz = rate
            self.periodic.set_period(self._publish_status, self._status_period())
            if self.controller:
                self.controller.set_publish_rate(rate)

        def set_diagnostics_period(period: float) -> None:
            self.diagnostics_period = period
            self.periodic.set_period(self._publish_diagnostics, period)

        def set_command_timeout(timeout: float) -> None:
            self.config.command_timeout = self.command_timeout = timeout
            if self.controller:
                self.controller.set_command_timeout(timeout)

        def set_config(name: str) -> Callable[[object], None]:
            def apply(value: object) -> None:
                setattr(self.config, name, value)
                setattr(self, name, value)
            return apply

        def set_limits(_: object) -> None:
            self.config.limits = self._limits_from(self.parameter_registry.current)

        self.runtime_parameter('publish_rate', set_publish_rate)
        self.runtime_parameter('diagnostics_period', set_diagnostics_period)
        self.runtime_parameter('command_timeout', set_command_timeout)
        for name in ('reconnect_period', 'goal_tolerance', 'move_timeout',
                     'motion_start_timeout', 'stop_deceleration', 'stop_margin'):
            self.runtime_parameter(name, set_config(name))
        limit_names = ('position_min', 'position_max', 'velocity_max')
        for name in limit_names:
            self.runtime_parameter(name, set_limits)
        self.parameter_check(limit_names, self._limits_from)

    def _status_period(self) -> float:
        return 1.0 / min(self.config.publish_rate, 10.0)

    # --------------------------------------------------------- ROS interfaces
    def create_publisher(self, *args: Any, event_callbacks: PublisherEventCallbacks | None = None,
                         **kwargs: Any):
        """rclpy's ``create_publisher`` without its default QoS-event handlers.

        rclpy gives every publisher two Python waitables (incompatible QoS, incompatible
        type) that its executor checks one by one after every wake-up, before it reaches
        the ``joint_command`` subscription: measured (bench node trace, Capture's 10
        publishers), wait return -> callback 0.29 -> 0.22 ms. A mismatch is still logged
        by the subscriber's own default handler (``ros2 topic echo``, rosbag) and by ours
        for what this node subscribes to.
        """
        if event_callbacks is None:
            event_callbacks = PublisherEventCallbacks(use_default_callbacks=False)
        return super().create_publisher(*args, event_callbacks=event_callbacks, **kwargs)

    def _create_ros_interfaces(self) -> None:
        guard_change_state_service(self, lambda: self.lifecycle_state)
        state_qos = QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE, history=HistoryPolicy.KEEP_LAST)
        self._joint_pub = self.create_publisher(JointState, 'joint_states', state_qos)
        self._joint_message = messages.JointStateMessage()  # refilled per sample
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._status_pub = self.create_publisher(GimbalStatus, '~/status', 10)
        # keep-last 1 (docs/interface.md): newest wins; the callback never waits on the device,
        # so run_driver's executor runs it inline (ros/run.py InlineGroupExecutor). Two
        # arguments: rclpy hands the message info too (Subscription.callback reads the
        # signature), which rclpy 7's annotation of create_subscription does not know of
        command_group = InlineCallbackGroup()
        self.create_subscription(JointState, 'joint_command',
                                 self._on_joint_command,  # type: ignore[arg-type]
                                 1, callback_group=command_group)
        services = [
            (Trigger, '~/stop', self._on_stop),
            (Trigger, '~/reset_faults', self._on_reset_faults),
            (SetPreset, '~/set_preset', self._on_set_preset),
            (GotoPreset, '~/goto_preset', self._on_goto_preset),
            (ListPresets, '~/list_presets', self._on_list_presets),
            (ClearPreset, '~/clear_preset', self._on_clear_preset),
            (StartScan, '~/start_scan', self._on_start_scan),
            (Trigger, '~/stop_scan', self._on_stop_scan),
        ]
        self.create_services(services)
        self.motion_actions = actions = MotionActions(self)
        self.create_accepting_action_server(MoveTo, '~/move_to', actions.execute_move)
        self.create_accepting_action_server(Home, '~/home', actions.execute_home)
        # ~/look_at (ros/look_at.py) runs through execute_move; ~/look_at_geo the same path
        self.look_at_server = LookAtServer(self, actions, type(self).__module__.split('.')[0],
                                           self.DESCRIPTION_NAME)
        self.look_at_geo_server = LookAtGeoServer(self, self.look_at_server, actions)
        self.periodic.add(self.diagnostics_period, self._publish_diagnostics)
        self.periodic.add(self._status_period(), self._publish_status)

    def destroy_node(self) -> None:
        self.periodic.stop()
        self.sensor_jobs.stop()
        self.log_bridge.remove()
        super().destroy_node()

    # -------------------------------------------------------------- lifecycle
    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Build the ROS-free device and controller, then connect (ros2_socketcan style)."""
        try:
            store = PresetStore(self.presets_file)
            device = self.make_device()
            controller = GimbalController(
                device, self.config, self.get_logger(), on_sample=self._publish_joint_state,
                on_link_change=self._publish_diagnostics, periodic=self.periodic,
                sensors=self.sensor_jobs, rejections=self.rejections)
            self.controller = controller
            self.motion = Motion(controller, store, self.SCAN_PATTERNS)
            self.procedures = GuardedProcedures(self.motion)
            controller.open()
            self.device_ready(device)
        except Exception as exc:  # noqa: BLE001 - any failure means "device not there"
            self.get_logger().error(f'configure failed: cannot reach the device: {exc}')
            if self.controller is not None:
                self.controller.close()
            return TransitionCallbackReturn.FAILURE
        self.lifecycle_state = 'inactive'
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = True
        if self.controller:
            self.controller.activate()
        self.get_logger().info('active: publishing joint_states and accepting commands')
        self.lifecycle_state = 'active'
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = False
        if self.controller:
            self.controller.deactivate()
        self.lifecycle_state = 'inactive'
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        if self.controller:
            self.controller.close()
        self.lifecycle_state = 'unconfigured'
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        self._active = False
        if self.controller:
            self.controller.shutdown()
        self.lifecycle_state = 'finalized'
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = self.on_shutdown(state)
        self.lifecycle_state = 'unconfigured'  # a handled error leads back to unconfigured
        return result

    # ---------------------------------------------------------- topics
    def _publish_joint_state(self, sample: JointSample) -> None:
        if self.context.ok():
            self._joint_pub.publish(self._joint_message.fill(sample, self.joint_names,
                                                             self.torque_constants))
            self._joint_rate.tick()

    def _publish_diagnostics(self) -> None:
        ctl = self.controller
        self._joint_rate.sample(time.monotonic(),
                                live=self._active and ctl is not None and ctl.connected)
        parts = messages.diagnostic_parts(ctl, self.joint_names, self._joint_rate, self._active)
        parts.append(self.rejections.status_part(self.command_stream.values()))
        hardware_id = ctl.device_info.hardware_id if ctl else DeviceInfo().hardware_id
        self._diag_pub.publish(messages.diagnostic_array(
            self.get_name(), self.get_clock().now().to_msg(), hardware_id, parts))

    def _publish_status(self) -> None:
        # Built only while someone listens (ros2 topic echo, rosbag, a supervisor): a
        # GimbalStatus at 10 Hz that nobody reads was most of the housekeeping thread's
        # CPU. A new subscriber gets its first message within one status period.
        if not self._status_pub.get_subscription_count():
            return
        msg = messages.gimbal_status(self.controller, self.joint_names, self.torque_constants)
        msg.header.stamp = self.get_clock().now().to_msg()
        self._status_pub.publish(msg)

    def _on_joint_command(self, msg: JointState, info: dict[str, Any]) -> None:
        # rclpy's message info: the publisher's timestamp and sequence number
        self.command_stream.took(info['source_timestamp'], info.get('publication_sequence_number'))
        try:
            if self.controller is None:
                raise DeviceRefused(self.command_refusal(), reason='node not active')
            self.controller.command(msg.name, msg.position, msg.velocity)
        except GimbalError as exc:  # counted by reason, logged once per reason every 5 s
            self.rejections.record(exc)

    # ---------------------------------------------------------- services
    def _on_stop(self, request: Trigger.Request, response: Trigger.Response):
        if self.controller is None:
            response.success, response.message = False, 'node is not configured; nothing to stop'
            return response
        return self._answer(response, self.controller.stop)

    def _configured(self) -> tuple[GimbalController, Motion]:
        """What configure built; refused (the node's reason) before it. A service reaches
        this through :meth:`serve_request`, which refuses first."""
        controller, motion = self.controller, self.motion
        if controller is None or motion is None:
            raise DeviceRefused(self.command_refusal())
        return controller, motion

    def _on_reset_faults(self, request: Trigger.Request, response: Trigger.Response):
        return self.serve_request(response, lambda: self._configured()[0].reset_faults())

    def _on_set_preset(self, request: SetPreset.Request, response: SetPreset.Response):
        def action() -> str:
            positions = None
            if not request.use_current_position:
                if len(request.joint_names) != len(request.positions):
                    raise InvalidRequest(f'{len(request.joint_names)} joint names but '
                                         f'{len(request.positions)} positions')
                positions = dict(zip(request.joint_names, request.positions, strict=True))
            return self._configured()[1].set_preset(request.index, request.name, positions)

        return self.serve_request(response, action)

    def _on_goto_preset(self, request: GotoPreset.Request, response: GotoPreset.Response):
        return self.serve_request(
            response, lambda: self._configured()[1].goto_preset(request.index, request.speed))

    def _on_list_presets(self, request: ListPresets.Request, response: ListPresets.Response):
        motion = self.motion
        if motion is None:
            return self.serve_request(response, lambda: '')

        def action() -> str:
            presets = motion.list_presets()
            response.presets = [Preset(index=p.index, name=p.name,
                                       joint_names=list(p.positions),
                                       positions=list(p.positions.values())) for p in presets]
            return f'{len(presets)} preset(s)'

        return self._answer(response, action)

    def _on_clear_preset(self, request: ClearPreset.Request, response: ClearPreset.Response):
        motion = self.motion
        if motion is None:
            return self.serve_request(response, lambda: '')
        index = None if request.all else request.index
        return self._answer(response, lambda: motion.clear_preset(index))

    def _on_start_scan(self, request: StartScan.Request, response: StartScan.Response):
        return self.serve_request(
            response, lambda: self._configured()[1].start_scan(ScanRequest.from_msg(request)))

    def _on_stop_scan(self, request: Trigger.Request, response: Trigger.Response):
        return self.serve_request(response, lambda: self._configured()[1].stop_scan())

    def _limits_from(self, value_of: Callable[[str], object]) -> dict[str, JointLimits]:
        return limits_from(self.joint_names, value_of)
