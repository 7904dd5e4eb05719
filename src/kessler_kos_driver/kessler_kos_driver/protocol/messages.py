"""Every Get/Set/Response message, Action and Notification of the kOS document.

Each message class knows its MessageID and MessageType and encodes its own payload; `decode`
turns one complete frame into the matching class, or `UnknownMessage` for ids/actions/
notifications the document does not define (those are ignored by the client, and the
simulator answers them with UnsupportedMessage).

Reconstruction decisions (see also the README "spec notes"):
- DeviceInfo.DevicePassword is part of the response payload; the field is excluded from repr()
  so that logging a decoded DeviceInfo can never leak the password.
- PlaybackStatus(Notification).PhotoCount is Float32 in the notification table but UInt32 in
  DeviceInfo; both tables are followed literally (same four bytes, different type).
- MotorInfo MotorAddress: low 7 bits address, high bit F.I.Z. flag (document text).
- MotorInfo is returned one motor per frame; MessageType 0x82 = more frames follow, 0x02 = last.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass, field
from typing import ClassVar

from .constants import (
    ALL_MOTORS,
    FIZ_FLAG,
    MOTOR_ADDRESS_MAX,
    MOTOR_ADDRESS_MIN,
    ActionId,
    DelayMode,
    MessageId,
    MessageType,
    NotificationId,
)
from .errors import DecodeError, EncodeError
from .framing import encode_frame, split_frame
from .wire import Reader, Writer


def check_motor_address(address: int, allow_all: bool = False) -> int:
    low = ALL_MOTORS if allow_all else MOTOR_ADDRESS_MIN
    if not isinstance(address, int) or not low <= address <= MOTOR_ADDRESS_MAX:
        extra = ' (0 = all motors)' if allow_all else ''
        raise EncodeError(
            f'motor address must be {low}..{MOTOR_ADDRESS_MAX}{extra}, got {address!r}'
        )
    return address


class Message:
    """Base: subclasses set MESSAGE_ID and a message_type (class constant or field)."""

    MESSAGE_ID: ClassVar[int]

    @property
    def message_type(self) -> int:
        """The header's MessageType: a class constant, a field or computed (subclasses)."""
        raise NotImplementedError

    def payload(self) -> bytes:
        return b''

    def encode(self) -> bytes:
        return encode_frame(self.MESSAGE_ID, int(self.message_type), self.payload())

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> Message:
        return cls()


# --------------------------------------------------------------------------- Get requests
@dataclass
class _GetRequest(Message):
    message_type: ClassVar[int] = MessageType.GET


@dataclass
class GetNetworkInfo(_GetRequest):
    """(Get)NetworkInfo; also the documented keep-alive. limited_response asks for a UDP
    limited broadcast reply, which this workspace never requests (loopback only)."""

    MESSAGE_ID: ClassVar[int] = MessageId.NETWORK_INFO
    limited_response: bool = False

    def payload(self) -> bytes:
        return Writer().boolean(self.limited_response).getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> GetNetworkInfo:
        # Tolerate an empty Get: the parameter is optional in practice.
        return cls(reader.boolean('LimitedResponse') if reader.remaining else False)


@dataclass
class GetLedStatus(_GetRequest):
    MESSAGE_ID: ClassVar[int] = MessageId.LED_STATUS


@dataclass
class GetMotorInfo(_GetRequest):
    MESSAGE_ID: ClassVar[int] = MessageId.MOTOR_INFO


@dataclass
class GetDeviceInfo(_GetRequest):
    MESSAGE_ID: ClassVar[int] = MessageId.DEVICE_INFO


@dataclass
class GetTrajectoryData(_GetRequest):
    MESSAGE_ID: ClassVar[int] = MessageId.TRAJECTORY_DATA


@dataclass
class GetDeviceGuid(_GetRequest):
    MESSAGE_ID: ClassVar[int] = MessageId.DEVICE_GUID


@dataclass
class GetSoftwareId(_GetRequest):
    MESSAGE_ID: ClassVar[int] = MessageId.SOFTWARE_ID


