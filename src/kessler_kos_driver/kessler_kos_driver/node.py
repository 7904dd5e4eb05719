"""ROS 2 node for Kessler kOS devices: parameters, the device adapter and the kOS extras.

The base node (gimbal_driver_common.ros.base_node) and its controller provide the lifecycle,
link supervision, joint_states, joint_command, ~/stop, ~/move_to, ~/home, presets
(driver-side YAML, kOS has none), the driver-side `sector` scan, /diagnostics and ~/status.
Everything device-side, including the SI <-> motor rotation conversion (`calibrated_spans`,
`joint_offsets`, `joint_scales`: :mod:`kessler_kos_driver.units`), is in the ROS-free
adapter :class:`~kessler_kos_driver.device.KosDevice` (built by
:meth:`KosDriverNode.make_device`); this node sees SI only. It adds the kOS services
(playback, ~/calibrate, ~/take_picture, ~/command for LEDStatus and SoftwareID) and topics
(~/playback_status, ~/aux_inputs, ~/slave_controller_present); each service is one call of
adapter methods through the controller's ``call()`` boundary, never the client. The service
handlers are the part :class:`~.ros_services.KosServices` (``kos_services``).

The `password` parameter is redacted: rclpy publishes declared parameter values on
/parameter_events and serves them on ~/get_parameters, so the real value is taken from the
parameter overrides (or `password_file`) and the declared parameter only ever holds
'********' (read-only).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from pathlib import Path

from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile
from sensor_msgs.msg import Joy
from std_msgs.msg import Bool
from std_srvs.srv import Trigger

from gimbal_driver_common.device import Device
from gimbal_driver_common.ros.base_node import Answer, GimbalDriverNode
from gimbal_driver_common.ros.parameters import ParameterError, take_secret
from gimbal_driver_common.ros.run import run_driver
from gimbal_msgs.msg import PlaybackStatus as PlaybackStatusMsg
from gimbal_msgs.srv import Calibrate, DeviceCommand, LoadTrajectory

from .client import KosClient
from .device import KosDevice, KosSettings, joint_mappings
from .playback import PlaybackReport
from .protocol import (
    DEFAULT_TCP_PORT,
    MOTOR_ADDRESS_MAX,
    MOTOR_ADDRESS_MIN,
    REPORT_SIZE,
    USB_KEEPALIVE_PERIOD_S,
)
from .ros_services import KosServices
from .status import AUX_INPUT_BUTTONS, AUX_SLAVE_PRESENT_BIT
from .units import MOTOR_RADIANS, MOTOR_RADIANS_PER_ROTATION, JointUnits, joint_units
from .usb_link import USB_BACKENDS, UsbTarget

REDACTED = '********'
TRANSPORTS = ('tcp', 'usb')
#: the parameters of the SI <-> rotation conversion (changed together, while idle)
UNIT_PARAMETERS = ('calibrated_spans', 'joint_offsets', 'joint_scales')


class KosDriverNode(GimbalDriverNode):
    DEFAULT_JOINT_NAMES = ('slider', 'pan', 'tilt')
    # One example rig in SI, the same in urdf/kessler_kos_driver.urdf (the package's
    # test/test_description_files.py checks they agree): a slider of 1.5 m from its begin mark
    # at up to 0.5 m/s, a pan of +-pi at up to 1.5 rad/s and a tilt of +-pi/2 at up to 1 rad/s.
    # The device checks its calibrated ranges and MaxMax speeds as well (the adapter, in SI).
    DEFAULT_POSITION_MIN = (0.0, -math.pi, -math.pi / 2)
    DEFAULT_POSITION_MAX = (1.5, math.pi, math.pi / 2)
    DEFAULT_VELOCITY_MAX = (0.5, 1.5, 1.0)
    SCAN_PATTERNS = ('sector',)

    def __init__(self, **kwargs: object) -> None:
        super().__init__('kessler_kos_driver', **kwargs)
        services = self.kos_services = KosServices(self)
        self._playback_pub = self.create_publisher(PlaybackStatusMsg, '~/playback_status', 10)
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self._aux_pub = self.create_publisher(Joy, '~/aux_inputs', latched)
        self._slave_pub = self.create_publisher(Bool, '~/slave_controller_present', latched)
        self.create_services([
            (DeviceCommand, '~/command', services.on_command),
            (LoadTrajectory, '~/load_trajectory', services.on_load_trajectory),
            (Trigger, '~/setup_playback', services.on_setup_playback),
            (Trigger, '~/start_playback', services.on_start_playback),
            (Trigger, '~/stop_playback', services.on_stop_playback),
            (Calibrate, '~/calibrate', services.on_calibrate),
            (Trigger, '~/take_picture', services.on_take_picture),
        ])

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
        self.calibrated_spans = self.declare_param(
            'calibrated_spans', [0.0] * n,
            'per joint: how far the joint moves from its begin mark to its end mark (m or rad, '
            'signed in the REP-103 direction), measured on the rig; a calibrated axis then '
            'reports joint_offsets + rotations * span / end_position (0 = no span: '
            'joint_scales)', element_type=float)
        self.joint_offsets = self.declare_param(
            'joint_offsets', [0.0] * n,
            'per joint: the SI value (m or rad) at the begin mark (motor rotation 0)',
            element_type=float)
        self.joint_scales = self.declare_param(
            'joint_scales', [MOTOR_RADIANS_PER_ROTATION] * n,
            'per joint without a calibrated span: SI units (m or rad) per motor rotation; '
            'negative flips the direction (default 2*pi: motor-shaft radians, not the joint)',
            element_type=float)
        self.acceleration_scale = self.declare_param(
            'acceleration_scale', 0.5,
            'fraction of each motor\'s MaxMaxAcceleration used for moves and jogs',
            value_range=(0.01, 1.0))
        # Positions come from MotorInfo polls, so the poll runs at publish_rate by default:
        # joint_states then arrive at publish_rate (a fixed 0.05 s gave 20 Hz).
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
        self.joint_units = self._joint_units(self.parameter_registry.current)
        self.kos_settings = KosSettings(self.acceleration_scale, self.playback_timeout)

    def _declare_password(self) -> str:
        """Take the password without ever letting its value into a parameter event."""
        given = take_secret(self, 'password')
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
                           read_only=True, ignore_override=True)
        return password

    # ------------------------------------------------- run-time parameters
    def _joint_units(self, value_of: Callable[[str], object]) -> list[JointUnits]:
        """The unit parameters, checked (start-up and ``ros2 param set``)."""
        try:
            spans, offsets, scales = (float_list(value_of(n)) for n in UNIT_PARAMETERS)
            return joint_units(len(self.joint_names), spans, offsets, scales)
        except ValueError as exc:
            raise ParameterError(str(exc)) from None

    def declare_runtime_parameters(self) -> None:
        """kOS parameters that apply when set; the link settings need a reconfigure.

        calibrated_spans, joint_offsets and joint_scales change the SI<->rotation conversion
        of every command and reading, so they are taken only while the axes are idle and no
        device move (playback) runs.
        """

        def units_busy() -> str | None:
            device = self.device
            if device is None:
                return None
            reason = device.playing() or self.configured().busy()
            return f'the axes must be idle ({reason})' if reason else None

        def set_units(name: str) -> Callable[[list[float]], None]:
            def apply(values: list[float]) -> None:
                setattr(self, name, values)
                self.joint_units = joint_units(
                    len(self.joint_names), *(getattr(self, n) for n in UNIT_PARAMETERS))
                if self.device is not None:
                    self.device.set_units(self.joint_units,
                                          dict(self.configured().commanded_targets))
            return apply

        for name in UNIT_PARAMETERS:
            self.runtime_parameter(name, set_units(name), busy=units_busy)
        self.parameter_check(UNIT_PARAMETERS, self._joint_units)
        for name in ('return_to_home_percent', 'picture_exposure'):
            self.runtime_parameter(name, name)

        def set_setting(name: str) -> Callable[[object], None]:
            def apply(value: object) -> None:
                setattr(self, name, value)
                setattr(self.kos_settings, name, value)
            return apply

        for name in ('acceleration_scale', 'playback_timeout'):
            self.runtime_parameter(name, set_setting(name))

        def set_poll_period(period: float) -> None:
            self.poll_period = period
            if self.device is not None:  # applies at the next poll tick
                self.device.set_poll_period(period)

        self.runtime_parameter('poll_period', set_poll_period)

    # ---------------------------------------------------------------- device
    def serve_device(self, response: Answer, request: Callable[[KosDevice], str],
                     joints: Sequence[str] | None = None) -> Answer:
        """A request to the adapter through the controller's ``call()`` boundary (refused
        while inactive, disconnected or, with ``joints``, while they cannot move; errors
        answer success=false)."""
        return self.serve_request(
            response, lambda: self.configured().call(lambda: request(self._kos()), joints))

    def make_device(self) -> KosDevice:
        """The client for the configured link (TCP or USB HID) wrapped in the SI adapter."""
        client = KosClient(
            host=self.host, port=self.port, password=self._password,
            discovery_port=self.discovery_port, discovery_timeout=self.discovery_timeout,
            discovery_bind=self.discovery_bind, reply_timeout=self.reply_timeout,
            keepalive_period=self.keepalive_period, poll_period=self.poll_period,
            usb=self.usb_target, usb_report_size=self.usb_report_size,
            usb_keepalive_period=self.usb_keepalive_period,
        )
        joints = joint_mappings(self.joint_names, self.motor_addresses, self.joint_units)
        return KosDevice(client, joints, self.config, self.kos_settings,
                         on_playback=self._publish_playback,
                         on_aux_inputs=self._publish_aux_inputs)

    @property
    def device(self) -> KosDevice | None:
        """The adapter (after configure)."""
        device = super().device
        assert device is None or isinstance(device, KosDevice)
        return device

    def _kos(self) -> KosDevice:
        """The adapter, for a request path (refused before configure)."""
        device = self.configured().device
        assert isinstance(device, KosDevice)
        return device

    def device_ready(self, device: Device) -> None:
        """Units are never silent: what each joint reports, and a warning naming the
        parameters to set for each joint that reports motor radians."""
        assert isinstance(device, KosDevice)
        report = device.units_report()
        self.get_logger().info('joint units: ' + ', '.join(f'{j} {u}' for j, u in report.items()))
        for joint, units in report.items():
            if units != MOTOR_RADIANS:
                continue
            index = self.joint_names.index(joint)
            pending = (' (its calibrated_spans entry applies once the axis is calibrated: '
                       '~/calibrate)' if self.calibrated_spans[index] else '')
            self.get_logger().warning(
                f'joint {joint!r} reports motor-shaft radians, not the joint\'s rad or m: no '
                f'calibrated span applies{pending} and joint_scales is 2*pi per motor '
                'rotation; set calibrated_spans (the distance between the begin and end '
                'marks, measured on the rig) or joint_scales (SI per motor rotation)')

    # ---------------------------------------------------------- notifications
    def _publish_playback(self, report: PlaybackReport) -> None:
        msg = PlaybackStatusMsg()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status, msg.status_name = report.status, report.status_name
        msg.elapsed, msg.photo_count = report.elapsed, report.photo_count
        msg.joint_names = list(report.positions)
        msg.positions = list(report.positions.values())
        self._playback_pub.publish(msg)

    def _publish_aux_inputs(self, status: int) -> None:
        """AuxInputStatus bits as sensor_msgs/Joy buttons + the slave controller flag."""
        msg = Joy()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.buttons = [status >> bit & 1 for bit in range(len(AUX_INPUT_BUTTONS))]
        self._aux_pub.publish(msg)
        self._slave_pub.publish(Bool(data=bool(status >> AUX_SLAVE_PRESENT_BIT & 1)))


def float_list(value: object) -> list[float]:
    """A double-array parameter's value (declared as one: a sequence of numbers)."""
    assert isinstance(value, Sequence)
    return [float(v) for v in value]


def main(args: Sequence[str] | None = None) -> int:
    return run_driver(KosDriverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
