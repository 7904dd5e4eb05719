"""Every byte example of the turret ICD as a test vector, plus the ICD's tables.

Byte examples (ICD sections 6.1.2-6.1.5, the pitch copies, 6.2.1, 6.3.1): all ten are
self-consistent (IEEE-754 big endian floats, UCHAR/CHAR type codes). They print eight
data bytes with zero padding although a UCHAR message needs only DLC 5; the codec sends
DLC = 4 + type size and accepts padded frames (`pad=True` reproduces the printed form).

Errors found in the ICD text and the rule followed instead:
* Data type table: codes 24..31 all printed "(0x17)"; the decimal codes (0x18..0x1F) are
  used, matching CANaerospace 1.7.
* LONG range printed "-2147483647 to 2147483648": used -2147483648..2147483647.
* ACHAR3 explained as "4 x ASCII character": 3 characters (name and Bits column say 3).
* UDEF printed 102-255 (0x66-0xFF) after RESVD 32-99: UDEF is 100-255, as CANaerospace
  1.7 and libcanaerospace have it (100/101 are user-defined, not unassigned); every
  code >= 32 is kept as raw bytes.
* "UCAR" for Stop actuators and the axis status bytes: read as UCHAR.
* Weapon identifiers (out of scope, never encoded): "Fuse control 1416 (0x57F)" where
  0x57F = 1407, and "Global shot counter 1418 (0x589)" where 0x589 = 1417 (the fuse state
  id). Neither is in the driver's table; both are ignored on receive.
* TIS/FPS/NIS responses put the result in the message code (NODATA), as CANaerospace
  1.7 (4.6, 4.7, 4.12) and libcanaerospace do; the client also accepts it as LONG data.
* Figure 4 (EED layout) was lost: error code bytes 4-5, operation id byte 6, location id
  byte 7 (CANaerospace 1.7).
* 7.5.1 Camera0 zoom position: on the file's last line (no trailing newline): 1342
  (0x53E), LONG, counts.
* Table of contents and headings repeat 6.1.1-6.1.5 and 6.7.1 for different entries.
"""

import math
import struct

import pytest

from canaero_turret_driver.protocol import (
    BY_ID,
    BY_KEY,
    CanAerospaceMessage,
    CodecError,
    DataType,
    LogicalChannel,
    channel_of,
)
from canaero_turret_driver.protocol.identifiers import MASTER_NODE_ID
from canaero_turret_driver.protocol.nodeservice import service_channel_ids

# (ICD section, identifier key, value in device units, the eight printed bytes)
ICD_EXAMPLES = [
    ("6.1.2 yaw position 20 deg", "yaw_position_setpoint", 20.0,
     "64 02 00 00 41 A0 00 00"),
    ("6.1.3 yaw velocity -10 deg/s", "yaw_velocity_setpoint", -10.0,
     "64 02 00 00 C1 20 00 00"),
    ("6.1.4 yaw relative 90 deg", "yaw_relative_setpoint", 90.0, "64 02 00 00 42 B4 00 00"),
    ("6.1.5 yaw actuator mode auto brake", "yaw_actuator_mode", 2, "64 0A 00 00 02 00 00 00"),
    ("6.1.1(p) pitch position 20 deg", "pitch_position_setpoint", 20.0,
     "64 02 00 00 41 A0 00 00"),
    ("6.1.2(p) pitch velocity -10 deg/s", "pitch_velocity_setpoint", -10.0,
     "64 02 00 00 C1 20 00 00"),
    ("6.1.3(p) pitch relative 90 deg", "pitch_relative_setpoint", 90.0,
     "64 02 00 00 42 B4 00 00"),
    ("6.1.4(p) pitch actuator mode auto brake", "pitch_actuator_mode", 2,
     "64 0A 00 00 02 00 00 00"),
    ("6.2.1 camera1 focus rotate", "camera1_focus", 1, "64 09 00 00 01 00 00 00"),
    ("6.3.1 open cover", "cover_control", 1, "64 0A 00 00 01 00 00 00"),
]


@pytest.mark.parametrize(("section", "key", "value", "printed"), ICD_EXAMPLES,
                         ids=[e[0] for e in ICD_EXAMPLES])