# ------------------------------------------------------------------ Set / Response messages
@dataclass
class NetworkInfo(Message):
    MESSAGE_ID: ClassVar[int] = MessageId.NETWORK_INFO
    dhcp: bool = False
    mac_address: bytes = b'\x00' * 6
    ip_address: int = 0
    subnet_mask: int = 0
    gateway: int = 0
    device_type: int = 0
    device_addr: int = 0
    message_type: int = MessageType.RESPONSE

    def payload(self) -> bytes:
        if len(self.mac_address) != 6:
            raise EncodeError(f'MACAddress must be 6 bytes, got {len(self.mac_address)}')
        w = Writer().boolean(self.dhcp).raw(self.mac_address)
        w.u32(self.ip_address, 'IPAddress').u32(self.subnet_mask, 'SubnetMask')
        w.u32(self.gateway, 'Gateway').u8(self.device_type, 'DeviceType')
        return w.u8(self.device_addr, 'DeviceAddr').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> NetworkInfo:
        return cls(
            reader.boolean(), reader.take(6, 'MACAddress'), reader.u32(), reader.u32(),
            reader.u32(), reader.u8(), reader.u8(), message_type,
        )

    @property
    def ip_text(self) -> str:
        return '.'.join(str((self.ip_address >> s) & 0xFF) for s in (24, 16, 8, 0))


@dataclass
class LedStatus(Message):
    MESSAGE_ID: ClassVar[int] = MessageId.LED_STATUS
    master_status: int = 0
    slave_status: int = 0
    message_type: int = MessageType.SET

    def payload(self) -> bytes:
        w = Writer().u8(self.master_status, 'MasterStatus')
        return w.u8(self.slave_status, 'SlaveStatus').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> LedStatus:
        return cls(reader.u8(), reader.u8(), message_type)


@dataclass
class MotorInfoEntry:
    address: int
    position: float
    begin_position: float
    end_position: float
    max_setup_speed: float       # MaxMaxSetupSpeed, rotations/s
    max_move_speed: float        # MaxMaxMoveSpeed, rotations/s
    max_acceleration: float      # MaxMaxAcceleration, rotations/s^2
    is_fiz: bool = False

    @property
    def calibrated(self) -> bool:
        """EndPosition 0 means "not (or no longer) calibrated"."""
        return self.end_position != 0.0


#: one MotorInfo entry: MotorAddress, then Position, Begin, End and the three maxima (Float32)
_MOTOR_INFO_ENTRY = struct.Struct('>B6f')


@dataclass
class MotorInfo(Message):
    """MotorInfo(Response). Devices send one motor per frame (MotorCount 1) with type 0x82
    while more follow; the codec accepts any count."""

    MESSAGE_ID: ClassVar[int] = MessageId.MOTOR_INFO
    motors: list[MotorInfoEntry] = field(default_factory=list)
    more_follows: bool = False

    @property
    def message_type(self) -> int:
        return MessageType.RESPONSE_MORE if self.more_follows else MessageType.RESPONSE

    def payload(self) -> bytes:
        w = Writer().u8(len(self.motors), 'MotorCount')
        for m in self.motors:
            check_motor_address(m.address)
            w.u8(m.address | (FIZ_FLAG if m.is_fiz else 0), 'MotorAddress')
            for value in (m.position, m.begin_position, m.end_position, m.max_setup_speed,
                          m.max_move_speed, m.max_acceleration):
                w.f32(value)
        return w.getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> MotorInfo:
        count = reader.u8('MotorCount')
        # all entries in one take and one iter_unpack: the polled hot path (make bench)
        entries = reader.take(count * _MOTOR_INFO_ENTRY.size, 'MotorInfo entries')
        motors = [MotorInfoEntry(raw & 0x7F, position, begin, end, setup_speed, move_speed,
                                 acceleration, bool(raw & FIZ_FLAG))
                  for raw, position, begin, end, setup_speed, move_speed, acceleration
                  in _MOTOR_INFO_ENTRY.iter_unpack(entries)]
        return cls(motors, message_type == MessageType.RESPONSE_MORE)


