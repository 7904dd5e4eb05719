"""Pure-Python codec for the Kessler kOS network protocol (no ROS imports)."""

from . import constants as _constants
from . import messages as _messages
from .bezier import fit_keyframes, position_at, segment_peak_rates
from .constants import *  # noqa: F403
from .errors import DecodeError, EncodeError, ProtocolError, TrajectoryError
from .framing import FrameParser, Header, encode_frame, split_frame, unpack_header
from .messages import *  # noqa: F403
from .messages import decode
from .trajectory import (
    AxisBlock,
    AxisLimits,
    PlaybackBlock,
    RawBlock,
    SegmentBlock,
    TimeLapseBlock,
    Trajectory,
    TrajectoryData,
    validate,
)
from .usb import (
    REPORT_ID,
    REPORT_SIZE,
    USB_KEEPALIVE,
    USB_KEEPALIVE_PERIOD_S,
    ReportReassembler,
    encode_reports,
)
from .wire import Reader, Writer, float32

__all__ = [
    'REPORT_ID',
    'REPORT_SIZE',
    'USB_KEEPALIVE',
    'USB_KEEPALIVE_PERIOD_S',
    'AxisBlock',
    'AxisLimits',
    'DecodeError',
    'EncodeError',
    'FrameParser',
    'Header',
    'PlaybackBlock',
    'ProtocolError',
    'RawBlock',
    'Reader',
    'ReportReassembler',
    'SegmentBlock',
    'TimeLapseBlock',
    'Trajectory',
    'TrajectoryData',
    'TrajectoryError',
    'Writer',
    'decode',
    'encode_frame',
    'encode_reports',
    'fit_keyframes',
    'float32',
    'position_at',
    'segment_peak_rates',
    'split_frame',
    'unpack_header',
    'validate',
]
__all__ += [n for n in dir(_constants) if n[:1].isupper()]
__all__ += list(_messages.__all__)
