"""Node service protocol (ICD section 5): channels, requests and responses.

Channels: high priority channel n (0..35) uses request id 128 + 2n and response id
129 + 2n; low priority channel n (100..115) uses 2000 + 2(n - 100) and the next id.
Checked against both tables in 5.0 (channel 35 = 198/199, channel 115 = 2030/2031).
The node-id in a request is the *addressed* node (0 = all nodes) and the response
carries the same node-id. A response is due within 100 ms.

Result codes. The ICD tables for TIS, FPS and NIS put the result into the response's
*message code* with data type NODATA ("0 = OK, -6 = out of range", "-3 = invalid security
code"), and so do the published CANaerospace 1.7 standard (4.6 TIS, 4.7 FPS, 4.12 NIS)
and libcanaerospace; DDS/DUS carry theirs as a LONG in the data bytes. `response_status`
accepts both forms for every service: LONG data when present (a node that answers a TIS
that way is understood too), else the message code read as a signed byte. The simulator
answers TIS/FPS/NIS in the NODATA form.

DDS/DUS reconstruction: the start request's message code holds the number of data
messages n (1..255, "1-1020 bytes, specified by the message number field"); the
checksum is the sum of all data bytes modulo 2**32 (the ICD: "a checksum calculated
from summing up all received data") and its response carries the last data message's
number. The ICD does not say whether data messages count from 0 or from 1: both are
supported (`first_number`). Default 0, after the second witness: libcanaerospace
(P. Kirienko, 2013, the public CANaerospace C implementation) numbers them 0..n-1 and
puts n-1 in the checksum response.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import IntEnum

from .datatypes import DataType
from .errors import CodecError
from .message import CanAerospaceMessage

SERVICE_RESPONSE_TIMEOUT_S = 0.1
MAX_BLOCK_BYTES = 1020
BROADCAST_NODE_ID = 0
NIS_MIN_NODE_ID = 1
NIS_MAX_NODE_ID = 199
DEFAULT_FIRST_NUMBER = 0  # DDS/DUS data messages count from 0 (see module notes)
FIRST_NUMBERS = (0, 1)


class ServiceCode(IntEnum):
    IDS = 0
    NSS = 1
    DDS = 2
    DUS = 3
    SCS = 4
    TIS = 5
    FPS = 6
    STS = 7
    FSS = 8
    TCS = 9
    BSS = 10
    NIS = 11
    MIS = 12
    MCS = 13
    CSS = 14
    DSS = 15


NO_RESPONSE_SERVICES = frozenset({ServiceCode.NSS, ServiceCode.STS})


class ServiceStatus(IntEnum):
    """Result values used by the services of this ICD."""

    XON = 1
    OK = 0  # also XOFF for DDS flow control
    ABORT = -1
    INVALID = -2
    INVALID_SECURITY_CODE = -3
    OUT_OF_RANGE = -6


def status_text(service: int, status: int) -> str:
    """Human text for a service result."""
    if service == ServiceCode.DDS and status == 0:
        return "XOFF"
    if service == ServiceCode.DDS and status == 1:
        return "XON"
    texts = {0: "OK", -1: "ABORT", -2: "INVALID", -3: "invalid security code",
             -6: "value out of range"}
    return texts.get(status, f"status {status}")


def service_channel_ids(channel: int) -> tuple[int, int]:
    """(request id, response id) of a node service channel."""
    if isinstance(channel, bool) or not isinstance(channel, int):
        raise CodecError(f"service channel must be an integer, got {channel!r}")
    if 0 <= channel <= 35:
        request = 128 + 2 * channel
    elif 100 <= channel <= 115:
        request = 2000 + 2 * (channel - 100)
    else:
        raise CodecError(f"service channel {channel} does not exist (0..35 or 100..115)")
    return request, request + 1


def service_channel_of(can_id: int) -> tuple[int, bool] | None:
    """(channel, is_request) for a node service id, None for any other id."""
    if 128 <= can_id <= 199:
        return (can_id - 128) // 2, can_id % 2 == 0
    if 2000 <= can_id <= 2031:
        return 100 + (can_id - 2000) // 2, can_id % 2 == 0
    return None


def is_response_to(request: CanAerospaceMessage, response: CanAerospaceMessage) -> bool:
    """Does `response` answer `request` (next id, same node, same service)?"""
    return (
        response.can_id == request.can_id + 1
        and response.service_code == request.service_code
        and (request.node_id == BROADCAST_NODE_ID or response.node_id == request.node_id)
    )


def _request(node_id: int, service: ServiceCode, data_type: DataType, value: object,
             message_code: int, channel: int) -> CanAerospaceMessage:
    request_id, _ = service_channel_ids(channel)
    return CanAerospaceMessage.build(request_id, node_id, data_type, value, int(service),
                                     message_code)


def _response(node_id: int, service: ServiceCode, data_type: DataType, value: object,
              message_code: int, channel: int) -> CanAerospaceMessage:
    _, response_id = service_channel_ids(channel)
    return CanAerospaceMessage.build(response_id, node_id, data_type, value, int(service),
                                     message_code)


def response_status(response: CanAerospaceMessage) -> int:
    """The result of a TIS/FPS/NIS/DDS/DUS response (see module notes)."""
    if response.data_type == DataType.LONG:
        value = response.value
        if isinstance(value, bool) or not isinstance(value, int):
            raise CodecError(f"LONG response carries {value!r}, not an integer")
        return value
    code = response.message_code
    return code - 256 if code >= 128 else code


def signed_code(status: int) -> int:
    """A status -128..127 as the unsigned message-code byte."""
    if not -128 <= status <= 127:
        raise CodecError(f"status {status} does not fit a message code")
    return status % 256


# --- IDS ------------------------------------------------------------------------------

@dataclass(frozen=True)
class IdentificationInfo:
    """IDS response data (UCHAR4)."""

    hardware_revision: int
    software_revision: int
    identifier_distribution: int  # 0 = CANaerospace standard
    header_type: int  # 0 = CANaerospace standard header


def ids_request(node_id: int, channel: int = 0, message_code: int = 0) -> CanAerospaceMessage:
    return _request(node_id, ServiceCode.IDS, DataType.NODATA, None, message_code, channel)


def ids_response(node_id: int, info: IdentificationInfo, channel: int = 0,
                 message_code: int = 0) -> CanAerospaceMessage:
    value = (info.hardware_revision, info.software_revision, info.identifier_distribution,
             info.header_type)
    return _response(node_id, ServiceCode.IDS, DataType.UCHAR4, value, message_code, channel)


def parse_ids_response(response: CanAerospaceMessage) -> IdentificationInfo:
    if response.service_code != ServiceCode.IDS:
        raise CodecError(f"not an IDS response (service code {response.service_code})")
    if response.data_type != DataType.UCHAR4:
        raise CodecError(f"IDS response must be UCHAR4, got {response.type_name}")
    value = response.value
    if not (isinstance(value, tuple) and len(value) == 4
            and all(isinstance(v, int) for v in value)):
        raise CodecError(f"IDS response carries {value!r}, not four bytes")
    hardware, software, distribution, header = value
    return IdentificationInfo(hardware, software, distribution, header)


# --- TIS ------------------------------------------------------------------------------

def tis_request(node_id: int, can_id: int, interval_ms: int,
                channel: int = 0) -> CanAerospaceMessage:
    """Set the transmission interval of `can_id` (SHORT2: id, interval in ms)."""
    if not 0 <= can_id <= 0x7FF:
        raise CodecError(f"TIS: CAN id {can_id} is not an 11-bit identifier")
    if not 0 <= interval_ms <= 32767:
        raise CodecError(f"TIS: interval {interval_ms} ms is outside 0..32767")
    return _request(node_id, ServiceCode.TIS, DataType.SHORT2, (can_id, interval_ms), 0,
                    channel)


def tis_response(node_id: int, status: int, channel: int = 0) -> CanAerospaceMessage:
    return _response(node_id, ServiceCode.TIS, DataType.NODATA, None, signed_code(status),
                     channel)


# --- FPS ------------------------------------------------------------------------------

def fps_request(node_id: int, security_code: int, channel: int = 0) -> CanAerospaceMessage:
    """Store configuration in non-volatile memory; the security code is the message code."""
    return _request(node_id, ServiceCode.FPS, DataType.NODATA, None, security_code, channel)


def fps_response(node_id: int, status: int, channel: int = 0) -> CanAerospaceMessage:
    return _response(node_id, ServiceCode.FPS, DataType.NODATA, None, signed_code(status),
                     channel)


# --- NIS ------------------------------------------------------------------------------

def nis_request(node_id: int, new_node_id: int, channel: int = 0) -> CanAerospaceMessage:
    """Give the addressed node a new node-id (ICD: 1 <= ID <= 199)."""
    if not NIS_MIN_NODE_ID <= new_node_id <= NIS_MAX_NODE_ID:
        raise CodecError(f"NIS: new node-id {new_node_id} is outside 1..199")
    if node_id == BROADCAST_NODE_ID:
        raise CodecError("NIS must address one node, not all (node-id 0)")
    return _request(node_id, ServiceCode.NIS, DataType.NODATA, None, new_node_id, channel)


def nis_response(node_id: int, status: int, channel: int = 0) -> CanAerospaceMessage:
    return _response(node_id, ServiceCode.NIS, DataType.NODATA, None, signed_code(status),
                     channel)


# --- DDS / DUS ------------------------------------------------------------------------

def block_checksum(data: bytes) -> int:
    return sum(data) % 2**32


def split_block(data: bytes) -> list[bytes]:
    """Split a 1..1020 byte block into data-message chunks of up to 4 bytes."""
    if not 1 <= len(data) <= MAX_BLOCK_BYTES:
        raise CodecError(f"a block must be 1..{MAX_BLOCK_BYTES} bytes, got {len(data)}")
    return [data[index:index + 4] for index in range(0, len(data), 4)]


_CHUNK_TYPES = {1: DataType.UCHAR, 2: DataType.UCHAR2, 3: DataType.UCHAR3,
                4: DataType.UCHAR4}


def chunk_message(can_id: int, node_id: int, service: ServiceCode, number: int,
                  chunk: bytes) -> CanAerospaceMessage:
    """A DDS/DUS data message numbered `number` carrying 1..4 bytes."""
    if not 1 <= len(chunk) <= 4:
        raise CodecError("a data message carries 1..4 bytes")
    value: object = chunk[0] if len(chunk) == 1 else tuple(chunk)
    return CanAerospaceMessage.build(can_id, node_id, _CHUNK_TYPES[len(chunk)], value,
                                     int(service), number)


def data_numbers(message_count: int, first_number: int = DEFAULT_FIRST_NUMBER) -> range:
    """Message codes of the data messages of an n-message transfer, in order."""
    if first_number not in FIRST_NUMBERS:
        raise CodecError(f"data messages count from 0 or 1, not {first_number}")
    return range(first_number, first_number + message_count)


def transfer_messages(can_id: int, node_id: int, service: ServiceCode, data: bytes,
                      first_number: int = DEFAULT_FIRST_NUMBER) -> list[CanAerospaceMessage]:
    """A 1..1020 byte block as numbered DDS/DUS data messages."""
    chunks = split_block(data)
    return [chunk_message(can_id, node_id, service, number, chunk)
            for number, chunk in zip(data_numbers(len(chunks), first_number), chunks,
                                     strict=True)]


def start_transfer_request(node_id: int, service: ServiceCode, memory_id: int,
                           message_count: int, channel: int = 0) -> CanAerospaceMessage:
    """DDS or DUS start request: MEMID data, number of data messages as message code."""
    if service not in (ServiceCode.DDS, ServiceCode.DUS):
        raise CodecError("only DDS and DUS transfer blocks")
    if not 1 <= message_count <= 255:
        raise CodecError(f"a transfer has 1..255 data messages, got {message_count}")
    return _request(node_id, service, DataType.MEMID, memory_id, message_count, channel)


def long_response(node_id: int, service: ServiceCode, status: int, message_code: int,
                  channel: int = 0) -> CanAerospaceMessage:
    return _response(node_id, service, DataType.LONG, status, message_code, channel)


def checksum_response(node_id: int, service: ServiceCode, checksum: int, last_number: int,
                      channel: int = 0) -> CanAerospaceMessage:
    return _response(node_id, service, DataType.CHKSUM, checksum, last_number, channel)