@dataclass
class DeviceInfo(Message):
    MESSAGE_ID: ClassVar[int] = MessageId.DEVICE_INFO
    message_type: ClassVar[int] = MessageType.RESPONSE
    device_type: int = 0
    device_addr: int = 0
    playback_mode: int = 0
    playback_status: int = 0
    firmware_major: int = 0
    firmware_minor: int = 0
    firmware_release: int = 0
    firmware_build: int = 0
    network_id: int = 0
    hardware_id: int = 0
    device_password: str = field(default='', repr=False)
    aux_input_status: int = 0
    delay_time_remaining: float = 0.0
    elapsed_time: float = 0.0
    photo_count: int = 0

    def payload(self) -> bytes:
        w = Writer()
        for name in ('device_type', 'device_addr', 'playback_mode', 'playback_status',
                     'firmware_major', 'firmware_minor', 'firmware_release', 'firmware_build',
                     'network_id', 'hardware_id'):
            w.u8(getattr(self, name), name)
        w.string(self.device_password, 'DevicePassword').u8(self.aux_input_status)
        w.f32(self.delay_time_remaining).f32(self.elapsed_time)
        return w.u32(self.photo_count, 'PhotoCount').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> DeviceInfo:
        (device_type, device_addr, playback_mode, playback_status, firmware_major,
         firmware_minor, firmware_release, firmware_build, network_id,
         hardware_id) = (reader.u8() for _ in range(10))
        return cls(device_type, device_addr, playback_mode, playback_status, firmware_major,
                   firmware_minor, firmware_release, firmware_build, network_id, hardware_id,
                   reader.string('DevicePassword'), reader.u8(), reader.f32(), reader.f32(),
                   reader.u32())

    @property
    def firmware(self) -> str:
        return (f'{self.firmware_major}.{self.firmware_minor}.'
                f'{self.firmware_release}.{self.firmware_build}')


@dataclass
class UserPassword(Message):
    """(Set)UserPassword: unlocks the device. repr hides the password."""

    MESSAGE_ID: ClassVar[int] = MessageId.USER_PASSWORD
    message_type: ClassVar[int] = MessageType.SET
    password: str = field(default='', repr=False)

    def payload(self) -> bytes:
        return Writer().string(self.password, 'Password').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> UserPassword:
        return cls(reader.string('Password'))


@dataclass
class DevicePassword(UserPassword):
    """(Set)DevicePassword: changes the device password (a persistent write)."""

    MESSAGE_ID: ClassVar[int] = MessageId.DEVICE_PASSWORD


@dataclass
class DeviceGuid(Message):
    MESSAGE_ID: ClassVar[int] = MessageId.DEVICE_GUID
    message_type: ClassVar[int] = MessageType.RESPONSE
    guid: bytes = b''

    def payload(self) -> bytes:
        return Writer().block(self.guid, 'GUID').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> DeviceGuid:
        return cls(reader.block('GUID'))

    @property
    def text(self) -> str:
        return self.guid.hex()


@dataclass
class SoftwareId(Message):
    MESSAGE_ID: ClassVar[int] = MessageId.SOFTWARE_ID
    device_type: int = 0
    message_type: int = MessageType.SET

    def payload(self) -> bytes:
        return Writer().u8(self.device_type, 'DeviceType').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> SoftwareId:
        return cls(reader.u8(), message_type)


# ------------------------------------------------------------------------------- Actions
@dataclass
class Action(Message):
    MESSAGE_ID: ClassVar[int] = MessageId.ACTION
    message_type: ClassVar[int] = MessageType.SET
    ACTION_ID: ClassVar[int]

    def params(self) -> bytes:
        return b''

    def payload(self) -> bytes:
        return bytes([self.ACTION_ID]) + self.params()


@dataclass
class ResetDevice(Action):
    """Soft reboot; the node only sends it with the explicit opt-in parameter."""

    ACTION_ID: ClassVar[int] = ActionId.RESET_DEVICE


@dataclass
class _AddressAction(Action):
    motor_address: int = 1
    ALLOW_ALL: ClassVar[bool] = False

    def params(self) -> bytes:
        check_motor_address(self.motor_address, self.ALLOW_ALL)
        return bytes([self.motor_address])

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> _AddressAction:
        return cls(reader.u8('MotorAddress'))


