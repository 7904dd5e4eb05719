"""ROS 2 node for Capture pedestals: a thin layer over :class:`~.client.CaptureClient`.

The shared :class:`GimbalDriverNode` owns the lifecycle, joint_states, joint_command,
~/stop, ~/move_to, ~/home, presets, scans, diagnostics and the reconnect loop; this class
translates them to Capture commands (SI <-> device degrees, REP-103 signs) and adds the
device's extras: ~/imu, ~/fix, ~/goto_lla, ~/set_stabilization, preset looping and the
~/command service that runs any in-scope table entry by name.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from sensor_msgs.msg import Imu, NavSatFix, NavSatStatus, Range
from std_msgs.msg import MultiArrayDimension, UInt8MultiArray
from std_srvs.srv import SetBool, Trigger

from gimbal_driver_common.device import DeviceInfo, JointSample
from gimbal_driver_common.diagnostics import ActiveFlag, Level
from gimbal_driver_common.joint_command import CommandError, validate_joint_command
from gimbal_driver_common.ros.diagnostics import StatusPart
from gimbal_driver_common.ros.heading import heading_imu
from gimbal_driver_common.ros.legacy import DeviceError
from gimbal_driver_common.ros.legacy import HookedDriverNode as GimbalDriverNode
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.ros.run import run_driver
from gimbal_driver_common.scan import ScanError, ScanRequest
from gimbal_driver_common.transport import SerialStream, TcpStream
from gimbal_msgs.action import Home
from gimbal_msgs.msg import AxisState, Preset
from gimbal_msgs.srv import DeviceCommand, SetMode

from .client import (
    SCAN_COMMANDS,
    CaptureClient,
    CaptureError,
    DeviceNack,
    DeviceTimeout,
    Identity,
    NotConnected,
)
from .protocol import COMMANDS, DataType, GeoPoint, PresetRecord, ProtocolError, Safety
from .protocol import command as lookup_command
from .protocol.geometry import aim_at
from .protocol.registers import AXIS_REGISTERS, CSR, SYSTEM_STATE

# MOTION commands have a dedicated, limit-checked interface; ~/command points there.
DEDICATED = {
    'MOT_SendPosition': 'joint_command or ~/move_to',
    'MOT_Update': 'joint_command or ~/move_to (the driver sends the whole motion profile)',
    'MOT_Homing': '~/home',
    'SCN_StartScanZigZag': '~/start_scan', 'SCN_StartScanSnake': '~/start_scan',
    'SCN_StartScanSquare': '~/start_scan',
    'PRST_GoToPreset': '~/goto_preset', 'PRST_StartPresetLooping': '~/start_preset_loop',
    'GPS_GoToTarget': '~/goto_lla',
    'GPS_StartTargetLooping': '~/start_target_loop',
    'IMU_Leveling': '~/level',
    'VDT_setTrackingOn': '~/set_tracking (the tracker drives pan and tilt)',
}
# Motion commands ~/command sends anyway: the auxiliary servo is not a joint; the
# dual-gimbal synchronisation moves the axes under the controller's own (software-limit)
# control with no driver-side target to check, so it gets the axis-state check (off/faulted
# axes refuse) but no limit check. Video tracking has its own service (~/set_tracking).
ALLOWED_MOTION = {'SRV_MoveTo', 'DG_SetSyncMode', 'DG_GoToCamera'}
JOINT_MOTION = ALLOWED_MOTION - {'SRV_MoveTo'}
OPT_IN = {
    Safety.NV_WRITE: 'allow_nv_write',
    Safety.REBOOT: 'allow_reboot',
    Safety.NETWORK: 'allow_network_config',
}
MAX_PRESETS = 15
DIGITAL_IO_COUNT = 6  # COM_get/setDigitalIO: I/O 1..6 in the axis byte (4.6.17-18)
TRACKING_MODES = {'off': 0, 'manual': 1, 'auto': 2}  # VDT_setTrackingOn values (4.11.1)
IMU_ANGLE_BY_AXIS = {1: 'yaw', 2: 'pitch', 3: 'roll'}  # what IMU_Leveling levels per axis


def _axis_flags(registers: dict[str, int]) -> list[ActiveFlag]:
    """Active flags of one axis' polled registers (MER, DER, SRH, SRL, MSR, CMER, OPR)."""
    return [a for r in AXIS_REGISTERS for a in r.decode(registers.get(r.name, 0))]


def _quaternion(roll: float, pitch: float, yaw: float) -> tuple[float, float, float, float]:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return (sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy, cr * cp * cy + sr * sp * sy)


def parse_arguments(dtype: DataType, args: Sequence[str]) -> Any:
    """Text arguments of ~/command to the value a table entry takes."""
    try:
        if dtype is DataType.NONE:
            if args:
                raise ValueError('this command takes no argument')
            return None
        if dtype is DataType.LLA:
            lon, lat, alt = (float(a) for a in _split(args, 3))
            return GeoPoint(lon, lat, alt)
        if dtype is DataType.PRESET:
            parts = _split(args, 7)
            return PresetRecord(parts[0], tuple(float(a) for a in parts[1:]))
        (text,) = _split(args, 1)
        if dtype in (DataType.F32, DataType.F64):
            return float(text)
        if dtype is DataType.BOOL:
            lowered = text.strip().lower()
            if lowered in ('1', 'true', 'on', 'yes'):
                return 1
            if lowered in ('0', 'false', 'off', 'no'):
                return 0
            raise ValueError(f'{text!r} is not a boolean (true/false/1/0)')
        if dtype in (DataType.U8, DataType.U16, DataType.U32):
            return int(text, 0)
        return text
    except ValueError as exc:
        raise CommandError(f'bad argument for {dtype.value}: {exc}') from None


def _split(args: Sequence[str], count: int) -> list[str]:
    items = [a for arg in args for a in arg.replace(',', ' ').split()] if count > 1 else list(args)
    if len(items) != count:
        raise ValueError(f'expected {count} argument(s), got {len(items)}')
    return items


def format_result(cmd_name: str, value: Any) -> list[str]:
    cmd = COMMANDS[cmd_name]
    unit = f' {cmd.ret_unit}' if cmd.ret_unit else ''
    if isinstance(value, GeoPoint):
        return [f'longitude={value.longitude:.8f} deg', f'latitude={value.latitude:.8f} deg',
                f'altitude={value.altitude:.3f} m']
    if isinstance(value, PresetRecord):
        return [f'name={value.name}', *(f'{axis}={angle:.4f} deg' for axis, angle in zip(
            ('azimuth', 'elevation', 'roll', 'x', 'y', 'z'), value.angles, strict=True))]
    if cmd.ret is DataType.TARGETS:
        return [f'target{i}={width}x{height}' for i, (width, height) in enumerate(value, 1)]
    if cmd.ret_unit == 'bits':
        return [f'0x{value:04X}']
    if isinstance(value, float):
        return [f'{value:.6g}{unit}']
    return [f'{value}{unit}']


