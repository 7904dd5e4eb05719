"""Emergency Event Data (EED, ICD 4.3): CAN ids 0..127, data type ERROR.

The ICD's Figure 4 (the byte layout) was lost in the OCR; only the sentence remains:
"information about the location within the unit at which the error occurred, the
offending operation and the error code". Reconstructed from the CANaerospace 1.7
definition that this ICD copies: data bytes 4-5 error code (16 bit, big endian), byte 6
operation id, byte 7 location id; the header's service and message codes are kept as
sent. The driver reports all three numbers verbatim (the ICD defines no code list).
"""

from __future__ import annotations

from dataclasses import dataclass

from .datatypes import DataType
from .errors import CodecError
from .message import CanAerospaceMessage, LogicalChannel


@dataclass(frozen=True)
class EmergencyEvent:
    node_id: int
    can_id: int
    error_code: int
    operation_id: int
    location_id: int
    service_code: int = 0
    message_code: int = 0

    def describe(self) -> str:
        return (f"EED from node {self.node_id} (id {self.can_id}): error 0x{self.error_code:04X}"
                f" operation {self.operation_id} location {self.location_id}")


def is_eed(can_id: int) -> bool:
    return LogicalChannel.EED.first_id <= can_id <= LogicalChannel.EED.last_id


def decode_eed(message: CanAerospaceMessage) -> EmergencyEvent:
    """Decode an EED message; CodecError if it is not one."""
    if not is_eed(message.can_id):
        raise CodecError(f"CAN id {message.can_id} is not in the EED range 0..127")
    if message.data_type != DataType.ERROR:
        raise CodecError(f"EED frame with data type {message.type_name}, expected ERROR")
    value = message.value
    if not (isinstance(value, tuple) and len(value) == 3
            and all(isinstance(v, int) for v in value)):
        raise CodecError(f"EED frame carries {value!r}, not (error, operation, location)")
    error_code, operation_id, location_id = value
    return EmergencyEvent(message.node_id, message.can_id, error_code, operation_id,
                          location_id, message.service_code, message.message_code)


def build_eed(can_id: int, node_id: int, error_code: int, operation_id: int, location_id: int,
              message_code: int = 0) -> CanAerospaceMessage:
    if not is_eed(can_id):
        raise CodecError(f"CAN id {can_id} is not in the EED range 0..127")
    return CanAerospaceMessage.build(can_id, node_id, DataType.ERROR,
                                     (error_code, operation_id, location_id),
                                     message_code=message_code)