@dataclass
class ResetAxis(_AddressAction):
    """Clears calibration, position becomes 0; address 0 resets all (no notification)."""

    ACTION_ID: ClassVar[int] = ActionId.RESET_AXIS
    ALLOW_ALL: ClassVar[bool] = True


@dataclass
class MarkBeginPosition(_AddressAction):
    ACTION_ID: ClassVar[int] = ActionId.MARK_BEGIN_POSITION


@dataclass
class MarkEndPosition(_AddressAction):
    ACTION_ID: ClassVar[int] = ActionId.MARK_END_POSITION


@dataclass
class StartPlayback(Action):
    ACTION_ID: ClassVar[int] = ActionId.START_PLAYBACK
    direction: int = 0
    start_time: float = 0.0

    def params(self) -> bytes:
        return Writer().u8(self.direction, 'Direction').f32(self.start_time).getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> StartPlayback:
        return cls(reader.u8(), reader.f32())


@dataclass
class StopPlayback(Action):
    ACTION_ID: ClassVar[int] = ActionId.STOP_PLAYBACK


@dataclass
class RapidToFirstKeyFrame(Action):
    ACTION_ID: ClassVar[int] = ActionId.RAPID_TO_FIRST_KEY_FRAME


@dataclass
class TakePicture(Action):
    ACTION_ID: ClassVar[int] = ActionId.TAKE_PICTURE
    motor_address: int = ALL_MOTORS
    exposure: float = 0.0

    def params(self) -> bytes:
        check_motor_address(self.motor_address, allow_all=True)
        if self.exposure < 0:
            raise EncodeError(f'Exposure must be >= 0 s, got {self.exposure}')
        return Writer().u8(self.motor_address).f32(self.exposure, 'Exposure').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> TakePicture:
        return cls(reader.u8(), reader.f32())


@dataclass
class SetupPlayback(Action):
    ACTION_ID: ClassVar[int] = ActionId.SETUP_PLAYBACK
    direction: int = 0
    start_time: float = 0.0
    delay_return: bool = False

    def params(self) -> bytes:
        w = Writer().u8(self.direction, 'Direction').f32(self.start_time, 'StartTime')
        return w.boolean(self.delay_return).getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> SetupPlayback:
        return cls(reader.u8(), reader.f32(), reader.boolean())


@dataclass
class SetPositionSpeedAcceleration(Action):
    """Absolute move (rotations). Speed 0 stops the motor. Uncalibrated motors: +/-25000."""

    ACTION_ID: ClassVar[int] = ActionId.SET_POSITION_SPEED_ACCELERATION
    motor_address: int = 1
    position: float = 0.0
    speed: float = 0.0
    acceleration: float = 0.0

    def params(self) -> bytes:
        check_motor_address(self.motor_address)
        if self.speed < 0 or self.acceleration < 0:
            raise EncodeError('Speed and Acceleration must be >= 0')
        w = Writer().u8(self.motor_address).f32(self.position, 'Position')
        return w.f32(self.speed, 'Speed').f32(self.acceleration, 'Acceleration').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> SetPositionSpeedAcceleration:
        return cls(reader.u8(), reader.f32(), reader.f32(), reader.f32())


@dataclass
class BumpPositionSpeedAcceleration(SetPositionSpeedAcceleration):
    """Relative move: `position` carries the document's Delta parameter."""

    ACTION_ID: ClassVar[int] = ActionId.BUMP_POSITION_SPEED_ACCELERATION

    @property
    def delta(self) -> float:
        return self.position


# ------------------------------------------------------------------------- Notifications
@dataclass
class Notification(Message):
    MESSAGE_ID: ClassVar[int] = MessageId.NOTIFICATION
    message_type: ClassVar[int] = MessageType.RESPONSE
    NOTE_ID: ClassVar[int]

    def params(self) -> bytes:
        return b''

    def payload(self) -> bytes:
        return bytes([self.NOTE_ID]) + self.params()


@dataclass
class MotorStatusEntry:
    address: int
    online: bool
    motor_type: int               # 0 = not F.I.Z., 1 = F.I.Z.
    max_setup_speed: float
    max_move_speed: float
    max_acceleration: float


