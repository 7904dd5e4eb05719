"""ROS 2 node for Capture pedestals: parameters, the device adapter and the device's extras.

The shared :class:`GimbalDriverNode` and its controller own the lifecycle, joint_states,
joint_command, ~/stop, ~/move_to, ~/home, presets, scans, diagnostics and the reconnect
loop; :class:`~.device.CaptureDevice` speaks the device in SI units. This node declares the
parameters, builds the adapter and adds the device's own topics and services: ~/imu, ~/fix,
~/heading, ~/range, ~/tracking_state, ~/digital_io, ~/goto_lla, ~/set_stabilization,
~/set_emergency_stop, ~/set_ranging, ~/set_tracking, ~/set_digital_output_<n>, ~/enable,
preset and target loops, ~/level, the gyro drift actions and the ~/command service that
runs any in-scope table entry by name.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TypeVar

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.lifecycle import LifecycleState, TransitionCallbackReturn
from rclpy.publisher import Publisher
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus, Range
from std_msgs.msg import MultiArrayDimension, UInt8MultiArray
from std_srvs.srv import SetBool, Trigger

from gimbal_driver_common.device import Device
from gimbal_driver_common.errors import (
    DeviceRefused,
    GimbalError,
    Unsupported,
)
from gimbal_driver_common.orientation import quaternion_from_euler
from gimbal_driver_common.ros.base_node import Answer, GimbalDriverNode
from gimbal_driver_common.ros.heading import heading_imu
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.ros.run import run_driver
from gimbal_msgs.srv import DeviceCommand, SetMode

from .capabilities import CaptureScans
from .device import CaptureDevice, CaptureSettings
from .functions import DIGITAL_IO_COUNT, CaptureFunctions

T = TypeVar('T')

#: parameters the adapter reads at run time (``ros2 param set`` updates its settings)
DEVICE_RUNTIME_PARAMETERS = ('default_speed', 'acceleration', 'status_period',
                             'gps_target_slot', 'home_timeout')


class CaptureDriverNode(GimbalDriverNode):
    """Capture pan-tilt pedestal driver (TCP port 4949 or RS-232/422/485)."""

    DEFAULT_JOINT_NAMES = ('pan', 'tilt')
    DEFAULT_POSITION_MIN = (-math.pi, -math.pi / 2)
    DEFAULT_POSITION_MAX = (math.pi, math.pi / 2)
    DEFAULT_VELOCITY_MAX = (1.5, 1.5)
    SCAN_PATTERNS = CaptureScans.patterns

    def __init__(self, **kwargs: object) -> None:
        super().__init__('capture_driver', **kwargs)
        self._imu_pub = self.create_publisher(Imu, '~/imu', 10)
        self._fix_pub = self.create_publisher(NavSatFix, '~/fix', 10)
        self._range_pub = self.create_publisher(Range, '~/range', 10)
        self._tracking_pub = self.create_publisher(DiagnosticStatus, '~/tracking_state', 10)
        self._dio_pub = self.create_publisher(UInt8MultiArray, '~/digital_io', 10)
        self._heading_pub = self.create_publisher(Imu, '~/heading', 10)
        self.create_services([
            (SetBool, '~/set_stabilization', self._on_stabilization),
            (Trigger, '~/start_preset_loop', self._on_start_loop),
            (Trigger, '~/stop_preset_loop', self._on_stop_loop),
            (SetBool, '~/set_emergency_stop', self._on_emergency_stop),
            (DeviceCommand, '~/command', self._on_command),
            (SetBool, '~/set_ranging', self._on_set_ranging),
            (SetMode, '~/set_tracking', self._on_set_tracking),
            (SetBool, '~/enable', self._on_enable),
            (Trigger, '~/start_target_loop', self._on_start_target_loop),
            (Trigger, '~/stop_target_loop', self._on_stop_target_loop),
            (Trigger, '~/reset_gyro_drift', self._on_reset_gyro_drift),
            *[(SetBool, f'~/set_digital_output_{number}',
               lambda request, response, n=number: self._on_set_output(n, request, response))
              for number in self.digital_outputs],
        ])
        self.create_subscription(NavSatFix, '~/goto_lla', self._on_goto_lla, 1,
                                 callback_group=self.service_group)
        # guarded device procedures: the core's policy runs them (gimbal_driver_common.guarded)
        self.motion_actions.create_procedure_action(
            '~/level', lambda device, joints: functions_of(device).levelling(joints))
        self.motion_actions.create_procedure_action(
            '~/compensate_gyro_drift',
            lambda device, joints: functions_of(device).gyro_drift_measurement(
                joints, self.gyro_drift_time))

    # ------------------------------------------------------------ parameters
    def declare_device_parameters(self) -> None:
        p = self.declare_param
        n = len(self.joint_names)
        self.transport = p('transport', 'tcp', 'link to the controller', choices=('tcp', 'serial'))
        self.host = p('host', '192.168.10.120', 'controller IP address (transport tcp)')
        self.port = p('port', 4949, 'controller TCP port', value_range=(1, 65535))
        self.serial_port = p('serial_port', '/dev/ttyUSB0', 'serial device (transport serial)')
        self.baudrate = p('baudrate', 115200, 'serial baud rate (8N1)', value_range=(1200, 921600))
        self.group_id = p('group_id', 0, 'pedestal group id (0 for a single pedestal)',
                          value_range=(0, 255))
        self.axis_ids = p('axis_ids', [1, 2][:n] + [3] * max(0, n - 2),
                          'Capture axis id per joint (1 yaw/pan, 2 pitch/tilt, 3 roll)',
                          element_type=int)
        self.joint_directions = p('joint_directions', [-1.0, 1.0][:n] + [1.0] * max(0, n - 2),
                                  'per joint: +1 if the device counts like REP-103, -1 if '
                                  'opposite (Capture yaw is clockwise, so pan defaults to -1)')
        self.gear_ratios = p('gear_ratios', [1.0] * n,
                             'motor/load ratio per joint (scan limits are motor degrees, 4.3.1)')
        self.default_speed = p('default_speed', 0.5, 'rad/s for moves given without a speed',
                               value_range=(1e-3, 100.0))
        self.acceleration = p('acceleration', 3.0, 'rad/s^2 for moves and jogs',
                              value_range=(1e-3, 1000.0))
        self.request_timeout = p('request_timeout', 0.5, 's to wait for each reply',
                                 value_range=(0.01, 30.0))
        self.batch_reads = p('batch_reads', True,
                             'send the poll\'s getters (position and speed of every axis, '
                             'status registers) in one write and match the replies by opcode '
                             'and axis; false: one request at a time')
        self.keepalive_period = p('keepalive_period', 0.5,
                                  's; the controller stops the axes after 3 silent periods '
                                  '(0 disables the controller keep-alive)',
                                  value_range=(0.0, 60.0))
        self.status_period = p('status_period', 0.5, 's between register/current reads',
                               value_range=(0.05, 60.0))
        self.imu_rate = p('imu_rate', 10.0, 'Hz for ~/imu (0 disables)', value_range=(0.0, 100.0))
        self.fix_rate = p('fix_rate', 1.0, 'Hz for ~/fix (0 disables)', value_range=(0.0, 20.0))
        self.imu_frame_id = p('imu_frame_id', 'capture_imu', 'frame_id of ~/imu')
        self.gps_frame_id = p('gps_frame_id', 'capture_gps', 'frame_id of ~/fix')
        self.gps_target_slot = p('gps_target_slot', 15, 'device target number used by ~/goto_lla',
                                 value_range=(1, 15))
        self.home_timeout = p('home_timeout', 120.0, 's before a homing goal fails',
                              value_range=(1.0, 3600.0))
        self.allow_nv_write = p('allow_nv_write', False,
                                'opt-in for ~/command entries that write controller memory')
        self.allow_reboot = p('allow_reboot', False,
                              'opt-in for ~/command entries that reboot or reset')
        self.allow_network_config = p('allow_network_config', False,
                                      'opt-in for ~/command entries that change IP/port')
        for label, values in (('axis_ids', self.axis_ids),
                              ('joint_directions', self.joint_directions),
                              ('gear_ratios', self.gear_ratios)):
            if len(values) != n:
                raise ParameterError(f'parameter {label!r}: {len(values)} values for {n} joints')
        if len(set(self.axis_ids)) != n or any(a not in (1, 2, 3) for a in self.axis_ids):
            raise ParameterError(f"parameter 'axis_ids': need distinct ids in 1..3, got "
                                 f'{self.axis_ids}')
        if any(d not in (-1.0, 1.0) for d in self.joint_directions):
            raise ParameterError("parameter 'joint_directions': each value must be 1 or -1")
        if any(not math.isfinite(g) or g == 0.0 for g in self.gear_ratios):
            raise ParameterError("parameter 'gear_ratios': values must be finite and non-zero")
        self._declare_device_function_parameters()
        self.settings = CaptureSettings(
            joint_names=list(self.joint_names), axis_ids=list(self.axis_ids),
            joint_directions=list(self.joint_directions), gear_ratios=list(self.gear_ratios),
            transport=self.transport, host=self.host, port=self.port,
            serial_port=self.serial_port, baudrate=self.baudrate, group_id=self.group_id,
            request_timeout=self.request_timeout, keepalive_period=self.keepalive_period,
            batch_reads=self.batch_reads, default_speed=self.default_speed,
            acceleration=self.acceleration,
            status_period=self.status_period, home_timeout=self.home_timeout,
            gps_target_slot=self.gps_target_slot, tracker_camera=self.tracker_camera,
            gyro_drift_sensor=self.gyro_drift_sensor, allow_nv_write=self.allow_nv_write,
            allow_reboot=self.allow_reboot, allow_network_config=self.allow_network_config)

    def _declare_device_function_parameters(self) -> None:
        p = self.declare_param
        self.range_rate = p('range_rate', 5.0, 'Hz for ~/range while ranging is on (0 disables)',
                            value_range=(0.0, 50.0))
        self.range_frame_id = p('range_frame_id', 'capture_lrf', 'frame_id of ~/range')
        self.range_field_of_view = p(
            'range_field_of_view', 0.002,
            'rad, ~/range field_of_view: the beam divergence from your LRF datasheet',
            value_range=(1e-6, math.pi))
        self.range_min = p('range_min', 5.0, 'm, ~/range min_range: from your LRF datasheet',
                           value_range=(0.0, 1e6))
        self.range_max = p('range_max', 5000.0, 'm, ~/range max_range: from your LRF datasheet',
                           value_range=(0.0, 1e6))
        if self.range_min >= self.range_max:
            raise ParameterError(f"parameters 'range_min' {self.range_min} and 'range_max' "
                                 f'{self.range_max}: min must be below max')
        self.tracker_camera = p('tracker_camera', 0,
                                'video tracker camera index (sent in the group byte, 4.11)',
                                value_range=(0, 3))
        self.tracking_rate = p('tracking_rate', 2.0, 'Hz for ~/tracking_state (0 disables)',
                               value_range=(0.0, 50.0))
        self.digital_outputs = p('digital_outputs', list(range(1, DIGITAL_IO_COUNT + 1)),
                                 'digital I/O numbers (1..6) ~/set_digital_output_<n> may set',
                                 element_type=int, value_range=(1, DIGITAL_IO_COUNT))
        self.digital_io_rate = p('digital_io_rate', 2.0, 'Hz for ~/digital_io (0 disables)',
                                 value_range=(0.0, 50.0))
        self.heading_accuracy = p('heading_accuracy', 0.0,
                                  'rad, 1-sigma of the GPS heading for ~/heading covariance '
                                  '(0 = unknown: a large variance)', value_range=(0.0, math.pi))
        self.gyro_drift_sensor = p('gyro_drift_sensor', 2,
                                   'IMU for drift compensation (0 client, 1 base, 2 load, '
                                   '3 middle; 4.5.28)', value_range=(0, 3))
        self.gyro_drift_time = p('gyro_drift_time', 10.0,
                                 's the pedestal is held still while the controller measures '
                                 'the gyro drift (the spec gives no duration)',
                                 value_range=(0.5, 600.0))
        if len(set(self.digital_outputs)) != len(self.digital_outputs):
            raise ParameterError(f"parameter 'digital_outputs': duplicate numbers in "
                                 f'{self.digital_outputs}')

    # ------------------------------------------------- run-time parameters
    def declare_runtime_parameters(self) -> None:
        """Capture parameters that apply when set: speeds, rates, timeouts, frame ids.

        The link, axis mapping (axis_ids, joint_directions, gear_ratios), keep-alive and
        the opt-ins (allow_*) need a reconfigure: the opt-ins guard commands that can cut
        off or brick the controller and are given at start-up only.
        """
        def device_setting(name: str) -> Callable[[object], None]:
            def apply(value: object) -> None:
                setattr(self, name, value)
                setattr(self.settings, name, value)
            return apply

        def sensor_rate(name: str) -> Callable[[object], None]:
            def apply(value: object) -> None:
                setattr(self, name, value)
                for job, rate_name in self._sensor_jobs():
                    if rate_name == name:
                        self.sensor_jobs.set_period(job, self._job_period(rate_name))
            return apply

        for name in DEVICE_RUNTIME_PARAMETERS:
            self.runtime_parameter(name, device_setting(name))
        for name in ('imu_rate', 'fix_rate'):
            self.runtime_parameter(name, sensor_rate(name))
        for name in ('imu_frame_id', 'gps_frame_id'):
            self.runtime_parameter(name, name)

    # ---------------------------------------------------------------- device
    def make_device(self) -> Device:
        return CaptureDevice(self.settings)  # the controller attaches config and logger

    def device_ready(self, device: Device) -> None:
        """The sensor topics start (device-run motions report their targets through the
        device contract, ``Device.report_targets``)."""
        for job, rate_name in self._sensor_jobs():
            self.sensor_jobs.remove(job)  # a reconfigure adds them again
            self.sensor_jobs.add(self._job_period(rate_name), job)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)
        for job, _ in self._sensor_jobs():  # publish at once, as the first poll did
            self.sensor_jobs.trigger(job)
        return result

    def _device_call(self, request: Callable[[CaptureFunctions], T],
                     joints: Sequence[str] | None = None) -> T:
        """One request to the device's functions (its part ``functions``) through the
        controller's ``call()`` boundary (refused while inactive, disconnected or, with
        ``joints``, while they cannot move)."""
        controller = self.configured()
        return controller.call(lambda: request(functions_of(controller.device)), joints)

    def _device_service(self, response: Answer, request: Callable[[CaptureFunctions], str],
                        joints: Sequence[str] | None = None) -> Answer:
        """Answer a service with one adapter call (refusals and errors: success=false)."""
        return self.serve_request(response, lambda: self._device_call(request, joints))

    # ----------------------------------------------------------- sensor topics
    def _sensor_jobs(self) -> list[tuple[Callable[[], None], str]]:
        return [(self._publish_imu, 'imu_rate'), (self._publish_fix, 'fix_rate'),
                (self._publish_heading, 'fix_rate'), (self._publish_range, 'range_rate'),
                (self._publish_tracking, 'tracking_rate'),
                (self._publish_digital_io, 'digital_io_rate')]

    def _job_period(self, rate_name: str) -> float:
        rate = getattr(self, rate_name)
        return 1.0 / rate if rate > 0 else 1.0  # at rate 0 the job looks once a second

    def _read_sensor(self, name: str, publisher: Publisher,
                     available: Callable[[CaptureFunctions], bool],
                     rate: float, read: Callable[[CaptureFunctions], T]) -> T | None:
        """One sensor read while active, connected, the device has the sensor and someone
        subscribes to its topic; a failed read is a throttled warning, never an exception.
        A getter the device does not answer with data stops the topic (the functions clear
        its flag), said here once.

        Without a subscriber the read is skipped: each is one or more request/reply
        transactions (the IMU six) that would take the link from commands and polls, and
        measured, a third of an idle node's CPU (bench/HISTORY.md).
        """
        if rate <= 0 or not self.active or not self.connected:
            return None
        if publisher.get_subscription_count() == 0:
            return None
        try:
            return self._device_call(lambda device: read(device) if available(device) else None)
        except Unsupported as exc:
            self.get_logger().warning(f'{name} not read any more on this connection: {exc}')
        except GimbalError as exc:
            self.get_logger().warning(f'{name} read failed: {exc}', throttle_duration_sec=10.0)
        return None

    def _publish_imu(self) -> None:
        reading = self._read_sensor('IMU', self._imu_pub, lambda d: d.has_imu, self.imu_rate,
                                    lambda d: d.imu())
        if reading is None:
            return
        msg = Imu()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.imu_frame_id
        x, y, z, w = quaternion_from_euler(reading.roll, reading.pitch, reading.yaw)
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = x, y, z, w
        (msg.angular_velocity.x, msg.angular_velocity.y,
         msg.angular_velocity.z) = reading.rates
        msg.linear_acceleration_covariance[0] = -1.0  # the protocol reports no acceleration
        self._imu_pub.publish(msg)

    def _publish_fix(self) -> None:
        fix = self._read_sensor('GPS', self._fix_pub, lambda d: d.has_gps, self.fix_rate,
                                lambda d: d.gps_fix())
        if fix is None:  # also: the device refused a GPS getter, the poll stops
            return
        msg = NavSatFix()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.gps_frame_id
        msg.status.status = NavSatStatus.STATUS_FIX if fix.ready else NavSatStatus.STATUS_NO_FIX
        msg.status.service = NavSatStatus.SERVICE_GPS
        msg.latitude, msg.longitude, msg.altitude = fix.latitude, fix.longitude, fix.altitude
        msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
        self._fix_pub.publish(msg)

    def _publish_heading(self) -> None:
        read = self._read_sensor('heading', self._heading_pub, lambda d: d.has_heading,
                                 self.fix_rate, lambda d: (d.gps_heading(),))
        if read is None:
            return
        (heading,) = read
        if heading is None:
            self.get_logger().warning('GPS heading not valid (GPS_HeadingReady 0): ~/heading '
                                      'not published', throttle_duration_sec=10.0)
            return
        msg = heading_imu(heading, self.heading_accuracy)
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.gps_frame_id
        self._heading_pub.publish(msg)

    def _publish_range(self) -> None:
        distance = self._read_sensor('range', self._range_pub, lambda d: d.ranging, self.range_rate,
                                     lambda d: d.range_m())
        if distance is None:
            return
        msg = Range()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.range_frame_id
        msg.radiation_type = Range.INFRARED  # laser rangefinders are near/short-wave IR
        msg.field_of_view = float(self.range_field_of_view)
        msg.min_range, msg.max_range = float(self.range_min), float(self.range_max)
        msg.range = distance  # REP-117: +inf = no return within range
        self._range_pub.publish(msg)

    def _publish_tracking(self) -> None:
        state = self._read_sensor('tracking', self._tracking_pub,
                                  lambda d: d.has_tracker, self.tracking_rate,
                                  lambda d: d.tracking_state())
        if state is None:
            return
        self._tracking_pub.publish(DiagnosticStatus(
            level=DiagnosticStatus.OK, name=f'{self.get_name()}: video tracker',
            hardware_id=self.configured().device_info.hardware_id,
            message=(f'camera {state.camera}: mode {state.mode}, tracking '
                     f'{"active" if state.active else "inactive"}, target '
                     f'{"detected" if state.target_detected else "not detected"}'),
            values=[KeyValue(key='camera', value=str(state.camera)),
                    KeyValue(key='mode', value=state.mode),
                    KeyValue(key='tracking_active', value=str(state.active).lower()),
                    KeyValue(key='target_detected', value=str(state.target_detected).lower())],
        ))

    def _publish_digital_io(self) -> None:
        states = self._read_sensor('digital_io', self._dio_pub, lambda d: d.has_digital_io,
                                   self.digital_io_rate, lambda d: d.digital_io())
        if states is None:
            return
        msg = UInt8MultiArray()
        msg.layout.dim = [MultiArrayDimension(label='digital_io_1_to_6',
                                              size=DIGITAL_IO_COUNT, stride=DIGITAL_IO_COUNT)]
        msg.data = states
        self._dio_pub.publish(msg)

    # -------------------------------------------------------------- services
    def _on_stabilization(self, request, response):
        return self._device_service(response, lambda d: d.set_stabilization(request.data))

    def _on_emergency_stop(self, request, response):
        return self._device_service(response, lambda d: d.set_emergency_stop(request.data))

    def _on_start_loop(self, request, response):
        return self._device_service(response, lambda d: d.start_preset_loop())

    def _on_stop_loop(self, request, response):
        return self._stop_program(response, lambda d: d.stop_preset_loop(),
                                  'preset looping stopped')

    def _on_start_target_loop(self, request, response):
        return self._device_service(response, lambda d: d.start_target_loop(),
                                    self.joint_names[:2])

    def _on_stop_target_loop(self, request, response):
        return self._stop_program(response, lambda d: d.stop_target_loop(),
                                  'target looping stopped')

    def _stop_program(self, response: Answer, stop: Callable[[CaptureFunctions], None],
                      message: str) -> Answer:
        """End a device program (loop), then stop every axis as ~/stop does: two calls to
        the controller, one after the other."""
        def run() -> str:
            self._device_call(stop)
            self.configured().stop()
            return message

        return self.serve_request(response, run)

    def _on_reset_gyro_drift(self, request, response):
        return self._device_service(response, lambda d: d.reset_gyro_drift())

    def _on_set_ranging(self, request, response):
        def ranging(device: CaptureFunctions) -> str:
            message = device.set_ranging(request.data)
            if request.data:
                self.sensor_jobs.trigger(self._publish_range)
                message += f': ~/range at {self.range_rate:g} Hz'
            return message

        return self._device_service(response, ranging)

    def _on_set_tracking(self, request, response):
        def tracking(device: CaptureFunctions) -> str:
            message = device.set_tracking(request.mode)
            self.sensor_jobs.trigger(self._publish_tracking)
            return message

        return self._device_service(response, tracking)

    def _on_set_output(self, number: int, request, response):
        def output(device: CaptureFunctions) -> str:
            message = device.set_digital_output(number, request.data)
            self.sensor_jobs.trigger(self._publish_digital_io)
            return message

        return self._device_service(response, output)

    def _on_enable(self, request, response):
        def enable() -> str:
            if request.data:
                faulted = self._device_call(lambda device: device.faulted_joints())
                if faulted:
                    raise DeviceRefused(f'{", ".join(faulted)}: drive in fault; call '
                                        '~/reset_faults (it switches the drives on)')
            else:  # stop first (moves, jogs, scans, loops): MOT_AxisOff under motion coasts
                try:
                    self.configured().stop()
                except GimbalError as exc:
                    raise DeviceRefused(f'stop before switching off failed: {exc}') from exc
            return self._device_call(lambda device: device.set_power(request.data))

        return self.serve_request(response, enable)

    def _on_command(self, request, response):
        def run(device: CaptureFunctions) -> str:
            message, response.results = device.command(
                request.command, request.axis, list(request.arguments))
            return message

        return self._device_service(response, run)

    def _on_goto_lla(self, msg: NavSatFix) -> None:
        refusal = self.command_refusal()
        if refusal:
            self.get_logger().warning(f'~/goto_lla ignored: {refusal}')
            return
        try:
            pose = self._device_call(lambda device: device.goto_lla(
                msg.latitude, msg.longitude, msg.altitude))
        except GimbalError as exc:
            self.get_logger().error(f'~/goto_lla refused, nothing moved: {exc}')
            return
        self.get_logger().info(
            f'aiming at lat {msg.latitude:.6f} lon {msg.longitude:.6f}: '
            + ', '.join(f'{j} {p:+.4f} rad' for j, p in pose.items()))


def functions_of(device: Device) -> CaptureFunctions:
    """The functions part of the adapter this node's make_device() built."""
    assert isinstance(device, CaptureDevice)
    return device.functions


def main(args: Sequence[str] | None = None) -> int:
    return run_driver(CaptureDriverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
