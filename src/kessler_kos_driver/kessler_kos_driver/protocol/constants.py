"""Numeric tables of the kOS network protocol (Feb 2022 third-party document).

Values checked against a second place in the document where one exists:
- message ids against the per-message tables and the byte examples (0x0B MotorInfo and 0x0F
  DeviceInfo in the Get examples, 0x80/0x1C in the SetPositionSpeedAcceleration examples,
  0x81/0x07 in the MotorPosition example);
- PlaybackStatus values 0..13 against both playback sequence tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

PROTOCOL_VERSION = 0x04
HEADER_SIZE = 6
DEFAULT_TCP_PORT = 5520
KEEPALIVE_DROP_S = 30.0        # device drops a silent TCP connection after this
KEEPALIVE_PERIOD_S = 10.0      # document: idle client sends (Get)NetworkInfo every 10 s
DISCOVERY_PERIOD_S = 5.0       # device sends NetworkInfo every 5 s while unconnected
MOTOR_ADDRESS_MIN = 1
MOTOR_ADDRESS_MAX = 10
ALL_MOTORS = 0
FIZ_FLAG = 0x80                # MotorInfo address high bit: focus/iris/zoom motor
UNCALIBRATED_TARGET = 25000.0  # +/- target used to drive uncalibrated motors


class MessageType(IntEnum):
    SET = 0
    GET = 1
    RESPONSE = 2
    RESPONSE_MORE = 0x82       # MotorInfo: more responses follow (example "82" byte)


class MessageId(IntEnum):
    NETWORK_INFO = 0x02
    LED_STATUS = 0x07
    MOTOR_INFO = 0x0B
    DEVICE_INFO = 0x0F
    USER_PASSWORD = 0x10
    DEVICE_PASSWORD = 0x11
    TRAJECTORY_DATA = 0x12
    DEVICE_GUID = 0x1F
    SOFTWARE_ID = 0x26
    ACTION = 0x80
    NOTIFICATION = 0x81


class ActionId(IntEnum):
    RESET_DEVICE = 0x01
    RESET_AXIS = 0x02
    MARK_BEGIN_POSITION = 0x03
    MARK_END_POSITION = 0x04
    START_PLAYBACK = 0x05
    STOP_PLAYBACK = 0x06
    RAPID_TO_FIRST_KEY_FRAME = 0x07
    TAKE_PICTURE = 0x09
    SETUP_PLAYBACK = 0x0F
    SET_POSITION_SPEED_ACCELERATION = 0x1C
    BUMP_POSITION_SPEED_ACCELERATION = 0x28


class NotificationId(IntEnum):
    MOTOR_STATUS = 0x01
    PLAYBACK_STATUS = 0x02
    ERROR_STATUS = 0x03
    MOTOR_POSITION = 0x07
    MOTOR_CALIBRATED = 0x11
    AUX_INPUT_STATUS = 0x15
    UNSUPPORTED_MESSAGE = 0xFF


class DeviceType(IntEnum):
    UNKNOWN = 0
    SECOND_SHOOTER_PLUS = 3
    SECOND_SHOOTER_PRO = 10
    CINESHOOTER = 11


class PlaybackMode(IntEnum):
    LIVE_MOTION = 0
    TIMELAPSE_CONTINUOUS = 1
    TIMELAPSE_SMS = 2


class PlaybackState(IntEnum):
    NO_MOVE = 0
    MOTORS_HOME = 1
    START_FORWARD = 2
    START_REVERSE = 3
    END_OF_MOVE = 4
    FULL_STOP = 5
    START_FRAME = 6
    SETUP_COMPLETED = 7
    DELAY_TIMER_STARTED = 8
    PRE_CAMERA_ROLL_STARTED = 9
    POST_CAMERA_ROLL_COMPLETED = 10
    PRE_MOVE_PHOTOS_STARTED = 11
    POST_MOVE_PHOTOS_COMPLETED = 12
    SMS_MOTORS_STOPPED = 13


class DelayMode(IntEnum):
    NONE = 0
    FOR_TIME = 1        # DelayInterval: seconds (Float32)
    UNTIL_DATE = 2      # DelayInterval: UnixTime (UInt32 in the same four bytes)


class Direction(IntEnum):
    """StartPlayback/SetupPlayback direction; the document says clients send 0."""

    FORWARD = 0


class LedState(IntEnum):
    OFF = 0
    ON = 1
    SLOW_BLINK = 2
    FAST_BLINK = 3


class BlockId(IntEnum):
    PLAYBACK = 1
    TIMELAPSE = 2
    AXIS = 5
    SEGMENT = 6


@dataclass(frozen=True)
class ErrorCodeInfo:
    code: int
    description: str
    axis_reset: bool          # the device resets (uncalibrates) the axis
    device_wide: bool         # (*) codes: followed by MotorAddress 0


ERROR_CODES: dict[int, ErrorCodeInfo] = {
    info.code: info
    for info in (
        ErrorCodeInfo(0, 'Error returning to first key frame', False, True),
        ErrorCodeInfo(1, 'Unable to write trajectory data to flash (obsolete)', False, True),
        ErrorCodeInfo(2, 'Unable to execute move', False, True),
        ErrorCodeInfo(3, 'Error in trajectory data', False, True),
        ErrorCodeInfo(4, 'Motor address is not valid', False, False),
        ErrorCodeInfo(6, 'No motors connected', False, True),
        ErrorCodeInfo(7, 'Unable to read trajectory data from flash (obsolete)', False, True),
        ErrorCodeInfo(10, 'Run away error detected, axis will be reset', True, False),
        ErrorCodeInfo(11, 'Motors not in PVT mode', False, False),
        ErrorCodeInfo(12, 'PVT quick stop', False, False),
        ErrorCodeInfo(13, 'PVT integrity counter error', False, False),
        ErrorCodeInfo(14, 'Motor calibration error, axis will be reset', True, False),
        ErrorCodeInfo(15, 'The Device is locked out, invalid password entered', False, False),
        ErrorCodeInfo(16, 'A fault condition was detected, axis will be reset', True, False),
        ErrorCodeInfo(17, 'Invalid move time', False, False),
        ErrorCodeInfo(19, 'External intervalometer has not been set up correctly', False, True),
        ErrorCodeInfo(20, 'No input configured for external intervalometer', False, True),
    )
}


class ErrorCode(IntEnum):
    RETURN_TO_FIRST_KEY_FRAME = 0
    EXECUTE_MOVE = 2
    TRAJECTORY_DATA = 3
    INVALID_MOTOR_ADDRESS = 4
    NO_MOTORS = 6
    RUN_AWAY = 10
    NOT_IN_PVT_MODE = 11
    PVT_QUICK_STOP = 12
    PVT_INTEGRITY = 13
    CALIBRATION = 14
    LOCKED_OUT = 15
    AXIS_FAULT = 16
    INVALID_MOVE_TIME = 17


def describe_error(code: int) -> str:
    info = ERROR_CODES.get(code)
    return info.description if info else f'Unknown kOS error code {code}'


@dataclass(frozen=True)
class AxisMaxima:
    """Documented action maxima (SetPositionSpeedAcceleration / Bump), rotations based."""

    speed: float          # rotations/s
    acceleration: float   # rotations/s^2


# Document: speed max 165 slider/pan, 65 tilt, 200 focus/zoom; acceleration 100 slider/pan,
# 50 tilt/focus/zoom. The MotorInfo example reports 166.7 and 200 for one motor, so the
# per-motor MotorInfo maxima are authoritative at run time and these are only defaults.
DOCUMENTED_MAXIMA: dict[str, AxisMaxima] = {
    'slider': AxisMaxima(165.0, 100.0),
    'pan': AxisMaxima(165.0, 100.0),
    'tilt': AxisMaxima(65.0, 50.0),
    'focus': AxisMaxima(200.0, 50.0),
    'zoom': AxisMaxima(200.0, 50.0),
}


# Document names of the PlaybackStatus values (published as PlaybackStatus.status_name).
PLAYBACK_STATE_NAMES: dict[int, str] = {
    PlaybackState.NO_MOVE: 'NoMove',
    PlaybackState.MOTORS_HOME: 'MotorsHome',
    PlaybackState.START_FORWARD: 'StartForward',
    PlaybackState.START_REVERSE: 'StartReverse',
    PlaybackState.END_OF_MOVE: 'EndOfMove',
    PlaybackState.FULL_STOP: 'FullStop',
    PlaybackState.START_FRAME: 'StartFrame',
    PlaybackState.SETUP_COMPLETED: 'SetupCompleted',
    PlaybackState.DELAY_TIMER_STARTED: 'DelayTimerStarted',
    PlaybackState.PRE_CAMERA_ROLL_STARTED: 'PreCameraRollStarted',
    PlaybackState.POST_CAMERA_ROLL_COMPLETED: 'PostCameraRollCompleted',
    PlaybackState.PRE_MOVE_PHOTOS_STARTED: 'PreMovePhotosStarted',
    PlaybackState.POST_MOVE_PHOTOS_COMPLETED: 'PostMovePhotosCompleted',
    PlaybackState.SMS_MOTORS_STOPPED: 'SMSMotorsStopped',
}

# Statuses during which the device owns the motors (a move is being executed).
PLAYBACK_RUNNING_STATES = frozenset({
    PlaybackState.START_FORWARD, PlaybackState.START_REVERSE, PlaybackState.END_OF_MOVE,
    PlaybackState.START_FRAME, PlaybackState.DELAY_TIMER_STARTED,
    PlaybackState.PRE_CAMERA_ROLL_STARTED, PlaybackState.POST_CAMERA_ROLL_COMPLETED,
    PlaybackState.PRE_MOVE_PHOTOS_STARTED, PlaybackState.POST_MOVE_PHOTOS_COMPLETED,
    PlaybackState.SMS_MOTORS_STOPPED,
})


def playback_state_name(status: int) -> str:
    return PLAYBACK_STATE_NAMES.get(status, f'Unknown({status})')