@dataclass
class MotorStatus(Notification):
    NOTE_ID: ClassVar[int] = NotificationId.MOTOR_STATUS
    motors: list[MotorStatusEntry] = field(default_factory=list)

    def params(self) -> bytes:
        w = Writer().u8(len(self.motors), 'MotorCount')
        for m in self.motors:
            w.u8(m.address, 'MotorAddress').boolean(m.online).u8(m.motor_type, 'MotorType')
            w.f32(m.max_setup_speed).f32(m.max_move_speed).f32(m.max_acceleration)
        return w.getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> MotorStatus:
        count = reader.u8('MotorCount')
        return cls([
            MotorStatusEntry(reader.u8(), reader.boolean(), reader.u8(), reader.f32(),
                             reader.f32(), reader.f32())
            for _ in range(count)
        ])


@dataclass
class PlaybackStatus(Notification):
    NOTE_ID: ClassVar[int] = NotificationId.PLAYBACK_STATUS
    status: int = 0
    elapsed_time: float = 0.0
    photo_count: float = 0.0                       # Float32 per the notification table
    positions: dict[int, float] = field(default_factory=dict)   # address -> rotations

    def params(self) -> bytes:
        w = Writer().u8(self.status, 'PlaybackStatus').f32(self.elapsed_time, 'ElapsedTime')
        w.f32(self.photo_count, 'PhotoCount').u8(len(self.positions), 'MotorCount')
        for address, position in self.positions.items():
            w.u8(address, 'MotorAddress').f32(position, 'Position')
        return w.getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> PlaybackStatus:
        status, elapsed, photos = reader.u8(), reader.f32(), reader.f32()
        count = reader.u8('MotorCount')
        positions = {}
        for _ in range(count):
            address = reader.u8('MotorAddress')
            positions[address] = reader.f32('Position')
        return cls(status, elapsed, photos, positions)


@dataclass
class ErrorStatus(Notification):
    NOTE_ID: ClassVar[int] = NotificationId.ERROR_STATUS
    error_code: int = 0
    motor_address: int = 0

    def params(self) -> bytes:
        return Writer().u8(self.error_code, 'ErrorCode').u8(self.motor_address).getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> ErrorStatus:
        return cls(reader.u8(), reader.u8())


@dataclass
class MotorPosition(Notification):
    NOTE_ID: ClassVar[int] = NotificationId.MOTOR_POSITION
    motor_address: int = 1
    position: float = 0.0

    def params(self) -> bytes:
        return Writer().u8(self.motor_address).f32(self.position, 'Position').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> MotorPosition:
        return cls(reader.u8(), reader.f32())


@dataclass
class MotorCalibrated(Notification):
    NOTE_ID: ClassVar[int] = NotificationId.MOTOR_CALIBRATED
    motor_address: int = 1
    begin_position: float = 0.0
    end_position: float = 0.0

    def params(self) -> bytes:
        w = Writer().u8(self.motor_address).f32(self.begin_position, 'BeginPosition')
        return w.f32(self.end_position, 'EndPosition').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> MotorCalibrated:
        return cls(reader.u8(), reader.f32(), reader.f32())


@dataclass
class AuxInputStatus(Notification):
    NOTE_ID: ClassVar[int] = NotificationId.AUX_INPUT_STATUS
    status: int = 0

    def params(self) -> bytes:
        return Writer().u8(self.status, 'Status').getvalue()

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> AuxInputStatus:
        return cls(reader.u8())

    def bit(self, index: int) -> bool:
        return bool(self.status >> index & 1)


@dataclass
class UnsupportedMessage(Notification):
    """Device reply to a message it does not support; carries (part of) that message."""

    NOTE_ID: ClassVar[int] = NotificationId.UNSUPPORTED_MESSAGE
    offending: bytes = b''

    def params(self) -> bytes:
        return bytes(self.offending)

    @classmethod
    def from_payload(cls, reader: Reader, message_type: int) -> UnsupportedMessage:
        return cls(reader.rest())


