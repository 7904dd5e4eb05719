"""Pure-Python CANaerospace codec for the turret ICD (no ROS imports)."""

from .datatypes import DataType, decode_value, encode_value, join_double, split_double
from .eed import EmergencyEvent, build_eed, decode_eed, is_eed
from .errors import CodecError
from .identifiers import (
    BY_ID,
    BY_KEY,
    IDENTIFIERS,
    ActuatorMode,
    AxisStatus,
    CoverState,
    Direction,
    Identifier,
    TargetState,
    identifier_table,
)
from .message import CanAerospaceMessage, LogicalChannel, channel_of
from .nodeservice import IdentificationInfo, ServiceCode, ServiceStatus
from .sequencing import MessageCodeCounter, MessageCodeTracker, SequenceEvent

__all__ = [
    "BY_ID",
    "BY_KEY",
    "IDENTIFIERS",
    "ActuatorMode",
    "AxisStatus",
    "CanAerospaceMessage",
    "CodecError",
    "CoverState",
    "DataType",
    "Direction",
    "EmergencyEvent",
    "IdentificationInfo",
    "Identifier",
    "LogicalChannel",
    "MessageCodeCounter",
    "MessageCodeTracker",
    "SequenceEvent",
    "ServiceCode",
    "ServiceStatus",
    "TargetState",
    "build_eed",
    "channel_of",
    "decode_eed",
    "decode_value",
    "encode_value",
    "identifier_table",
    "is_eed",
    "join_double",
    "split_double",
]