def test_icd_example_encodes_to_printed_bytes(section, key, value, printed):
    ident = BY_KEY[key]
    message = CanAerospaceMessage.build(ident.can_id, MASTER_NODE_ID, ident.data_type, value)
    expected = bytes.fromhex(printed)
    assert message.to_bytes(pad=True) == expected
    # Unpadded frame: header plus exactly the type's data bytes.
    size = {DataType.FLOAT: 4, DataType.UCHAR: 1, DataType.CHAR: 1}[ident.data_type]
    assert message.to_bytes() == expected[: 4 + size]


@pytest.mark.parametrize(("section", "key", "value", "printed"), ICD_EXAMPLES,
                         ids=[e[0] for e in ICD_EXAMPLES])
def test_icd_example_decodes_from_printed_bytes(section, key, value, printed):
    ident = BY_KEY[key]
    message = CanAerospaceMessage.from_frame(ident.can_id, bytes.fromhex(printed))
    assert message.node_id == MASTER_NODE_ID
    assert message.data_type == ident.data_type
    assert message.service_code == 0 and message.message_code == 0
    assert message.value == pytest.approx(value)


def test_example_units_convert_to_si():
    assert BY_KEY["yaw_position_setpoint"].to_si(20.0) == pytest.approx(math.radians(20))
    assert BY_KEY["yaw_velocity_setpoint"].from_si(math.radians(-10)) == pytest.approx(-10)


# Decimal/hex pairs exactly as printed in sections 6 and 7 (in-scope entries).
PRINTED_ID_PAIRS = [
    (300, 0x12C), (1300, 0x514), (1301, 0x515), (1302, 0x516), (1307, 0x51B),
    (1310, 0x51E), (1311, 0x51F), (1312, 0x520), (1317, 0x525), (1420, 0x58C),
    (1421, 0x58D), (1340, 0x53C), (1341, 0x53D), (1350, 0x546), (1351, 0x547),
    (1360, 0x550), (1361, 0x551), (1370, 0x55A), (1371, 0x55B), (1400, 0x578),
    (1403, 0x57B), (1414, 0x586), (1430, 0x596), (1432, 0x598), (1303, 0x517),
    (1304, 0x518), (1305, 0x519), (1308, 0x51C), (1461, 0x5B5), (1462, 0x5B6),
    (1464, 0x5B8), (1465, 0x5B9), (1466, 0x5BA), (1467, 0x5BB), (1313, 0x521),
    (1314, 0x522), (1315, 0x523), (1318, 0x526), (1481, 0x5C9), (1482, 0x5CA),
    (1484, 0x5CC), (1485, 0x5CD), (1486, 0x5CE), (1487, 0x5CF), (1404, 0x57C),
    (1405, 0x57D), (1413, 0x585), (1415, 0x587), (1431, 0x597), (1433, 0x599),
    (1435, 0x59B), (1801, 0x709), (1802, 0x70A), (1409, 0x581), (1507, 0x5E3),
    (1509, 0x5E5), (1800, 0x708), (1520, 0x5F0), (1521, 0x5F1), (1523, 0x5F3),
    (1524, 0x5F4), (1528, 0x5F8), (1342, 0x53E),
]


@pytest.mark.parametrize(("decimal", "hexadecimal"), PRINTED_ID_PAIRS)
def test_identifier_table_decimal_matches_hex(decimal, hexadecimal):
    assert decimal == hexadecimal
    assert decimal in BY_ID


def test_every_table_entry_was_cross_checked():
    checked = {d for d, _ in PRINTED_ID_PAIRS}
    assert set(BY_ID) == checked  # every id, the zoom position (7.5.1) included


def test_printed_weapon_pairs_disagree_and_are_not_in_table():
    """The two inconsistent pairs of the ICD are weapon entries: documented, not used."""
    assert 0x57F != 1416 and 0x589 != 1418
    for can_id in (1401, 1402, 1406, 1410, 1411, 1412, 1416, 1417, 1418):
        assert can_id not in BY_ID