@dataclass
class UnknownMessage(Message):
    """A well-framed message the document does not define (ignored by the client)."""

    message_id: int = 0
    message_type: int = 0
    raw_payload: bytes = b''

    def encode(self) -> bytes:
        return encode_frame(self.message_id, self.message_type, self.raw_payload)

    @property
    def sub_id(self) -> int | None:
        """Action/notification id for 0x80/0x81 frames, else None."""
        if self.message_id in (MessageId.ACTION, MessageId.NOTIFICATION) and self.raw_payload:
            return self.raw_payload[0]
        return None


# ------------------------------------------------------------------------------- decoding
_GETS = {cls.MESSAGE_ID: cls for cls in (
    GetNetworkInfo, GetLedStatus, GetMotorInfo, GetDeviceInfo, GetTrajectoryData,
    GetDeviceGuid, GetSoftwareId)}
_DATA = {cls.MESSAGE_ID: cls for cls in (
    NetworkInfo, LedStatus, MotorInfo, DeviceInfo, UserPassword, DevicePassword, DeviceGuid,
    SoftwareId)}
ACTIONS: dict[int, type[Action]] = {cls.ACTION_ID: cls for cls in (
    ResetDevice, ResetAxis, MarkBeginPosition, MarkEndPosition, StartPlayback, StopPlayback,
    RapidToFirstKeyFrame, TakePicture, SetupPlayback, SetPositionSpeedAcceleration,
    BumpPositionSpeedAcceleration)}
NOTIFICATIONS: dict[int, type[Notification]] = {cls.NOTE_ID: cls for cls in (
    MotorStatus, PlaybackStatus, ErrorStatus, MotorPosition, MotorCalibrated, AuxInputStatus,
    UnsupportedMessage)}


def _lookup(message_id: int, message_type: int, payload: bytes) -> type[Message] | None:
    if message_id == MessageId.ACTION:
        return ACTIONS.get(payload[0]) if payload else None
    if message_id == MessageId.NOTIFICATION:
        return NOTIFICATIONS.get(payload[0]) if payload else None
    if message_id == MessageId.TRAJECTORY_DATA and message_type != MessageType.GET:
        from .trajectory import TrajectoryData
        return TrajectoryData
    if message_type == MessageType.GET:
        return _GETS.get(message_id)
    return _DATA.get(message_id)


def decode(frame: bytes) -> Message:
    """Decode one complete frame. Raises DecodeError (a ProtocolError) on malformed input."""
    header, payload = split_frame(frame)
    cls = _lookup(header.message_id, header.message_type, payload)
    if cls is None:
        return UnknownMessage(header.message_id, header.message_type, payload)
    skip = 1 if header.message_id in (MessageId.ACTION, MessageId.NOTIFICATION) else 0
    name = cls.__name__
    reader = Reader(payload[skip:], name)
    try:
        message = cls.from_payload(reader, header.message_type)
    except DecodeError:
        raise
    except (ValueError, TypeError) as exc:  # e.g. an invalid enum inside a block
        raise DecodeError(f'{name}: {exc}') from exc
    reader.expect_end()
    return message


__all__ = [
    'ACTIONS', 'NOTIFICATIONS', 'Action', 'AuxInputStatus', 'BumpPositionSpeedAcceleration',
    'DelayMode', 'DeviceGuid', 'DeviceInfo', 'DevicePassword', 'ErrorStatus', 'GetDeviceGuid',
    'GetDeviceInfo', 'GetLedStatus', 'GetMotorInfo', 'GetNetworkInfo', 'GetSoftwareId',
    'GetTrajectoryData', 'LedStatus', 'MarkBeginPosition', 'MarkEndPosition', 'Message',
    'MotorCalibrated', 'MotorInfo', 'MotorInfoEntry', 'MotorPosition', 'MotorStatus',
    'MotorStatusEntry', 'NetworkInfo', 'Notification', 'PlaybackStatus',
    'RapidToFirstKeyFrame', 'ResetAxis', 'ResetDevice', 'SetPositionSpeedAcceleration',
    'SetupPlayback', 'SoftwareId', 'StartPlayback', 'StopPlayback', 'TakePicture',
    'UnknownMessage', 'UnsupportedMessage', 'UserPassword', 'check_motor_address', 'decode',
]
