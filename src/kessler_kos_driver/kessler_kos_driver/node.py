"""ROS 2 node for Kessler kOS devices: a thin layer over KosClient on the shared base node.

The base node (gimbal_driver_common.ros.base_node) provides the lifecycle, joint_states,
joint_command, ~/stop, ~/move_to, ~/home, presets (driver-side YAML, kOS has none), scans,
/diagnostics and ~/status. This node adds the kOS playback services, ~/calibrate,
~/take_picture, ~/playback_status, the aux inputs (~/aux_inputs, ~/slave_controller_present),
~/command (LEDStatus, SoftwareID), and converts SI joint units to motor rotations with
`joint_scales` (SI units per rotation; a negative scale flips the direction). The link is TCP
or USB HID (`transport`).

Things the base node does not provide and that live here:
- the `password` parameter is redacted: rclpy publishes declared parameter values on
  /parameter_events and serves them on ~/get_parameters, so the real value is taken from the
  parameter overrides (or `password_file`) and the declared parameter only ever holds
  '********' (read-only);
- per-axis diagnostics from ErrorStatus codes, motor online state, calibration and lock state.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import Joy
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from gimbal_driver_common.device import DeviceInfo, JointSample
from gimbal_driver_common.diagnostics import Level
from gimbal_driver_common.joint_command import CommandError
from gimbal_driver_common.ros.diagnostics import StatusPart
from gimbal_driver_common.ros.legacy import DeviceError
from gimbal_driver_common.ros.legacy import HookedDriverNode as GimbalDriverNode
from gimbal_driver_common.ros.parameters import ParameterError
from gimbal_driver_common.ros.run import run_driver
from gimbal_msgs.msg import AxisState
from gimbal_msgs.msg import PlaybackStatus as PlaybackStatusMsg
from gimbal_msgs.srv import Calibrate, DeviceCommand, LoadTrajectory

from .client import ErrorEvent, KosClient, KosError
from .moves import (
    AxisRange,
    JointMapping,
    Keyframe,
    PlaybackSettings,
    from_keyframes,
    from_segments,
)
from .protocol import (
    DEFAULT_TCP_PORT,
    ERROR_CODES,
    MOTOR_ADDRESS_MAX,
    MOTOR_ADDRESS_MIN,
    REPORT_SIZE,
    USB_KEEPALIVE_PERIOD_S,
    DeviceType,
    ErrorCode,
    LedState,
    PlaybackMode,
    PlaybackState,
    PlaybackStatus,
    ProtocolError,
    playback_state_name,
)
from .usb_link import USB_BACKENDS, UsbTarget

REDACTED = '********'
TRANSPORTS = ('tcp', 'usb')
# AuxInputStatus bits (document "AuxInputStatus"): buttons of ~/aux_inputs in this order;
# bit 4 (slave controller present) goes to ~/slave_controller_present.
AUX_INPUT_BUTTONS = ('master_tip', 'master_ring', 'slave_tip', 'slave_ring')
AUX_SLAVE_PRESENT_BIT = 4
LED_NAMES = {int(state): state.name.lower() for state in LedState}
TWO_PI = 2.0 * math.pi
DEVICE_MODELS = {
    DeviceType.CINESHOOTER: 'Kessler CineShooter',
    DeviceType.SECOND_SHOOTER_PRO: 'Kessler Second Shooter Pro',
    DeviceType.SECOND_SHOOTER_PLUS: 'Kessler Second Shooter Plus',
}


class _RosLogHandler(logging.Handler):
    """Forward the client's Python log records to the node's ROS logger (and /rosout)."""

    def __init__(self, node: GimbalDriverNode) -> None:
        super().__init__()
        self._logger = node.get_logger()

    def emit(self, record: logging.LogRecord) -> None:
        text = self.format(record)
        if record.levelno >= logging.ERROR:
            self._logger.error(text)
        elif record.levelno >= logging.WARNING:
            self._logger.warning(text)
        else:
            self._logger.debug(text)


class KosDriverNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = ('slider', 'pan', 'tilt')
    STREAMED = True  # positions come from notifications and the client's position polls
    # Device limits are the calibrated ranges and the motors' MaxMax speeds (checked by the
    # client); these parameter defaults only bound what the driver accepts at all.
    DEFAULT_POSITION_MIN = (-1000.0,)
    DEFAULT_POSITION_MAX = (1000.0,)
    DEFAULT_VELOCITY_MAX = (60.0,)
    SCAN_PATTERNS = ('sector',)

    def __init__(self, **kwargs: object) -> None:
        self.client: KosClient | None = None
        self._latched_errors: list[ErrorEvent] = []
        self._errors_lock = threading.Lock()
        self._locked_out = False
        self._delay_return = False     # from the last ~/load_trajectory, for ~/setup_playback
        super().__init__('kessler_kos_driver', **kwargs)
        package_logger = logging.getLogger('kessler_kos_driver')
        package_logger.addHandler(_RosLogHandler(self))
        package_logger.setLevel(logging.INFO)
        package_logger.propagate = False
        group = ReentrantCallbackGroup()
        self._playback_pub = self.create_publisher(PlaybackStatusMsg, '~/playback_status', 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._aux_pub = self.create_publisher(Joy, '~/aux_inputs', latched)
        self._slave_pub = self.create_publisher(Bool, '~/slave_controller_present', latched)
        self._device_settings: dict[str, str] = {}
        self.create_service(DeviceCommand, '~/command', self._on_command, callback_group=group)
        self.create_service(LoadTrajectory, '~/load_trajectory', self._on_load_trajectory,
                            callback_group=group)
        self.create_service(Trigger, '~/setup_playback', self._on_setup_playback,
                            callback_group=group)
        self.create_service(Trigger, '~/start_playback', self._on_start_playback,
                            callback_group=group)
        self.create_service(Trigger, '~/stop_playback', self._on_stop_playback,
                            callback_group=group)
        self.create_service(Calibrate, '~/calibrate', self._on_calibrate, callback_group=group)
        self.create_service(Trigger, '~/take_picture', self._on_take_picture,
                            callback_group=group)

    # ------------------------------------------------------------ parameters
    def declare_device_parameters(self) -> None:
        n = len(self.joint_names)
        self.transport = self.declare_param(
            'transport', 'tcp', 'link to the device: tcp (network) or usb (HID)',
            choices=TRANSPORTS)
        self.usb_vendor_id = self.declare_param(
            'usb_vendor_id', 0, 'USB vendor id of the kOS device (transport usb; 0 = use '
            'usb_path)', value_range=(0, 0xFFFF))
        self.usb_product_id = self.declare_param(
            'usb_product_id', 0, 'USB product id of the kOS device (transport usb)',
            value_range=(0, 0xFFFF))
        self.usb_serial_number = self.declare_param(
            'usb_serial_number', '', 'USB serial number to pick one of several devices '
            '("" = the first)')
        self.usb_path = self.declare_param(
            'usb_path', '', 'HID device path (e.g. /dev/hidraw0); wins over the ids')
        self.usb_backend = self.declare_param(
            'usb_backend', 'hidraw', 'HID backend: hidraw (Linux /dev/hidraw*) or libusb',
            choices=tuple(USB_BACKENDS))
        self.usb_report_size = self.declare_param(
            'usb_report_size', REPORT_SIZE, 'bytes per HID report including the report ID '
            '0x01 (document: 64)', value_range=(7, 4096))
        self.usb_keepalive_period = self.declare_param(
            'usb_keepalive_period', USB_KEEPALIVE_PERIOD_S, 's between USB keep-alive '
            'messages (document: every 4 s)', value_range=(0.1, 4.0))
        self.allow_software_id_write = self.declare_param(
            'allow_software_id_write', False, 'allow ~/command SetSoftwareID (changes what '
            'the device reports to every other client)')
        if self.transport == 'usb':
            try:
                self.usb_target: UsbTarget | None = UsbTarget(
                    self.usb_vendor_id, self.usb_product_id, self.usb_serial_number,
                    self.usb_path, self.usb_backend)
                self.usb_target.check()
            except ValueError as exc:
                raise ParameterError(f'parameters usb_vendor_id/usb_product_id/usb_path: '
                                     f'{exc}') from None
        else:
            self.usb_target = None
        self.host = self.declare_param('host', '', 'device IP address or name ("" = discover '
                                       'by listening for NetworkInfo datagrams)')
        self.port = self.declare_param('port', DEFAULT_TCP_PORT, 'device TCP port',
                                       value_range=(1, 65535))
        self._password = self._declare_password()
        self.discovery_port = self.declare_param(
            'discovery_port', DEFAULT_TCP_PORT,
            'UDP port on which NetworkInfo discovery datagrams are received',
            value_range=(1, 65535))
        self.discovery_timeout = self.declare_param(
            'discovery_timeout', 10.0, 's to wait for a NetworkInfo datagram',
            value_range=(0.1, 600.0))
        self.discovery_bind = self.declare_param(
            'discovery_bind', '0.0.0.0', 'local address the discovery listener binds to')
        self.motor_addresses = self.declare_param(
            'motor_addresses', list(range(1, n + 1)),
            'kOS motor address (1..10) of each joint, same order as joint_names',
            element_type=int, value_range=(MOTOR_ADDRESS_MIN, MOTOR_ADDRESS_MAX))
        self.joint_scales = self.declare_param(
            'joint_scales', [TWO_PI] * n,
            'SI units (rad or m) per motor rotation for each joint; negative flips direction',
            element_type=float)
        self.acceleration_scale = self.declare_param(
            'acceleration_scale', 0.5,
            'fraction of each motor\'s MaxMaxAcceleration used for moves and jogs',
            value_range=(0.01, 1.0))
        # Positions come from MotorInfo polls, so the poll runs at publish_rate by default:
        # joint_states then arrive at publish_rate (issue 12; a fixed 0.05 s gave 20 Hz).
        self.poll_period = self.declare_param(
            'poll_period', 1.0 / self.publish_rate,
            's between (Get)MotorInfo state polls (default 1/publish_rate; 0 = notifications '
            'only)', value_range=(0.0, 10.0))
        self.keepalive_period = self.declare_param(
            'keepalive_period', 10.0, 's of idle link before a (Get)NetworkInfo keep-alive '
            '(the device drops silent links after 30 s)', value_range=(0.5, 29.0))
        self.reply_timeout = self.declare_param(
            'reply_timeout', 2.0, 's to wait for a device response', value_range=(0.1, 60.0))
        self.return_to_home_percent = self.declare_param(
            'return_to_home_percent', 100.0,
            'speed of the return to the first key frame, % of MaxMaxMoveSpeed',
            value_range=(1.0, 100.0))
        self.picture_exposure = self.declare_param(
            'picture_exposure', 0.1, 's of shutter time for ~/take_picture',
            value_range=(0.0, 3600.0))
        self.playback_timeout = self.declare_param(
            'playback_timeout', 60.0, 's to wait for SetupCompleted / MotorsHome',
            value_range=(1.0, 3600.0))
        if len(self.motor_addresses) != n or len(set(self.motor_addresses)) != n:
            raise ParameterError(f'parameter motor_addresses: need {n} distinct addresses '
                                 f'(one per joint), got {self.motor_addresses}')
        self._check_joint_scales(self.joint_scales)
        self.joints = {
            name: JointMapping(name, address, scale)
            for name, address, scale in zip(self.joint_names, self.motor_addresses,
                                            self.joint_scales, strict=True)
        }
        self._joint_of = {m.address: m.name for m in self.joints.values()}

    def _declare_password(self) -> str:
        """Take the password without ever letting its value into a parameter event."""
        overrides = getattr(self, '_parameter_overrides', {})
        given = overrides.pop('password', None)
        password = ''
        if given is not None:
            if given.type_ != Parameter.Type.STRING:
                raise ParameterError('parameter password: must be a string')
            password = given.value
        password_file = self.declare_param(
            'password_file', '', 'file whose first line is the device password (overrides '
            'password)')
        if password_file:
            try:
                password = Path(password_file).read_text(encoding='utf-8').splitlines()[0]
            except (OSError, IndexError) as exc:
                raise ParameterError(f'parameter password_file: cannot read a password from '
                                     f'{password_file!r} ({type(exc).__name__})') from None
        self.declare_param('password', REDACTED if password else '',
                           'device password (write-only: always shown redacted)',
                           read_only=True)
        return password

    # ------------------------------------------------- run-time parameters
    def _check_joint_scales(self, scales: Sequence[float]) -> None:
        """One value per joint, finite and non-zero (start-up and ``ros2 param set``)."""
        n = len(self.joint_names)
        if len(scales) != n or any(not math.isfinite(s) or s == 0 for s in scales):
            raise ParameterError(f'parameter joint_scales: need {n} finite non-zero values, '
                                 f'got {list(scales)}')

    def declare_runtime_parameters(self) -> None:
        """kOS parameters that apply when set; the link settings need a reconfigure.

        joint_scales change the SI<->rotation conversion of every command and reading, so
        they are taken only while the axes are idle and no device move (playback) runs.
        """

        def scales_busy() -> str | None:
            client = self.client
            if client is not None and client.playback_running:
                return (f'a move is playing ({playback_state_name(client.playback.status)}); '
                        'stop it first')
            reason = self.axes_busy()
            return f'the axes must be idle ({reason})' if reason else None

        def set_joint_scales(scales: list[float]) -> None:
            for (name, mapping), scale in zip(self.joints.items(), scales, strict=True):
                if name in self.commanded_targets:  # same motor target in the new units
                    self.commanded_targets[name] *= scale / mapping.scale
            self.joint_scales = scales
            self.joints = {name: JointMapping(name, mapping.address, scale)
                           for (name, mapping), scale in zip(self.joints.items(), scales,
                                                             strict=True)}

        self.runtime_parameter('joint_scales', set_joint_scales, busy=scales_busy,
                               check=self._check_joint_scales)
        for name in ('acceleration_scale', 'return_to_home_percent', 'picture_exposure',
                     'playback_timeout'):
            self.runtime_parameter(name, name)

        def set_poll_period(period: float) -> None:
            self.poll_period = period
            if self.client is not None:  # the client reads it on every poll tick
                self.client.poll_period = period

        self.runtime_parameter('poll_period', set_poll_period)

    # ------------------------------------------------------------------ hooks
    def open_device(self) -> DeviceInfo:
        self.close_device()
        client = KosClient(
            host=self.host, port=self.port, password=self._password,
            discovery_port=self.discovery_port, discovery_timeout=self.discovery_timeout,
            discovery_bind=self.discovery_bind, reply_timeout=self.reply_timeout,
            keepalive_period=self.keepalive_period, poll_period=self.poll_period,
            usb=self.usb_target, usb_report_size=self.usb_report_size,
            usb_keepalive_period=self.usb_keepalive_period,
        )
        client.on_playback = self._publish_playback
        client.on_aux_inputs = self._publish_aux_inputs
        client.on_error = self._on_device_error
        client.on_motor_update = self.notify_new_data  # publish positions as they arrive
        try:
            client.connect()
        except KosError as exc:
            client.close()
            raise DeviceError(str(exc)) from exc
        missing = [f'{m.name} (motor {m.address})' for m in self.joints.values()
                   if m.address not in client.motors]
        if missing:
            self.get_logger().warning(f'joints without a connected motor: {missing}; '
                                      f'device motors: {sorted(client.motors)}')
        self.client = client
        self._locked_out = False
        self._read_device_settings(client)
        self._publish_aux_inputs(client.aux_inputs)
        info = client.device_info
        model = DEVICE_MODELS.get(info.device_type, f'kOS device type {info.device_type}') \
            if info else 'kOS device'
        return DeviceInfo(model=model, serial_number=client.guid,
                          firmware_version=info.firmware if info else '',
                          hardware_id=client.guid or client.description)

    def close_device(self) -> None:
        client, self.client = self.client, None
        if client is not None:
            client.on_playback = client.on_error = client.on_motor_update = None
            client.on_aux_inputs = None
            client.close()

    def link_healthy(self) -> bool:
        return self.client is not None and self.client.connected

    def link_description(self) -> str:
        if self.client:
            return self.client.description
        if self.usb_target is not None:
            return self.usb_target.describe()
        return f'tcp://{self.host or "?"}:{self.port}'

    def _client(self) -> KosClient:
        client = self.client
        if client is None or not client.connected:
            raise DeviceError('device not connected')
        return client

    def poll_device(self) -> JointSample | None:
        client = self._client()
        positions, velocities, moving = {}, {}, {}
        stamp = 0.0
        running = client.playback_running
        for name, mapping in self.joints.items():
            motor = client.motors.get(mapping.address)
            if motor is None or not motor.online or not motor.stamp:
                continue
            positions[name] = motor.position * mapping.scale
            velocities[name] = motor.velocity * mapping.scale
            moving[name] = running or abs(motor.velocity) > 1e-4
            stamp = max(stamp, motor.stamp)
        if not positions:
            return None
        return JointSample(positions, velocities, stamp=stamp or time.time(), moving=moving)

    def _speed_rot(self, name: str, speed_si: float | None) -> float:
        """Motor speed in rot/s for a joint speed (None: velocity_max)."""
        speed = speed_si if speed_si is not None else self.limits[name].velocity_max
        return abs(speed / self.joints[name].scale)

    def _refuse_during_playback(self, client: KosClient) -> None:
        if client.playback_running:
            raise DeviceError(
                f'a move is playing ({playback_state_name(client.playback.status)}); '
                'call ~/stop_playback or ~/stop first')

    def send_moves(self, moves: dict[str, tuple[float, float | None]]) -> None:
        client = self._client()
        self._refuse_during_playback(client)
        messages = []
        for name, (target, speed) in moves.items():   # check everything before sending
            mapping = self.joints[name]
            motor = client.motor(mapping.address) if mapping.address in client.motors else None
            if motor is None:
                raise DeviceError(f'joint {name!r}: motor {mapping.address} is not connected')
            speed_rot = self._speed_rot(name, speed)
            if speed is None:
                speed_rot = min(speed_rot, motor.max_setup_speed)
            try:
                messages.append(client.check_move(
                    mapping.address, target / mapping.scale, speed_rot,
                    motor.max_acceleration * self.acceleration_scale))
            except KosError as exc:
                raise CommandError(f'joint {name!r}: {exc}') from exc
        for message in messages:
            client.send(message)

    def send_jogs(self, jogs: dict[str, float]) -> None:
        client = self._client()
        self._refuse_during_playback(client)
        for name in jogs:
            if self.joints[name].address not in client.motors:
                raise DeviceError(f'joint {name!r}: motor {self.joints[name].address} is not '
                                  'connected')
        for name, velocity in jogs.items():
            mapping = self.joints[name]
            motor = client.motor(mapping.address)
            rot_velocity = velocity / mapping.scale
            if abs(rot_velocity) > motor.max_setup_speed:
                raise CommandError(f'joint {name!r}: {abs(velocity):.4f} exceeds the motor '
                                   f'maximum {motor.max_setup_speed * abs(mapping.scale):.4f}')
            client.jog(mapping.address, rot_velocity,
                       motor.max_acceleration * self.acceleration_scale)

    def stop_axes(self, joints: Sequence[str] | None) -> None:
        client = self._client()
        if joints is None:
            client.stop_all()
            return
        for name in joints:
            address = self.joints[name].address
            if address in client.motors and client.motors[address].online:
                client.stop_motor(address)

    def reset_faults(self) -> str:
        """kOS has no fault-clear command: clear the driver's latched errors and re-read."""
        client = self._client()
        with self._errors_lock:
            count = len(self._latched_errors)
            self._latched_errors.clear()
        self._locked_out = False
        client.refresh_motors()
        uncalibrated = [n for n, m in self.joints.items()
                        if m.address in client.motors and not client.motors[m.address].calibrated]
        note = (f'; not calibrated (recalibrate with ~/calibrate): {uncalibrated}'
                if uncalibrated else '')
        return f'cleared {count} latched device error(s){note}'

    def home(self, joints: Sequence[str], report: Callable[[str], None],
             cancelled: threading.Event) -> str:
        """First key frame if a move is loaded, else the begin mark of calibrated joints;
        uncalibrated joints only get their latched errors cleared."""
        client = self._client()
        self._refuse_during_playback(client)
        if client.playback.loaded:
            report('returning to the first key frame')
            marker = len(client.playback.history)
            try:
                client.rapid_to_first_key_frame()
            except KosError as exc:
                raise DeviceError(str(exc)) from exc
            if not client.wait_for(
                    lambda: PlaybackState.MOTORS_HOME in client.playback.history[marker:]
                    or cancelled.is_set(), self.playback_timeout):
                raise DeviceError('no MotorsHome notification: the return to the first key '
                                  'frame did not complete')
            return 'at the first key frame of the loaded move'
        calibrated = [n for n in joints if self.joints[n].address in client.motors
                      and client.motors[self.joints[n].address].calibrated]
        cleared = [n for n in joints if n not in calibrated]
        if cleared:
            addresses = {self.joints[n].address for n in cleared}
            with self._errors_lock:
                self._latched_errors = [e for e in self._latched_errors
                                        if e.motor_address not in addresses]
        if calibrated:
            report('moving to the begin marks')
            self.send_moves({n: (0.0, None) for n in calibrated})
            deadline = time.monotonic() + self.move_timeout
            while time.monotonic() < deadline and not cancelled.is_set():
                current = self.current_positions()
                if all(abs(current.get(n, math.inf)) <= self.goal_tolerance
                       for n in calibrated):
                    break
                report('moving to the begin marks')
                time.sleep(0.05)
            else:
                if not cancelled.is_set():
                    raise DeviceError(f'begin marks not reached within {self.move_timeout:g} s')
        parts = []
        if calibrated:
            parts.append(f'at the begin mark: {calibrated}')
        if cleared:
            parts.append(f'not calibrated, errors cleared (no homing without calibration): '
                         f'{cleared}')
        return '; '.join(parts)

    # ---------------------------------------------------------- notifications
    def _on_device_error(self, event: ErrorEvent) -> None:
        with self._errors_lock:
            self._latched_errors.append(event)
            del self._latched_errors[:-20]
        if event.code == ErrorCode.LOCKED_OUT:
            self._locked_out = True
        joint = self._joint_of.get(event.motor_address)
        where = f'joint {joint!r}' if joint else f'motor {event.motor_address}'
        self.get_logger().error(f'device error {event.code}: {event.description} ({where})')

    def _publish_playback(self, note: PlaybackStatus) -> None:
        msg = PlaybackStatusMsg()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = int(note.status)
        msg.status_name = playback_state_name(note.status)
        msg.elapsed = float(note.elapsed_time) if math.isfinite(note.elapsed_time) else 0.0
        photos = note.photo_count
        msg.photo_count = (min(round(photos), 2**32 - 1)
                           if math.isfinite(photos) and photos >= 0 else 0)
        for address, position in sorted(note.positions.items()):
            name = self._joint_of.get(address)
            if name is not None:
                msg.joint_names.append(name)
                msg.positions.append(float(position) * self.joints[name].scale)
        self._playback_pub.publish(msg)

    def _publish_aux_inputs(self, status: int) -> None:
        """AuxInputStatus bits as sensor_msgs/Joy buttons + the slave controller flag."""
        msg = Joy()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.buttons = [status >> bit & 1 for bit in range(len(AUX_INPUT_BUTTONS))]
        self._aux_pub.publish(msg)
        self._slave_pub.publish(Bool(data=bool(status >> AUX_SLAVE_PRESENT_BIT & 1)))

    def _read_device_settings(self, client: KosClient) -> None:
        """LEDStatus and SoftwareID once per connection, for diagnostics."""
        settings: dict[str, str] = {}
        try:
            master, slave = client.led_status()
            settings['led_master'] = LED_NAMES.get(master, str(master))
            settings['led_slave'] = LED_NAMES.get(slave, str(slave))
            settings['last_client_software_id'] = str(client.software_id())
        except KosError as exc:
            self.get_logger().warning(f'cannot read LEDStatus/SoftwareID: {exc}')
        self._device_settings = settings

    # -------------------------------------------------------------- services
    def _on_command(self, request, response):
        """~/command: the kOS Get/Set messages without a dedicated interface."""
        def action() -> str:
            client = self._client()
            name = request.command.strip()
            args = [a.strip() for a in request.arguments]
            handler = {'GetLEDStatus': (0, self._get_leds), 'SetLEDStatus': (2, self._set_leds),
                       'GetSoftwareID': (0, self._get_software_id),
                       'SetSoftwareID': (1, self._set_software_id)}.get(name)
            if handler is None:
                raise CommandError(f'unknown command {name!r}; this driver has GetLEDStatus, '
                                   'SetLEDStatus MASTER SLAVE, GetSoftwareID, SetSoftwareID ID')
            count, run = handler
            if len(args) != count:
                raise CommandError(f'{name} takes {count} argument(s), got {len(args)}: {args}')
            if request.axis:
                raise CommandError(f'{name} is device-wide: axis must be 0, got {request.axis}')
            try:
                response.results = run(client, args)
            except KosError as exc:
                raise DeviceError(f'{name}: {exc}') from exc
            return f'{name}: ' + ', '.join(response.results)

        return self.serve_request(response, action)

    def _led_results(self, master: int, slave: int) -> list[str]:
        self._device_settings['led_master'] = LED_NAMES.get(master, str(master))
        self._device_settings['led_slave'] = LED_NAMES.get(slave, str(slave))
        return [f'master={self._device_settings["led_master"]}',
                f'slave={self._device_settings["led_slave"]}']

    def _get_leds(self, client: KosClient, _args: list[str]) -> list[str]:
        return self._led_results(*client.led_status())

    def _set_leds(self, client: KosClient, args: list[str]) -> list[str]:
        states = []
        by_name = {v: k for k, v in LED_NAMES.items()}
        for which, text in zip(('master', 'slave'), args, strict=True):
            value = by_name.get(text.lower(), int(text) if text.isdigit() else None)
            if value not in LED_NAMES:
                raise CommandError(f'{which} LED status {text!r} is not one of '
                                   f'{", ".join(f"{k} ({v})" for k, v in LED_NAMES.items())}')
            states.append(value)
        return self._led_results(*client.set_led_status(*states))

    def _get_software_id(self, client: KosClient, _args: list[str]) -> list[str]:
        value = client.software_id()
        self._device_settings['last_client_software_id'] = str(value)
        return [f'software_id={value}']

    def _set_software_id(self, client: KosClient, args: list[str]) -> list[str]:
        if not self.allow_software_id_write:
            raise CommandError('SetSoftwareID changes what the device tells every other client '
                               'about its last user; set the parameter '
                               'allow_software_id_write:=true to allow it')
        text = args[0]
        if not text.isdigit() or int(text) > 0xFF:
            raise CommandError(f'SoftwareID must be an integer 0..255, got {text!r}')
        value = client.set_software_id(int(text))
        self._device_settings['last_client_software_id'] = str(value)
        return [f'software_id={value}']

    def _on_load_trajectory(self, request, response):
        def action() -> str:
            client = self._client()
            self._refuse_during_playback(client)
            start_time = self._start_time(request.start_time)
            settings = PlaybackSettings(
                mode=request.playback_mode, duration=request.duration,
                loop_count=request.loop_count, rapid_reverse=request.rapid_reverse,
                start_delay=request.start_delay, start_time=start_time,
                interval=request.interval,
                exposure=request.exposure, move_photos=request.move_photos,
                pre_move_photos=request.pre_move_photos,
                post_move_photos=request.post_move_photos,
                return_to_home_percent=self.return_to_home_percent)
            keyframes = request.keyframes
            has_keyframes = bool(keyframes.points)
            if has_keyframes == bool(request.axes):
                raise CommandError('give either keyframes (trajectory_msgs/JointTrajectory) or '
                                   'explicit Bezier axes, not both and not neither')
            client.refresh_motors()
            try:
                if has_keyframes:
                    trajectory = from_keyframes(self._keyframes(keyframes), self.joints,
                                                self._ranges(client), settings)
                else:
                    trajectory = from_segments(self._segments(request.axes), self.joints,
                                               settings)
                client.load_trajectory(trajectory)
            except (ProtocolError, KosError) as exc:
                raise DeviceError(f'trajectory not loaded: {exc}') from exc
            self._delay_return = bool(request.delay_return)
            axes = ', '.join(f'{self._joint_of.get(a, a)}: {len(s)} segment(s)'
                             for a, s in trajectory.axes.items())
            mode = PlaybackMode(request.playback_mode).name.lower()
            when = ''
            if start_time:
                when = time.strftime('; starts at %Y-%m-%dT%H:%M:%SZ', time.gmtime(start_time))
            elif request.start_delay > 0:
                when = f'; starts {request.start_delay:g} s after ~/start_playback'
            if self._delay_return:
                when += '; delay_return: ~/setup_playback does not move the axes'
            return (f'{mode} move loaded ({axes}), duration '
                    f'{trajectory.effective_duration():.3f} s{when}; now ~/setup_playback '
                    'and ~/start_playback')

        return self.serve_request(response, action)

    def _start_time(self, stamp) -> int:
        """LoadTrajectory.start_time as UnixTime (0 = not used); a past date is refused."""
        if stamp.sec == 0 and stamp.nanosec == 0:
            return 0
        value = math.ceil(stamp.sec + stamp.nanosec * 1e-9)   # UnixTime is whole seconds
        now = time.time()
        if value <= now:
            raise CommandError(f'start_time {value} (UnixTime s) is {now - value:.0f} s in the '
                               'past; give a future date or use start_delay')
        if value > 0xFFFFFFFF:
            raise CommandError(f'start_time {value} is beyond UnixTime (UInt32) 4294967295')
        return value

    def _keyframes(self, trajectory) -> list[Keyframe]:
        names = list(trajectory.joint_names)
        if not names or len(set(names)) != len(names):
            raise CommandError(f'keyframes.joint_names must be unique and non-empty: {names}')
        unknown = [n for n in names if n not in self.joints]
        if unknown:
            raise CommandError(f'unknown joint(s) {unknown}; this device has '
                               f'{list(self.joint_names)}')
        frames = []
        for index, point in enumerate(trajectory.points):
            if len(point.positions) != len(names):
                raise CommandError(f'keyframe {index}: {len(point.positions)} positions for '
                                   f'{len(names)} joints')
            if point.velocities and len(point.velocities) != len(names):
                raise CommandError(f'keyframe {index}: velocities must be empty or one per '
                                   'joint')
            positions = dict(zip(names, point.positions, strict=True))
            for name, value in positions.items():
                limits = self.limits[name]
                if not math.isfinite(value) or not (
                        limits.position_min <= value <= limits.position_max):
                    raise CommandError(f'keyframe {index}: joint {name!r} position {value} is '
                                       f'outside [{limits.position_min}, '
                                       f'{limits.position_max}]')
            velocities = (dict(zip(names, point.velocities, strict=True))
                          if point.velocities else None)
            t = point.time_from_start.sec + point.time_from_start.nanosec * 1e-9
            frames.append(Keyframe(t, positions, velocities))
        return frames

    def _segments(self, axes) -> dict[str, list[tuple[float, ...]]]:
        segments: dict[str, list[tuple[float, ...]]] = {}
        for axis in axes:
            if axis.joint_name not in self.joints:
                raise CommandError(f'unknown joint {axis.joint_name!r}; this device has '
                                   f'{list(self.joint_names)}')
            if axis.joint_name in segments:
                raise CommandError(f'joint {axis.joint_name!r} is given twice')
            segments[axis.joint_name] = [
                (s.p0_time, s.p0_position, s.p1_time, s.p1_position, s.p2_time,
                 s.p2_position, s.p3_time, s.p3_position) for s in axis.segments]
        return segments

    def _ranges(self, client: KosClient) -> dict[int, AxisRange]:
        return {a: AxisRange(m.begin_position, m.end_position)
                for a, m in client.motors.items() if m.online}

    def _on_setup_playback(self, request, response):
        def action() -> str:
            client = self._client()
            self._refuse_during_playback(client)
            marker = len(client.playback.history)
            try:
                client.setup_playback(delay_return=self._delay_return)
            except KosError as exc:
                raise DeviceError(str(exc)) from exc
            if not client.wait_for(
                    lambda: PlaybackState.SETUP_COMPLETED in client.playback.history[marker:],
                    self.playback_timeout):
                raise DeviceError('no SetupCompleted notification within '
                                  f'{self.playback_timeout:g} s')
            if self._delay_return:
                return ('move set up without moving (delay_return); ~/start_playback returns '
                        'to the first key frame, then plays')
            return 'motors at the first key frame, move set up; call ~/start_playback'

        return self.serve_request(response, action)

    def _on_start_playback(self, request, response):
        def action() -> str:
            client = self._client()
            self._refuse_during_playback(client)
            try:
                client.start_playback()
            except KosError as exc:
                raise DeviceError(str(exc)) from exc
            return 'playback started; follow ~/playback_status (FullStop ends the move)'

        return self.serve_request(response, action)

    def _on_stop_playback(self, request, response):
        def action() -> str:
            self._client().stop_playback()
            return 'StopPlayback sent: motors stop, the device reports FullStop'

        return self.serve_request(response, action)

    def _on_calibrate(self, request, response):
        def action() -> str:
            client = self._client()
            self._refuse_during_playback(client)
            mapping = self.joints.get(request.joint_name)
            if mapping is None:
                raise CommandError(f'unknown joint {request.joint_name!r}; this device has '
                                   f'{list(self.joint_names)}')
            try:
                if request.action == Calibrate.Request.MARK_BEGIN:
                    client.mark_begin(mapping.address)
                    return (f'{mapping.name}: begin marked here; move to the end of the '
                            'travel and mark the end')
                if request.action == Calibrate.Request.MARK_END:
                    begin, end = client.mark_end(mapping.address)
                    return (f'{mapping.name}: calibrated, range {begin * mapping.scale:.4f} .. '
                            f'{end * mapping.scale:.4f} (position is now relative to the '
                            'begin mark)')
                if request.action == Calibrate.Request.RESET:
                    client.reset_axis(mapping.address)
                    return f'{mapping.name}: calibration cleared, position reset to 0'
            except KosError as exc:
                raise DeviceError(str(exc)) from exc
            raise CommandError(f'action {request.action} is not MARK_BEGIN (0), MARK_END (1) '
                               'or RESET (2)')

        return self.serve_request(response, action)

    def _on_take_picture(self, request, response):
        def action() -> str:
            try:
                self._client().take_picture(self.picture_exposure)
            except KosError as exc:
                raise DeviceError(str(exc)) from exc
            return f'picture taken (exposure {self.picture_exposure:g} s)'

        return self.serve_request(response, action)

    # ------------------------------------------------------------ diagnostics
    def device_status_parts(self) -> list[StatusPart]:
        client = self.client
        if client is None:
            return []
        with self._errors_lock:
            errors = list(self._latched_errors)
        device_errors = [e for e in errors if e.motor_address not in self._joint_of]
        device = StatusPart('device')
        device.values = [
            ('lock', 'LOCKED (password rejected)' if self._locked_out else 'unlocked'),
            ('playback_status', playback_state_name(client.playback.status)),
            ('move_loaded', str(client.playback.loaded)),
            ('guid', client.guid),
            ('malformed_frames', str(client.malformed_frames)),
            ('unsupported_replies', str(client.unsupported_replies)),
            ('transport', self.transport),
            *([('usb_dropped_reports', str(client.usb_dropped_reports))]
              if self.transport == 'usb' else []),
            ('aux_inputs', ' '.join(f'{n}={client.aux_inputs >> b & 1}'
                                    for b, n in enumerate(AUX_INPUT_BUTTONS))),
            ('slave_controller_present',
             str(bool(client.aux_inputs >> AUX_SLAVE_PRESENT_BIT & 1))),
            *sorted(self._device_settings.items()),
            *[(f'error_{e.code}', f'{e.description} (motor {e.motor_address})')
              for e in device_errors],
        ]
        if self._locked_out:
            device.level, device.message = Level.ERROR, 'device locked: password rejected'
        elif device_errors:
            device.level = Level.ERROR
            device.message = f'error {device_errors[-1].code}: {device_errors[-1].description}'
        else:
            device.message = f'OK, playback {playback_state_name(client.playback.status)}'
        parts = [device]
        for name, mapping in self.joints.items():
            part = StatusPart(name)
            motor = client.motors.get(mapping.address)
            axis_errors = [e for e in errors if e.motor_address == mapping.address]
            if motor is None or not motor.online:
                part.level, part.message = Level.ERROR, f'motor {mapping.address} offline'
                part.values = [('motor_address', str(mapping.address)), ('online', 'False')]
                parts.append(part)
                continue
            part.values = [
                ('motor_address', str(mapping.address)), ('online', 'True'),
                ('calibrated', str(motor.calibrated)),
                ('begin_position', f'{motor.begin_position * mapping.scale:.6g}'),
                ('end_position', f'{motor.end_position * mapping.scale:.6g}'),
                ('position_rotations', f'{motor.position:.6g}'),
                ('max_setup_speed', f'{motor.max_setup_speed * abs(mapping.scale):.6g}'),
                ('max_move_speed', f'{motor.max_move_speed * abs(mapping.scale):.6g}'),
                ('max_acceleration', f'{motor.max_acceleration * abs(mapping.scale):.6g}'),
                ('fiz_motor', str(motor.is_fiz)),
                *[(f'error_{e.code}', e.description) for e in axis_errors],
            ]
            if axis_errors:
                last = axis_errors[-1]
                part.level = Level.ERROR
                part.message = f'error {last.code}: {last.description}'
            elif not motor.calibrated:
                part.level, part.message = Level.WARN, 'not calibrated (no playback, ' \
                    'uncalibrated travel)'
            else:
                part.message = 'calibrated'
            parts.append(part)
        return parts

    def device_mode(self) -> str:
        client = self.client
        if client is None:
            return ''
        mode = client.device_info.playback_mode if client.device_info else 0
        try:
            mode_name = PlaybackMode(mode).name.lower()
        except ValueError:
            mode_name = str(mode)
        return f'{mode_name}/{playback_state_name(client.playback.status)}'

    def axis_details(self, joint: str) -> dict[str, object]:
        client = self.client
        mapping = self.joints[joint]
        motor = client.motors.get(mapping.address) if client else None
        if motor is None:
            return {'state': AxisState.STATE_DISABLED}
        with self._errors_lock:
            errors = [ERROR_CODES[e.code].description if e.code in ERROR_CODES else
                      f'error {e.code}' for e in self._latched_errors
                      if e.motor_address == mapping.address]
        details: dict[str, object] = {'calibrated': motor.calibrated,
                                      'homed': motor.calibrated, 'active_errors': errors}
        if not motor.online:
            details['state'] = AxisState.STATE_DISABLED
        elif errors:
            details['state'] = AxisState.STATE_FAULT
        elif client.playback_running:
            details['state'] = AxisState.STATE_PLAYBACK
        return details

    def device_errors(self) -> list[str]:
        with self._errors_lock:
            return [f'{e.code}: {e.description}' for e in self._latched_errors
                    if e.motor_address not in self._joint_of]


def main(args: Sequence[str] | None = None) -> int:
    return run_driver(KosDriverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