DATA_TYPE_TABLE = [  # (name, printed decimal, printed hex or None when garbled)
    ("NODATA", 0, 0x00), ("ERROR", 1, 0x01), ("FLOAT", 2, 0x02), ("LONG", 3, 0x03),
    ("ULONG", 4, 0x04), ("BLONG", 5, 0x05), ("SHORT", 6, 0x06), ("USHORT", 7, 0x07),
    ("BSHORT", 8, 0x08), ("CHAR", 9, 0x09), ("UCHAR", 10, 0x0A), ("BCHAR", 11, 0x0B),
    ("SHORT2", 12, 0x0C), ("USHORT2", 13, 0x0D), ("BSHORT2", 14, 0x0E), ("CHAR4", 15, 0x0F),
    ("UCHAR4", 16, 0x10), ("BCHAR4", 17, 0x11), ("CHAR2", 18, 0x12), ("UCHAR2", 19, 0x13),
    ("BCHAR2", 20, 0x14), ("MEMID", 21, 0x15), ("CHKSUM", 22, 0x16), ("ACHAR", 23, 0x17),
    ("ACHAR2", 24, None), ("ACHAR4", 25, None), ("CHAR3", 26, None), ("UCHAR3", 27, None),
    ("BCHAR3", 28, None), ("ACHAR3", 29, None), ("DOUBLEH", 30, None), ("DOUBLEL", 31, None),
]


@pytest.mark.parametrize(("name", "decimal", "printed_hex"), DATA_TYPE_TABLE)
def test_data_type_codes(name, decimal, printed_hex):
    assert DataType[name] == decimal
    if printed_hex is not None:
        assert printed_hex == decimal


DATA_TYPE_SIZES = {
    "NODATA": 0, "ERROR": 4, "FLOAT": 4, "LONG": 4, "ULONG": 4, "BLONG": 4, "SHORT": 2,
    "USHORT": 2, "BSHORT": 2, "CHAR": 1, "UCHAR": 1, "BCHAR": 1, "SHORT2": 4, "USHORT2": 4,
    "BSHORT2": 4, "CHAR4": 4, "UCHAR4": 4, "BCHAR4": 4, "CHAR2": 2, "UCHAR2": 2, "BCHAR2": 2,
    "MEMID": 4, "CHKSUM": 4, "ACHAR": 1, "ACHAR2": 2, "ACHAR4": 4, "CHAR3": 3, "UCHAR3": 3,
    "BCHAR3": 3, "ACHAR3": 3, "DOUBLEH": 4, "DOUBLEL": 4,
}


@pytest.mark.parametrize(("name", "size"), DATA_TYPE_SIZES.items())
def test_data_type_sizes_follow_bits_column(name, size):
    from canaero_turret_driver.protocol.datatypes import payload_size

    assert payload_size(DataType[name]) == size


def test_long_range_is_twos_complement():
    from canaero_turret_driver.protocol import encode_value

    assert encode_value(DataType.LONG, -2147483648) == bytes.fromhex("80000000")
    assert encode_value(DataType.LONG, 2147483647) == bytes.fromhex("7FFFFFFF")
    with pytest.raises(CodecError):
        encode_value(DataType.LONG, 2147483648)


@pytest.mark.parametrize(("can_id", "channel"), [
    (0, LogicalChannel.EED), (127, LogicalChannel.EED), (128, LogicalChannel.NSH),
    (199, LogicalChannel.NSH), (200, LogicalChannel.UDH), (299, LogicalChannel.UDH),
    (300, LogicalChannel.NOD), (1799, LogicalChannel.NOD), (1800, LogicalChannel.UDL),
    (1899, LogicalChannel.UDL), (1900, LogicalChannel.DSD), (1999, LogicalChannel.DSD),
    (2000, LogicalChannel.NSL), (2031, LogicalChannel.NSL), (2032, None),
])
def test_logical_channel_ranges(can_id, channel):
    assert channel_of(can_id) is channel


@pytest.mark.parametrize(("channel", "request_id", "response_id"), [
    (0, 128, 129), (1, 130, 131), (34, 196, 197), (35, 198, 199),
    (100, 2000, 2001), (101, 2002, 2003), (114, 2028, 2029), (115, 2030, 2031),
])
def test_node_service_channel_table(channel, request_id, response_id):
    assert service_channel_ids(channel) == (request_id, response_id)


@pytest.mark.parametrize("channel", [-1, 36, 99, 116, 300])
def test_node_service_channel_out_of_range(channel):
    with pytest.raises(CodecError):
        service_channel_ids(channel)


def test_float_example_is_ieee754_single():
    assert struct.pack(">f", 20.0) == bytes.fromhex("41A00000")