class CaptureDriverNode(GimbalDriverNode):
    """Capture pan-tilt pedestal driver (TCP port 4949 or RS-232/422/485)."""

    DEFAULT_JOINT_NAMES = ('pan', 'tilt')
    DEFAULT_POSITION_MIN = (-math.pi, -math.pi / 2)
    DEFAULT_POSITION_MAX = (math.pi, math.pi / 2)
    DEFAULT_VELOCITY_MAX = (1.5, 1.5)
    SCAN_PATTERNS = tuple(sorted(SCAN_COMMANDS))
    DEVICE_PRESETS = True

    def __init__(self, **kwargs: object) -> None:
        self.client: CaptureClient | None = None
        self._status: dict[str, Any] = {}
        self._status_lock = threading.Lock()
        self._next_status = 0.0
        self._next_imu = 0.0
        self._next_fix = 0.0
        self._has_imu = False
        self._has_gps = False
        self._device_scanning = False
        self._preset_looping = False
        self._target_looping = False
        self._ranging = False
        self._has_tracker = False
        self._tracker_problem = ''
        self._has_digital_io = False
        self._next_extra: dict[str, float] = {}
        self._guarded = threading.Lock()  # one levelling/drift run at a time
        super().__init__('capture_driver', **kwargs)
        group = ReentrantCallbackGroup()  # own group: services may wait on device I/O
        self._imu_pub = self.create_publisher(Imu, '~/imu', 10)
        self._fix_pub = self.create_publisher(NavSatFix, '~/fix', 10)
        self.create_service(SetBool, '~/set_stabilization', self._on_stabilization,
                            callback_group=group)
        self.create_service(Trigger, '~/start_preset_loop', self._on_start_loop,
                            callback_group=group)
        self.create_service(Trigger, '~/stop_preset_loop', self._on_stop_loop,
                            callback_group=group)
        self.create_service(SetBool, '~/set_emergency_stop', self._on_emergency_stop,
                            callback_group=group)
        self.create_service(DeviceCommand, '~/command', self._on_command, callback_group=group)
        self.create_subscription(NavSatFix, '~/goto_lla', self._on_goto_lla, 1,
                                 callback_group=group)
        self._create_device_function_interfaces(group)

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
        self._axis = dict(zip(self.joint_names, self.axis_ids, strict=True))
        self._direction = dict(zip(self.joint_names, self.joint_directions, strict=True))
        self._gear = dict(zip(self.joint_names, self.gear_ratios, strict=True))
        self._declare_device_function_parameters()

    # ------------------------------------------------- run-time parameters
    def declare_runtime_parameters(self) -> None:
        """Capture parameters that apply when set: speeds, rates, timeouts, frame ids.

        The link, axis mapping (axis_ids, joint_directions, gear_ratios), keep-alive and
        the opt-ins (allow_*) need a reconfigure: the opt-ins guard commands that can cut
        off or brick the controller and are given at start-up only.
        """
        for name in ('default_speed', 'acceleration', 'status_period', 'imu_rate', 'fix_rate',
                     'imu_frame_id', 'gps_frame_id', 'gps_target_slot', 'home_timeout'):
            self.runtime_parameter(name, name)

    # ------------------------------------------------------------ conversions
    def to_device(self, joint: str, radians: float) -> float:
        return math.degrees(radians) * self._direction[joint]

    def from_device(self, joint: str, degrees: float) -> float:
        return math.radians(degrees * self._direction[joint])

    def _client(self) -> CaptureClient:
        client = self.client
        if client is None or not client.connected:
            raise DeviceError('device not connected')
        return client

    def _device_call(self, action: Callable[[CaptureClient], Any]) -> Any:
        """Run client calls; device failures become DeviceError with a readable message."""
        try:
            return action(self._client())
        except (DeviceNack, DeviceTimeout, NotConnected, ProtocolError, CaptureError) as exc:
            raise DeviceError(str(exc)) from exc

    # ------------------------------------------------------------------ link
    def link_description(self) -> str:
        if self.transport == 'tcp':
            return f'tcp://{self.host}:{self.port}'
        return f'serial://{self.serial_port}?baudrate={self.baudrate}'

    def open_device(self) -> DeviceInfo:
        if self.transport == 'tcp':
            def factory():
                return TcpStream(self.host, self.port, connect_timeout=2.0)
        else:
            def factory():
                return SerialStream(self.serial_port, self.baudrate)
        client = CaptureClient(
            factory, group=self.group_id, timeout=self.request_timeout,
            expect_greeting=self.transport == 'tcp', keepalive_period=self.keepalive_period,
        )
        client.connect()
        self.client = client
        ident = client.identity()
        self._has_imu = bool(client.optional('IMU_IsReadyImu'))
        self._has_gps = bool(client.optional('GPS_isConnectedGPS'))
        self._device_scanning = bool(client.optional('SCN_IsScanOn'))
        self._preset_looping = False
        self._probe_device_functions(client)
        self._next_status = 0.0
        client.start()
        self.get_logger().info(
            f'Capture controller on {client.description}: IMU {"yes" if self._has_imu else "no"}'
            f', GPS {"yes" if self._has_gps else "no"}'
        )
        firmware = ident.firmware + (f' (hw {ident.hardware})' if ident.hardware else '')
        serial = ident.serial_number
        return DeviceInfo(
            model=ident.part_number or 'Capture pedestal', serial_number=serial,
            firmware_version=firmware, hardware_id=self._hardware_id(ident),
        )

    def _hardware_id(self, ident: Identity) -> str:
        """capture[-pn<part>]-sn<serial>[-hw<rev>][-fw<firmware>] from what the device
        answered; the link address stands in for a serial number it does not give."""
        parts = ['capture']
        if ident.part_number:
            parts.append(f'pn{ident.part_number}')
        parts.append(f'sn{ident.serial_number}' if ident.serial_number
                     else f'@{self.link_description()}')
        if ident.hardware:
            parts.append(f'hw{ident.hardware}')
        if ident.firmware:
            parts.append(f'fw{ident.firmware}')
        return '-'.join(parts)

    def close_device(self) -> None:
        client, self.client = self.client, None
        if client is not None:
            client.stop()
        with self._status_lock:
            self._status = {}

    def link_healthy(self) -> bool:
        return self.client is not None and self.client.connected

    # --------------------------------------------------------------- polling
    def poll_device(self) -> JointSample | None:
        client = self.client
        if client is None or not client.connected:
            raise NotConnected('client link is down')
        positions, velocities = {}, {}
        try:
            for joint in self.joint_names:
                axis = self._axis[joint]
                positions[joint] = self.from_device(joint, client.request('MOT_GetLoadPosition',
                                                                          axis))
                velocities[joint] = self.from_device(joint, client.request('MOT_GetMotorSpeed',
                                                                           axis))
        except (DeviceNack, DeviceTimeout) as exc:
            self.get_logger().warning(f'poll skipped: {exc}', throttle_duration_sec=5.0)
            return None
        stamp = time.time()
        now = time.monotonic()
        if now >= self._next_status:
            self._next_status = now + self.status_period
            self._refresh_status(client)
        if self.active and self._has_imu and self.imu_rate > 0 and now >= self._next_imu:
            self._next_imu = now + 1.0 / self.imu_rate
            self._publish_imu(client)
        if self.active and self._has_gps and self.fix_rate > 0 and now >= self._next_fix:
            self._next_fix = now + 1.0 / self.fix_rate
            self._publish_fix(client)
        if self.active:
            self._poll_device_functions(client, now)
        with self._status_lock:
            currents = self._status.get('current', {})
        return JointSample(
            positions=positions, velocities=velocities, stamp=stamp,
            efforts={j: currents[j] for j in self.joint_names if j in currents},
            moving={j: abs(v) > 1e-4 for j, v in velocities.items()},
        )

    def _refresh_status(self, client: CaptureClient) -> None:
        """Registers, currents and error strings, cached for diagnostics and ~/status."""
        status: dict[str, Any] = {'axes': {}, 'current': {}, 'problems': []}
        for joint in self.joint_names:
            axis = self._axis[joint]
            try:
                status['axes'][joint] = client.registers(axis)
                status['current'][joint] = client.request('MOT_GetMotorCurrent', axis) / 1000.0
            except (DeviceNack, DeviceTimeout) as exc:
                status['problems'].append(f'{joint}: {exc}')
        try:
            system = client.registers(None)
            status['system'] = system
            status['errors'] = client.error_strings(system.get('CSR', 0))
            status['emergency_stop'] = bool(client.request('MOT_GetEmgStopAxes'))
        except (DeviceNack, DeviceTimeout) as exc:
            status['problems'].append(f'system: {exc}')
        sys_state = status.get('system', {}).get('SYS', 0)
        self._device_scanning = bool(sys_state & (1 << 2))
        self._preset_looping = bool(sys_state & (1 << 3))
        self._target_looping = bool(sys_state & (1 << 4))
        with self._status_lock:
            self._status = status

    def _publish_imu(self, client: CaptureClient) -> None:
        try:
            values = client.imu()
        except (DeviceNack, DeviceTimeout) as exc:
            self.get_logger().warning(f'IMU read failed: {exc}', throttle_duration_sec=10.0)
            return
        msg = Imu()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.imu_frame_id
        # Device yaw counts clockwise (0..360); REP-103 yaw counts counter-clockwise.
        x, y, z, w = _quaternion(math.radians(values['roll']), math.radians(values['pitch']),
                                 -math.radians(values['yaw']))
        msg.orientation.x, msg.orientation.y, msg.orientation.z, msg.orientation.w = x, y, z, w
        msg.angular_velocity.x = math.radians(values['gyro_x'])
        msg.angular_velocity.y = math.radians(values['gyro_y'])
        msg.angular_velocity.z = math.radians(values['gyro_z'])
        msg.linear_acceleration_covariance[0] = -1.0  # the protocol reports no acceleration
        self._imu_pub.publish(msg)

    def _publish_fix(self, client: CaptureClient) -> None:
        try:
            fix = client.gps_fix()
        except (DeviceNack, DeviceTimeout, ProtocolError) as exc:
            self.get_logger().warning(f'GPS read failed: {exc}', throttle_duration_sec=10.0)
            return
        if fix is None:  # the device refused a GPS getter: the fix poll stops (diagnostics)
            self._has_gps = False
            return
        ready, latitude, longitude = fix
        msg = NavSatFix()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.gps_frame_id
        msg.status.status = NavSatStatus.STATUS_FIX if ready else NavSatStatus.STATUS_NO_FIX
        msg.status.service = NavSatStatus.SERVICE_GPS
        msg.latitude, msg.longitude = latitude, longitude
        msg.altitude = self._gps_altitude(client)
        msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
        self._fix_pub.publish(msg)

    # -------------------------------------------------------------- commands
    def _leave_device_programs(self, client: CaptureClient) -> None:
        """A new motion command ends a device scan or preset loop first (4.3 refuses motor
        writes with 0xA6 while scanning)."""
        if self._device_scanning:
            client.request('SCN_StopScan')
            self._device_scanning = False
        if self._preset_looping:
            client.request('PRST_StopPresetLooping')
            self._preset_looping = False
        if self._target_looping:
            client.request('GPS_StopTargetLooping')
            self._target_looping = False

    def send_moves(self, moves: dict[str, tuple[float, float | None]]) -> None:
        def action(client: CaptureClient) -> None:
            self._leave_device_programs(client)
            for joint, (target, speed) in moves.items():
                client.move_absolute(
                    self._axis[joint], self.to_device(joint, target),
                    math.degrees(speed if speed else self.default_speed),
                    math.degrees(self.acceleration),
                )

        self._device_call(action)

    def send_jogs(self, jogs: dict[str, float]) -> None:
        def action(client: CaptureClient) -> None:
            self._leave_device_programs(client)
            for joint, velocity in jogs.items():
                if velocity == 0.0:
                    client.stop_axis(self._axis[joint])
                else:
                    client.jog(self._axis[joint], self.to_device(joint, velocity),
                               math.degrees(self.acceleration))

        self._device_call(action)

    def stop_axes(self, joints: Sequence[str] | None) -> None:
        def action(client: CaptureClient) -> None:
            if joints is None:
                problems = client.stop_all([self._axis[j] for j in self.joint_names])
                self._device_scanning = self._preset_looping = self._target_looping = False
            else:
                problems = []
                for joint in joints:
                    try:
                        client.stop_axis(self._axis[joint])
                    except (DeviceNack, DeviceTimeout) as exc:
                        problems.append(str(exc))
            if problems:
                raise DeviceError('; '.join(problems))

        self._device_call(action)

    def reset_faults(self) -> str:
        """Per axis MOT_ResetFaults + MOT_AxisOn (4.10) and a stop, then ERR_ClearErrors;
        the answer quotes the device (its NACK and reason, or the axis state it reports
        afterwards), and fails while an axis is still off or faulted."""
        def action(client: CaptureClient) -> str:
            for joint in self.joint_names:
                axis = self._axis[joint]
                try:
                    client.reset_faults(axis)  # ResetFaults + AxisOn (4.10)
                    client.stop_axis(axis)  # AxisOn resumes a buffered move (4.2.11)
                except (DeviceNack, DeviceTimeout) as exc:
                    self._next_status = 0.0
                    raise DeviceError(f'{joint}: {exc}') from exc
            client.request('ERR_ClearErrors')
            self._refresh_status(client)  # motion checks see the new state at once
            still = self.axis_refusal(self.joint_names)
            if still:
                raise DeviceError('the device ACKed MOT_ResetFaults and MOT_AxisOn, but ' + still)
            return ('device ACKed MOT_ResetFaults, MOT_AxisOn and ERR_ClearErrors; registers '
                    'now show ' + ', '.join(f'{j} on, no fault' for j in self.joint_names))

        return self._device_call(action)

    def axis_refusal(self, joints: Sequence[str]) -> str | None:
        """Refuse motion on an axis whose last registers show a fault or the drive off.

        The device ACKs position commands to an axis that is off and then does not move;
        the registers polled every ``status_period`` say why, so the node refuses first.
        """
        with self._status_lock:
            axes = self._status.get('axes', {})
        reasons = []
        for joint in joints:
            registers = axes.get(joint)
            if registers is None:
                continue
            active = _axis_flags(registers)
            names = {a.flag.name for a in active}
            faults = sorted({a.key for a in active if a.flag.level >= Level.ERROR})
            if 'fault' in names or faults:
                reasons.append(f'{joint} is faulted ({", ".join(faults) or "fault"})')
            elif 'axis_off' in names:
                reasons.append(f'{joint} drive is off (SRL axis_off); switch it on with '
                               '~/enable')
        if not reasons:
            return None
        return '; '.join(reasons) + '; ~/reset_faults clears faults (MOT_ResetFaults + MOT_AxisOn)'

    def home(self, joints: Sequence[str], report: Callable[[str], None],
             cancelled: threading.Event) -> str:
        client = self._client()
        try:
            self._leave_device_programs(client)
            for joint in joints:
                client.run('MOT_Homing', self._axis[joint])
            deadline = time.monotonic() + self.home_timeout
            while True:
                if cancelled.is_set():
                    raise DeviceError('homing cancelled')
                states = []
                for joint in joints:
                    axis = self._axis[joint]
                    srl = client.request('MOT_SrlRegister', axis)
                    der = client.request('MOT_DerRegister', axis)
                    if der & (1 << 2):
                        raise DeviceError(f'{joint}: the drive reports homing not available '
                                          '(DER bit 2); contact Capture support')
                    position = self.from_device(joint, client.request('MOT_GetLoadPosition',
                                                                      axis))
                    states.append((joint, bool(srl & (1 << 8)), position))
                report(', '.join(f'{j}: {"homing" if active else "done"} at {p:+.4f} rad'
                                 for j, active, p in states))
                if not any(active for _, active, _ in states):
                    break
                if time.monotonic() > deadline:
                    raise DeviceError(f'homing not finished within home_timeout '
                                      f'{self.home_timeout:g} s')
                cancelled.wait(0.1)
            unfinished = [j for j in joints
                          if client.request('ERR_OperationRegister', self._axis[j]) & (1 << 1)]
            if unfinished:
                raise DeviceError(f'homing not completed for {unfinished} '
                                  f'({client.request("ERR_GetHomingErrorString")})')
        except (DeviceNack, DeviceTimeout, NotConnected) as exc:
            raise DeviceError(f'homing failed: {exc}') from exc
        self._next_status = 0.0
        return f'homed: {", ".join(joints)}'

    # ------------------------------------------------------------- presets
    def _check_index(self, index: int) -> None:
        if not 1 <= index <= MAX_PRESETS:
            raise CommandError(f'preset index {index} outside 1..{MAX_PRESETS} (device presets)')

    def device_set_preset(self, index: int, name: str, positions: dict[str, float] | None) -> str:
        self._check_index(index)
        if not name.isascii() or len(name) > 16:
            raise CommandError(f'preset name {name!r} must be ASCII, at most 16 characters')

        def action(client: CaptureClient) -> str:
            angles = [0.0] * 6
            for joint in self.joint_names:
                axis = self._axis[joint]
                if positions is not None and joint in positions:
                    angles[axis - 1] = self.to_device(joint, positions[joint])
                else:
                    angles[axis - 1] = client.request('MOT_GetLoadPosition', axis)
            client.set_preset(index, name, angles)
            return f'device preset {index} ({name or "unnamed"}) stored'

        return self._device_call(action)

    def _preset_positions(self, record: PresetRecord) -> dict[str, float]:
        return {j: self.from_device(j, record.angles[self._axis[j] - 1]) for j in self.joint_names}

    def _checked_preset(self, client: CaptureClient, index: int) -> PresetRecord:
        if index not in client.preset_indices():
            raise CommandError(f'preset {index} is empty on the device')
        record = client.get_preset(index)
        positions = self._preset_positions(record)
        try:
            validate_joint_command(list(positions), list(positions.values()), [], self.limits)
        except CommandError as exc:
            raise CommandError(f'preset {index} ({record.name}) is outside the joint limits, '
                               f'not moving: {exc}') from None
        return record

    def device_goto_preset(self, index: int, speed: float) -> str:
        self._check_index(index)

        def action(client: CaptureClient) -> str:
            record = self._checked_preset(client, index)
            if speed > 0:
                for joint in self.joint_names:
                    if speed > self.limits[joint].velocity_max:
                        raise CommandError(f'speed {speed:.4f} exceeds {joint} velocity_max '
                                           f'{self.limits[joint].velocity_max:.4f}')
                for joint in self.joint_names:
                    client.run('CFG_SetGeneralSpd', self._axis[joint], math.degrees(speed))
            self._leave_device_programs(client)
            client.run('PRST_GoToPreset', index)
            self.commanded_targets.update(self._preset_positions(record))
            return f'moving to device preset {index} ({record.name or "unnamed"})'

        return self._device_call(action)

    def device_list_presets(self) -> list[Preset]:
        def action(client: CaptureClient) -> list[Preset]:
            presets = []
            for index in client.preset_indices():
                record = client.get_preset(index)
                positions = self._preset_positions(record)
                presets.append(Preset(index=index, name=record.name,
                                      joint_names=list(positions),
                                      positions=list(positions.values())))
            return presets

        return self._device_call(action)

    def device_clear_preset(self, index: int | None) -> str:
        if index is not None:
            self._check_index(index)

        def action(client: CaptureClient) -> str:
            if index is None:
                client.run('PRST_ClearAll')
                return 'all device presets cleared'
            client.run('PRST_ClearSinglePreset', index)
            return f'device preset {index} cleared'

        return self._device_call(action)

    def _on_start_loop(self, request, response):
        def action() -> str:
            def run(client: CaptureClient) -> str:
                indices = client.preset_indices()
                if not indices:
                    raise CommandError('no device presets stored; set some with ~/set_preset')
                for index in indices:
                    self._checked_preset(client, index)
                self._leave_device_programs(client)
                client.run('PRST_StartPresetLooping')
                self._preset_looping = True
                return f'looping over device presets {indices}'

            return self._device_call(run)

        return self.serve_request(response, action)

    def _on_stop_loop(self, request, response):
        def action() -> str:
            self._device_call(lambda c: c.run('PRST_StopPresetLooping'))
            self._preset_looping = False
            self.stop_axes(None)
            return 'preset looping stopped'

        return self.serve_request(response, action)

    # ---------------------------------------------------------------- scans
    def start_device_scan(self, request: ScanRequest) -> str | None:
        if request.pattern not in SCAN_COMMANDS:
            raise ScanError(f'pattern {request.pattern!r} not available; the Capture device '
                            f'has {sorted(SCAN_COMMANDS)}')
        if len(self.joint_names) < 2:
            raise ScanError('a scan needs a pan and a tilt joint')
        pan, tilt = self.joint_names[0], self.joint_names[1]
        if self._axis[pan] != 1 or self._axis[tilt] != 2:
            raise ScanError('device scans move yaw (axis 1) and pitch (axis 2); map the first '
                            'two joints to axis_ids 1 and 2')
        for label, value in (('speed', request.speed), ('tilt_step', request.tilt_step)):
            if not math.isfinite(value) or value <= 0:
                raise ScanError(f'{label} {value} must be > 0')
        if request.speed > self.limits[pan].velocity_max:
            raise ScanError(f'speed {request.speed:.4f} exceeds {pan} velocity_max '
                            f'{self.limits[pan].velocity_max:.4f}')
        for label, joint, low, high in (('pan', pan, request.pan_min, request.pan_max),
                                        ('tilt', tilt, request.tilt_min, request.tilt_max)):
            limits = self.limits[joint]
            if not (math.isfinite(low) and math.isfinite(high)) or low > high:
                raise ScanError(f'{label} range [{low}, {high}] is not a valid interval')
            if low < limits.position_min or high > limits.position_max:
                raise ScanError(f'{label} range [{low:.4f}, {high:.4f}] outside the joint limits '
                                f'[{limits.position_min:.4f}, {limits.position_max:.4f}]')
        steps = math.floor((request.tilt_max - request.tilt_min) / request.tilt_step + 1e-9)
        if steps > 255:
            raise ScanError(f'{steps} rows exceed the device maximum 255; increase tilt_step')

        def motor(joint: str, value: float) -> float:
            return self.to_device(joint, value) * self._gear[joint]

        yaw = sorted((motor(pan, request.pan_min), motor(pan, request.pan_max)))
        pitch_min = min(motor(tilt, request.tilt_min), motor(tilt, request.tilt_max))

        def action(client: CaptureClient) -> str:
            self._leave_device_programs(client)
            client.configure_scan(yaw[0], yaw[1], pitch_min, steps,
                                  math.degrees(request.tilt_step) * abs(self._gear[tilt]),
                                  math.degrees(request.speed) * abs(self._gear[pan]))
            client.start_scan(request.pattern)
            self._device_scanning = True
            self._next_status = 0.0
            return (f'device {request.pattern} scan started: yaw {yaw[0]:.2f}..{yaw[1]:.2f} deg, '
                    f'{steps} step(s) of {math.degrees(request.tilt_step):.2f} deg')

        return self._device_call(action)

    def stop_device_scan(self) -> None:
        client = self.client
        if client is not None and client.connected:
            try:
                client.request('SCN_StopScan')
            except (DeviceNack, DeviceTimeout) as exc:
                raise DeviceError(f'SCN_StopScan failed: {exc}') from exc
        self._device_scanning = False

    # --------------------------------------------------------------- extras
    def _on_stabilization(self, request, response):
        def action() -> str:
            name = 'STB_StabilizationOn' if request.data else 'STB_StabilizationOff'
            self._device_call(lambda c: c.run(name))
            self._next_status = 0.0
            return f'stabilisation {"on" if request.data else "off"}'

        return self.serve_request(response, action)

    def _on_emergency_stop(self, request, response):
        def action() -> str:
            self._device_call(lambda c: c.run('MOT_SetEmgStopAxes', None, int(request.data)))
            self._device_scanning = self._preset_looping = False
            self._next_status = 0.0
            if request.data:
                return 'emergency stop set: all axes stopped, motion commands refused'
            return 'emergency stop cleared (the controller reset the axes to relative mode)'

        return self.serve_request(response, action)

    def _on_goto_lla(self, msg: NavSatFix) -> None:
        refusal = self.command_refusal()
        if refusal:
            self.get_logger().warning(f'~/goto_lla ignored: {refusal}')
            return
        try:
            target = GeoPoint(msg.longitude, msg.latitude,
                              msg.altitude if math.isfinite(msg.altitude) else 0.0)
            self._goto_lla(target)
        except (DeviceError, CommandError, ProtocolError) as exc:
            self.get_logger().error(f'~/goto_lla refused, nothing moved: {exc}')

    def _goto_lla(self, target: GeoPoint) -> None:
        for value, label, bound in ((target.latitude, 'latitude', 90.0),
                                    (target.longitude, 'longitude', 180.0)):
            if not math.isfinite(value) or abs(value) > bound:
                raise CommandError(f'{label} {value} outside +-{bound}')

        def action(client: CaptureClient) -> None:
            pose = self._target_pose(client, target)
            validate_joint_command(list(pose), list(pose.values()), [], self.limits)
            self._leave_device_programs(client)
            client.goto_lla(self.gps_target_slot, target)
            self.commanded_targets.update(pose)
            self.get_logger().info(f'aiming at lat {target.latitude:.6f} lon '
                                   f'{target.longitude:.6f}: '
                                   + ', '.join(f'{j} {p:+.4f} rad' for j, p in pose.items()))

        self._device_call(action)

    def _target_pose(self, client: CaptureClient, target: GeoPoint) -> dict[str, float]:
        """Joint positions (rad) the device takes to look at ``target``, from the GPS or
        the inserted position and heading (what GPS_GoToTarget uses)."""
        if client.request('GPS_GetOvdPosGPS'):
            origin = client.request('GPS_GetInsertedLLA')
            heading = client.request('GPS_GetInsertedHeading')
        else:
            _, latitude, longitude = client.gps_fix()
            origin = GeoPoint(longitude, latitude, target.altitude)
            heading = client.request('GPS_GetHeading')
        angles = aim_at(origin, heading, target)
        return {joint: self.from_device(joint, degrees)
                for joint, degrees in zip(self.joint_names[:2], angles, strict=False)}

    def _on_command(self, request, response):
        def action() -> str:
            try:
                cmd = lookup_command(request.command.strip())
            except ProtocolError as exc:  # unknown, or opcode not established
                raise CommandError(str(exc)) from None
            if cmd.safety is Safety.MOTION and cmd.name not in ALLOWED_MOTION:
                where = DEDICATED.get(cmd.name, 'the dedicated interface')
                raise CommandError(f"{cmd.name} moves the axes without the driver's limit "
                                   f'checks; use {where}')
            opt_in = OPT_IN.get(cmd.safety)
            if opt_in and not getattr(self, opt_in):
                raise CommandError(f'{cmd.name} is a {cmd.safety.value} command; set the '
                                   f'parameter {opt_in}:=true to allow it')
            value = parse_arguments(cmd.arg, list(request.arguments))
            if cmd.name in JOINT_MOTION and value != 0:  # 0 switches tracking/sync off
                refusal = self.axis_refusal(self.joint_names)
                if refusal:
                    raise CommandError(f'{cmd.name} refused, nothing sent: {refusal}')
            axis = request.axis if (cmd.axis.low != cmd.axis.high or request.axis) else None
            try:
                cmd.frame(axis, value, self.group_id)  # argument and axis checks, nothing sent
            except ProtocolError as exc:
                raise CommandError(str(exc)) from None
            # VDT_* take the camera index as `axis`; the codec puts it in the group byte (4.11)
            result = self._device_call(lambda c: c.run(cmd.name, axis, value))
            response.results = format_result(cmd.name, result) if cmd.replies_with_data else []
            self._next_status = 0.0
            if response.results:
                return f'{cmd.name}: ' + ', '.join(response.results)
            return f'{cmd.name}: ACK'

        return self.serve_request(response, action)

    # ------------------------------------------------------ status/diagnostics
    def device_status_parts(self) -> list[StatusPart]:
        with self._status_lock:
            status = self._status
        if not status:
            return [StatusPart('device', Level.STALE, 'no register data yet')]
        parts = []
        client = self.client
        for joint in self.joint_names:
            registers = status['axes'].get(joint)
            if registers is None:
                parts.append(StatusPart(joint, Level.STALE, 'registers unavailable'))
                continue
            active = _axis_flags(registers)
            values = [(f'{name}_raw', f'0x{value:04X}') for name, value in registers.items()]
            current = status['current'].get(joint)
            if current is not None:
                values.append(('current_A', f'{current:.3f}'))
            values.append(('axis_id', str(self._axis[joint])))
            parts.append(StatusPart.from_flags(joint, active, values))
        system = status.get('system', {})
        active = CSR.decode(system.get('CSR', 0)) + SYSTEM_STATE.decode(system.get('SYS', 0))
        values = [(f'{name}_raw', f'0x{value:04X}') for name, value in system.items()]
        values += [(f'error.{name}', text) for name, text in status.get('errors', {}).items()
                   if text]
        values += [(f'problem.{i}', text) for i, text in enumerate(status['problems'])]
        unsupported = dict(client.unsupported) if client is not None else {}
        values += [(f'unsupported.{name}', f'{answer}; not polled')
                   for name, answer in unsupported.items()]
        if client is not None:
            values += [('link', client.description)] + [
                (f'link.{k}', str(v)) for k, v in client.stats.items()
            ] + [('link.garbage_bytes', str(client.garbage_bytes))]
        part = StatusPart.from_flags('device', active, values)
        if status.get('emergency_stop'):
            part.level = max(part.level, Level.WARN)
            part.message = 'emergency stop flag set (MOT_SetEmgStopAxes 0 clears it); ' + (
                part.message)
            part.values.append(('emergency_stop', 'True'))
        errors = status.get('errors', {})
        texts = [t for t in errors.values() if t]
        if texts:
            part.message += ' | ' + '; '.join(texts)
        if unsupported:  # informational: an optional function the device lacks
            part.message += ' | device does not know: ' + ', '.join(unsupported)
        parts.append(part)
        return parts

    def device_mode(self) -> str:
        with self._status_lock:
            system = self._status.get('system', {})
            emergency = self._status.get('emergency_stop')
        if emergency:
            return 'emergency_stop'
        names = [a.flag.name for a in SYSTEM_STATE.decode(system.get('SYS', 0))]
        return '+'.join(names) if names else 'manual'

    def axis_details(self, joint: str) -> dict[str, object]:
        with self._status_lock:
            registers = self._status.get('axes', {}).get(joint)
            system = self._status.get('system', {})
        if registers is None:
            return {}
        active = _axis_flags(registers)
        names = {a.flag.name for a in active}
        details: dict[str, object] = {
            'active_errors': sorted({a.key for a in active if a.flag.level > Level.OK}),
            'homed': not registers.get('OPR', 0) & (1 << 1),
            'calibrated': not registers.get('OPR', 0) & (1 << 1),
        }
        if 'fault' in names:
            details['state'] = AxisState.STATE_FAULT
        elif 'homing_active' in names:
            details['state'] = AxisState.STATE_HOMING
        elif 'axis_off' in names:
            details['state'] = AxisState.STATE_DISABLED
        elif system.get('SYS', 0) & (1 << 2) and self._axis[joint] in (1, 2):
            details['state'] = AxisState.STATE_SCANNING
        return details

    def device_errors(self) -> list[str]:
        with self._status_lock:
            system = self._status.get('system', {})
            errors = self._status.get('errors', {})
        flags = [a.key for a in CSR.decode(system.get('CSR', 0)) if a.flag.level > Level.OK]
        return flags + [text for text in errors.values() if text]

    # ============================================ issue 15: first-class device functions
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

    def _create_device_function_interfaces(self, group: ReentrantCallbackGroup) -> None:
        self._range_pub = self.create_publisher(Range, '~/range', 10)
        self._tracking_pub = self.create_publisher(DiagnosticStatus, '~/tracking_state', 10)
        self._dio_pub = self.create_publisher(UInt8MultiArray, '~/digital_io', 10)
        self._heading_pub = self.create_publisher(Imu, '~/heading', 10)
        services = (
            (SetBool, '~/set_ranging', self._on_set_ranging),
            (SetMode, '~/set_tracking', self._on_set_tracking),
            (SetBool, '~/enable', self._on_enable),
            (Trigger, '~/start_target_loop', self._on_start_target_loop),
            (Trigger, '~/stop_target_loop', self._on_stop_target_loop),
            (Trigger, '~/reset_gyro_drift', self._on_reset_gyro_drift),
        )
        for srv_type, name, callback in services:
            self.create_service(srv_type, name, callback, callback_group=group)
        for number in self.digital_outputs:
            self.create_service(
                SetBool, f'~/set_digital_output_{number}',
                lambda request, response, n=number: self._on_set_output(n, request, response),
                callback_group=group)
        for name, callback in (('~/level', self._execute_level),
                               ('~/compensate_gyro_drift', self._execute_gyro_drift)):
            ActionServer(self, Home, name, execute_callback=callback,
                         goal_callback=lambda _: GoalResponse.ACCEPT,
                         cancel_callback=lambda _: CancelResponse.ACCEPT, callback_group=group)

    def _probe_device_functions(self, client: CaptureClient) -> None:
        """Which optional units answer (a missing video tracker NACKs with 0x76); ranging
        that was on before a reconnect is started again (the controller may have rebooted)."""
        if self._ranging:
            try:
                client.run('LRF_StartMeasurement')
            except (DeviceNack, DeviceTimeout) as exc:
                self._ranging = False
                self.get_logger().warning(f'ranging not restarted after reconnect: {exc}')
        self._target_looping = False
        self._next_extra = {}
        # firmware before 2.22.0 has no digital I/O: polling it would latch protocol errors
        # optional(): a device without the function answers 0xA6 once and is not asked again
        self._has_digital_io = client.optional('COM_getDigitalIO', 1) is not None
        self._has_tracker = client.optional('VDT_isTrackingOn', self.tracker_camera) is not None
        self._tracker_problem = '' if self._has_tracker else client.unsupported.get(
            'VDT_isTrackingOn', 'VDT_isTrackingOn refused or unanswered (no video tracker)')

    def _due(self, key: str, rate: float, now: float) -> bool:
        if rate <= 0 or now < self._next_extra.get(key, 0.0):
            return False
        self._next_extra[key] = now + 1.0 / rate
        return True

    def _poll_device_functions(self, client: CaptureClient, now: float) -> None:
        """Publish range, tracking state, digital I/O and GPS heading at their rates."""
        jobs: list[tuple[str, bool, float, Callable[[CaptureClient], None]]] = [
            ('range', self._ranging, self.range_rate, self._publish_range),
            ('tracking', self._has_tracker, self.tracking_rate, self._publish_tracking),
            ('digital_io', self._has_digital_io, self.digital_io_rate,
             self._publish_digital_io),
            ('heading', self._has_gps, self.fix_rate, self._publish_heading),
        ]
        for key, available, rate, publish in jobs:
            if available and self._due(key, rate, now):
                try:
                    publish(client)
                except (DeviceNack, DeviceTimeout, ProtocolError) as exc:
                    self.get_logger().warning(f'{key} read failed: {exc}',
                                              throttle_duration_sec=10.0)

    def _publish_range(self, client: CaptureClient) -> None:
        distance = client.request('LRF_GetLRFDistance', 1)  # 4.17.11: 1 = current/last
        msg = Range()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.range_frame_id
        msg.radiation_type = Range.INFRARED  # laser rangefinders are near/short-wave IR
        msg.field_of_view = float(self.range_field_of_view)
        msg.min_range, msg.max_range = float(self.range_min), float(self.range_max)
        # REP-117: +inf = no return within range; the device reads 0 when it measured none
        msg.range = float(distance) if distance > 0 else math.inf
        self._range_pub.publish(msg)

    def _publish_tracking(self, client: CaptureClient) -> None:
        state = client.tracking_state(self.tracker_camera)
        self._tracking_pub.publish(DiagnosticStatus(
            level=DiagnosticStatus.OK, name=f'{self.get_name()}: video tracker',
            hardware_id=self.device_info.hardware_id,
            message=(f'camera {state.camera}: mode {state.mode}, tracking '
                     f'{"active" if state.active else "inactive"}, target '
                     f'{"detected" if state.target_detected else "not detected"}'),
            values=[KeyValue(key='camera', value=str(state.camera)),
                    KeyValue(key='mode', value=state.mode),
                    KeyValue(key='tracking_active', value=str(state.active).lower()),
                    KeyValue(key='target_detected', value=str(state.target_detected).lower())],
        ))

    def _publish_digital_io(self, client: CaptureClient) -> None:
        states = client.digital_io(list(range(1, DIGITAL_IO_COUNT + 1)))
        msg = UInt8MultiArray()
        msg.layout.dim = [MultiArrayDimension(label='digital_io_1_to_6',
                                              size=DIGITAL_IO_COUNT, stride=DIGITAL_IO_COUNT)]
        msg.data = [int(states[n]) for n in sorted(states)]
        self._dio_pub.publish(msg)

    def _publish_heading(self, client: CaptureClient) -> None:
        ready, heading = client.gps_heading()
        if not ready:
            self.get_logger().warning('GPS heading not valid (GPS_HeadingReady 0): ~/heading '
                                      'not published', throttle_duration_sec=10.0)
            return
        msg = heading_imu(math.radians(heading), self.heading_accuracy)
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = self.gps_frame_id
        self._heading_pub.publish(msg)

    def _gps_altitude(self, client: CaptureClient) -> float:
        """GPS altitude in m where GPS_GetAltitude's opcode is established, else NaN."""
        if 'GPS_GetAltitude' not in COMMANDS:
            return math.nan  # 4.4.4 prints no opcode: 0x0506..0x0509 all fit (README)
        try:
            return float(client.request('GPS_GetAltitude'))
        except (DeviceNack, DeviceTimeout):
            return math.nan

    # ------------------------------------------------------------ guards
    def _busy_reason(self) -> str | None:
        """Why the pedestal is not at rest for a guarded operation, or None."""
        if self._device_scanning or (self._scan_thread is not None
                                     and self._scan_thread.is_alive()):
            return 'a scan is running; stop it with ~/stop_scan first'
        if self._preset_looping or self._target_looping:
            return 'a preset or target loop is running; stop it first'
        sample = self.latest_sample
        moving = [j for j, m in (sample.moving.items() if sample else ()) if m]
        if moving:
            return f'{", ".join(moving)} moving; wait for the move to end or call ~/stop'
        return None

    def _refuse_motion(self, joints: Sequence[str]) -> None:
        refusal = self.motion_refusal(joints)
        if refusal:
            raise CommandError(refusal)

    # ---------------------------------------------------------- services
    def _on_set_ranging(self, request, response):
        def action() -> str:
            def run(client: CaptureClient) -> str:
                if not request.data:
                    client.run('LRF_StopMeasurement')
                    self._ranging = False
                    return 'ranging off (LRF_StopMeasurement)'
                if not client.request('LRF_IsConnected'):
                    raise CommandError('no rangefinder connected (LRF_IsConnected 0); nothing '
                                       'sent')
                client.run('LRF_StartMeasurement')
                self._ranging = True
                self._next_extra.pop('range', None)
                return f'ranging on: ~/range at {self.range_rate:g} Hz'

            return self._device_call(run)

        return self.serve_request(response, action)

    def _on_set_tracking(self, request, response):
        def action() -> str:
            mode = request.mode.strip().lower()
            if mode not in TRACKING_MODES:
                raise CommandError(f'tracking mode {request.mode!r} unknown; use one of '
                                   f'{list(TRACKING_MODES)}')
            if not self._has_tracker:
                raise CommandError(f'no video tracker on camera {self.tracker_camera}: '
                                   f'{self._tracker_problem}')
            if mode != 'off':  # the tracker drives pan and tilt
                self._refuse_motion(self.scan_joints())

            def run(client: CaptureClient) -> str:
                if mode != 'off':
                    self._leave_device_programs(client)
                client.set_tracking(self.tracker_camera, TRACKING_MODES[mode])
                state = client.tracking_state(self.tracker_camera)
                self._next_extra.pop('tracking', None)
                if mode == 'manual' and not state.active:
                    raise CommandError(f'camera {self.tracker_camera}: manual tracking did not '
                                       'start: no target detected (VDT_isTargetDetected 0)')
                return (f'camera {self.tracker_camera}: tracking {mode} (active: '
                        f'{state.active}, target detected: {state.target_detected})')

            return self._device_call(run)

        return self.serve_request(response, action)

    def _on_set_output(self, number: int, request, response):
        def action() -> str:
            self._device_call(lambda c: c.set_digital_output(number, request.data))
            self._next_extra.pop('digital_io', None)
            return f'digital output {number} {"set (on)" if request.data else "reset (off)"}'

        return self.serve_request(response, action)

    def _on_enable(self, request, response):
        def action() -> str:
            joints = list(self.joint_names)
            if request.data:
                faulted = [j for j in joints
                           if self.axis_details(j).get('state') == AxisState.STATE_FAULT]
                if faulted:
                    raise CommandError(f'{", ".join(faulted)}: drive in fault; call '
                                       '~/reset_faults (it switches the drives on)')

            def run(client: CaptureClient) -> str:
                if not request.data:  # stop first: MOT_AxisOff under motion would coast
                    self._move_generation += 1  # ends running move goals
                    self.jog_watchdog.cancel()
                    self._stop_scan_silently()
                    problems = client.stop_all([self._axis[j] for j in joints])
                    self._device_scanning = self._preset_looping = False
                    self._target_looping = False
                    if problems:
                        raise DeviceError('stop before switching off failed: '
                                          + '; '.join(problems))
                for joint in joints:
                    client.set_axis_power(self._axis[joint], request.data)
                self._next_status = 0.0
                verb = 'on (MOT_AxisOn)' if request.data else 'off (MOT_AxisOff)'
                return f'drives {verb}: {", ".join(joints)}'

            return self._device_call(run)

        return self.serve_request(response, action)

    def _on_start_target_loop(self, request, response):
        def action() -> str:
            joints = self.joint_names[:2]
            self._refuse_motion(joints)

            def run(client: CaptureClient) -> str:
                targets = client.stored_targets()
                if not targets:
                    raise CommandError('no GPS targets stored; set some with ~/command '
                                       'GPS_SetTargetLLA')
                for number, point in targets.items():
                    pose = self._target_pose(client, point)
                    try:
                        validate_joint_command(list(pose), list(pose.values()), [],
                                               self.limits)
                    except CommandError as exc:
                        raise CommandError(f'target {number} (lat {point.latitude:.6f} lon '
                                           f'{point.longitude:.6f}) is outside the joint '
                                           f'limits, not looping: {exc}') from None
                self._leave_device_programs(client)
                client.run('GPS_StartTargetLooping')
                self._target_looping = True
                return f'looping over GPS targets {sorted(targets)}'

            return self._device_call(run)

        return self.serve_request(response, action)

    def _on_stop_target_loop(self, request, response):
        def action() -> str:
            self._device_call(lambda c: c.run('GPS_StopTargetLooping'))
            self._target_looping = False
            self.stop_axes(None)
            return 'target looping stopped'

        return self.serve_request(response, action)

    def _on_reset_gyro_drift(self, request, response):
        def action() -> str:
            if not self._has_imu:
                raise CommandError('the controller reports no IMU (IMU_IsReadyImu)')
            self._device_call(lambda c: c.run('IMU_ResetGyroDriftCompensation',
                                              self.gyro_drift_sensor))
            return f'gyro drift compensation of IMU sensor {self.gyro_drift_sensor} reset to 0'

        return self.serve_request(response, action)

    # ----------------------------------------------------------- actions
    def _run_guarded(self, goal_handle, work: Callable[[Callable[[str], None]], str]):
        """Run a levelling/drift goal: refused while the pedestal is busy or another runs;
        feedback through ``report``; cancel, ~/stop and link loss end it."""
        result = Home.Result()
        feedback = Home.Feedback()

        def report(state: str) -> None:
            feedback.state = state
            goal_handle.publish_feedback(feedback)

        if not self._guarded.acquire(blocking=False):
            goal_handle.abort()
            result.message = 'refused: a levelling or drift compensation is already running'
            return result
        try:
            refusal = self.command_refusal() or self._busy_reason()
            if refusal:
                raise CommandError(refusal)
            result.message = work(report)
            result.success = True
        except (CommandError, DeviceError, DeviceNack, DeviceTimeout, NotConnected,
                ProtocolError) as exc:
            result.success, result.message = False, str(exc)
        finally:
            self._guarded.release()
        if goal_handle.is_cancel_requested:
            goal_handle.canceled()
            result.success = False
        elif result.success:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result

    def _execute_level(self, goal_handle):
        joints = list(goal_handle.request.joint_names) or list(self.joint_names)

        def work(report: Callable[[str], None]) -> str:
            unknown = [j for j in joints if j not in self._axis]
            if unknown:
                raise CommandError(f'unknown joint(s) {unknown}; this device has '
                                   f'{list(self.joint_names)}')
            if not self._has_imu:
                raise CommandError('levelling needs an IMU on the load; the controller '
                                   'reports none (IMU_IsReadyImu)')
            self._refuse_motion(joints)
            client = self._client()
            errors = self._level_errors(client, joints)
            targets = {j: self.from_device(j, client.request('MOT_GetLoadPosition',
                                                             self._axis[j]) + errors[j])
                       for j in joints}
            validate_joint_command(list(targets), list(targets.values()), [], self.limits)
            self._leave_device_programs(client)
            for joint in joints:
                client.run('IMU_Leveling', self._axis[joint])
            self.commanded_targets.update(targets)
            return self._wait_level(client, joints, report, goal_handle)

        return self._run_guarded(goal_handle, work)

    def _level_errors(self, client: CaptureClient, joints: Sequence[str]) -> dict[str, float]:
        """Per joint: device degrees between the IMU angle and its levelling value."""
        imu = client.imu()
        errors = {}
        for joint in joints:
            axis = self._axis[joint]
            level = client.request('IMU_getLevelingValue', axis)
            error = level - imu[IMU_ANGLE_BY_AXIS[axis]]
            errors[joint] = (error + 180.0) % 360.0 - 180.0  # yaw is 0..360
        return errors

    def _wait_level(self, client: CaptureClient, joints: Sequence[str],
                    report: Callable[[str], None], goal_handle) -> str:
        """Feedback until every IMU angle is at its levelling value and the axes rest."""
        generation = self._move_generation
        deadline = time.monotonic() + self.move_timeout
        tolerance = math.degrees(self.goal_tolerance)
        while True:
            errors = self._level_errors(client, joints)
            sample = self.latest_sample
            moving = any(sample.moving.get(j, False) for j in joints) if sample else True
            report(', '.join(f'{j}: {abs(e):.3f} deg from level' for j, e in errors.items())
                   + (' (moving)' if moving else ''))
            if all(abs(e) <= tolerance for e in errors.values()) and not moving:
                return 'levelled ' + ', '.join(f'{j} ({abs(e):.3f} deg)'
                                               for j, e in errors.items())
            if goal_handle.is_cancel_requested or generation != self._move_generation:
                self._stop_quietly(joints)
                raise CommandError('levelling cancelled; axes stopped')
            if not self.connected:
                raise DeviceError('device link lost during levelling')
            if time.monotonic() > deadline:
                self._stop_quietly(joints)
                raise CommandError(f'not level within move_timeout {self.move_timeout:g} s')
            time.sleep(0.1)

    def _execute_gyro_drift(self, goal_handle):
        def work(report: Callable[[str], None]) -> str:
            if goal_handle.request.joint_names:
                raise CommandError('the drift compensation takes no joint names (it measures '
                                   f'IMU sensor {self.gyro_drift_sensor}, gyro_drift_sensor)')
            if not self._has_imu:
                raise CommandError('the controller reports no IMU (IMU_IsReadyImu)')
            self._refuse_motion(self.joint_names)
            client = self._client()
            sensor = self.gyro_drift_sensor
            client.run('IMU_GyroDriftCompensation', sensor)
            generation = self._move_generation
            start = time.monotonic()
            while (elapsed := time.monotonic() - start) < self.gyro_drift_time:
                if goal_handle.is_cancel_requested or generation != self._move_generation:
                    raise CommandError('drift measurement cancelled (the controller may still '
                                       'finish it; ~/reset_gyro_drift clears it)')
                if not self.connected:
                    raise DeviceError('device link lost during the drift measurement')
                reason = self._busy_reason()
                if reason:
                    raise CommandError(f'the pedestal moved during the drift measurement '
                                       f'({reason}); the result is not trusted')
                report(f'holding still while measuring the gyro drift: {elapsed:.1f} of '
                       f'{self.gyro_drift_time:g} s')
                time.sleep(0.2)
            drift = client.request('IMU_GetGyroDrift', sensor)
            return (f'gyro drift of IMU sensor {sensor}: {drift:.5f} deg/s '
                    f'({math.radians(drift):.6f} rad/s), compensated by the controller')

        return self._run_guarded(goal_handle, work)


def main(args: Sequence[str] | None = None) -> int:
    return run_driver(CaptureDriverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
