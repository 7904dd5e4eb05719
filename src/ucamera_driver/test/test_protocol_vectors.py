"""Byte vectors for the UCSP codec.

Spec examples (manual chapter 5), all five tested here:

=========================  ==================  ========================================
example                    printed CK_A CK_B   verdict
=========================  ==================  ========================================
Save Configuration 5.5.1.1 0xD1 0x3E           consistent
Request Version 5.5.2.2    0xD6 0x4C           consistent
Request Frequency 5.5.2.4  0xD8 0x50           consistent
Save FFC 5.5.1.2           0xD1 0x3E           WRONG: copy of Save Configuration; the
                                               rule gives 0xD2 0x40 (id 0x02 differs)
Figure 5 test packet       0xFC 0x74           WRONG: the rule gives 0x05 0x7D; no variant
                                               (without sync, payload only) gives FC 74
=========================  ==================  ========================================

Rule followed: 8-bit Fletcher over every byte before the checksum, sync byte
included (text of 5.3: "involves all the packet bytes except for the checksum
bytes"), which the three consistent examples confirm. The payload-only reading
of the pseudo-code (N = payload length) would give 0x00 0x00 for every empty
packet and is refuted by all three.

Every other packet has no example in the text: its vector below was written by
hand from the payload tables (little endian, scale factors of 5.5) and its
checksum follows the rule above.
"""

import math

import pytest

from ucamera_driver.protocol import (
    AnglesReport,
    AntennaPositionReport,
    AntennaPositionRequest,
    ConfigureGpsFeed,
    Frame,
    FrameError,
    GimbalMode,
    GimbalType,
    GimbalTypeReport,
    GpsFeed,
    GpsPositionVelocities,
    GpsVelocities,
    IrPaletteReport,
    ModeReport,
    PayloadError,
    RangeError,
    RatesReport,
    SaveConfiguration,
    SaveFfc,
    SetAngles,
    SetAntennaPosition,
    SetIrPalette,
    SetMode,
    SetRates,
    SetTelemetryRate,
    SetZoom,
    SystemPositionReport,
    TelemetryRateReport,
    TelemetryRateRequest,
    UnknownPacketError,
    VehicleAngles,
    VehicleAngularVelocities,
    VersionReport,
    VersionRequest,
    ZoomReport,
    decode_frame,
    decode_packet,
    encode_frame,
    fletcher8,
)
from ucamera_driver.protocol.packets import ALL_PACKETS

r = math.radians


def hexbytes(text: str) -> bytes:
    return bytes.fromhex(text.replace("0x", "").replace(",", " "))


CONSISTENT_SPEC_EXAMPLES = [
    ("Save Configuration", "CC 04 01 00 D1 3E"),
    ("Request Gimbal Version", "CC 08 02 00 D6 4C"),
    ("Request Telemetry Data Frequency", "CC 08 04 00 D8 50"),
]

WRONG_SPEC_EXAMPLES = [
    # (name, bytes as printed, checksum the rule gives)
    ("Save FFC", "CC 04 02 00 D1 3E", (0xD2, 0x40)),
    ("Figure 5 test packet", "CC 01 02 09 01 02 03 04 05 06 07 08 09 FC 74", (0x05, 0x7D)),
]


@pytest.mark.parametrize(("name", "wire"), CONSISTENT_SPEC_EXAMPLES)
def test_consistent_spec_examples_decode(name: str, wire: str) -> None:
    data = hexbytes(wire)
    frame = decode_frame(data)
    assert frame.payload == b""
    assert encode_frame(frame.category, frame.packet_id) == data


@pytest.mark.parametrize(("name", "wire", "rule_checksum"), WRONG_SPEC_EXAMPLES)
def test_wrong_spec_examples_are_rejected(name: str, wire: str, rule_checksum) -> None:
    data = hexbytes(wire)
    with pytest.raises(FrameError, match="checksum"):
        decode_frame(data)
    assert fletcher8(data[:-2]) == rule_checksum
    fixed = data[:-2] + bytes(rule_checksum)
    assert decode_frame(fixed).payload == data[4:-2]


def test_pseudo_code_payload_only_reading_is_refuted() -> None:
    # Payload-only Fletcher of an empty packet is 0, 0: the examples print D1 3E etc.
    assert fletcher8(b"") == (0, 0)
    assert fletcher8(hexbytes("CC 04 01 00")) == (0xD1, 0x3E)


PACKET_VECTORS = [
    (SaveConfiguration(), "CC 04 01 00 D1 3E"),
    (SaveFfc(), "CC 04 02 00 D2 40"),
    (VersionReport(1234, -2, 0x01020304, 70000, 7),
     "CC 08 01 0E D2 04 FE FF 04 03 02 01 70 11 01 00 07 00 49 B0"),
    (VersionRequest(), "CC 08 02 00 D6 4C"),
    (TelemetryRateReport(50), "CC 08 03 02 32 00 0B 66"),
    (TelemetryRateRequest(), "CC 08 04 00 D8 50"),
    (SetTelemetryRate(200), "CC 08 05 02 C8 00 A3 9A"),
    (SetMode(GimbalMode.FFC_CALIBRATION), "CC 09 01 02 07 00 DF 0D"),
    (ModeReport(GimbalMode.RATES), "CC 09 02 02 01 00 DA 05"),
    (SetRates(r(10.0), r(-2.5)), "CC 09 03 06 E8 03 06 FF 00 00 CE 1F"),
    (RatesReport(r(-0.01), r(327.67)), "CC 09 04 06 FF FF FF 7F 00 00 5B 01"),
    (SetAngles(r(12.34), r(-45.0)), "CC 09 05 06 D2 04 6C EE 00 00 10 15"),
    (AnglesReport(r(-180.0), r(90.0)), "CC 09 06 06 B0 B9 28 23 00 00 95 69"),
    (SetZoom(1.0), "CC 0A 01 02 FF 3F 17 41"),
    (ZoomReport(8192 / 16383), "CC 0A 02 02 00 20 FA 28"),
    (GimbalTypeReport(GimbalType.IR), "CC 0A 03 02 01 00 DC 0E"),
    (GpsVelocities(1.5, -0.25, 12.0),
     "CC 0B 01 0C 96 00 00 00 E7 FF FF FF B0 04 00 00 12 09"),
    (GpsPositionVelocities(40.4168, -3.7038, 650.5, 0.0, 1.0, -1.0),
     "CC 0B 02 18 40 1D 17 18 50 D8 CA FD 90 95 E0 03 00 00 00 00 64 00 00 00 9C FF FF FF 71 87"),
    (SystemPositionReport(-33.8688, 151.2093, 12.34567),
     "CC 0B 03 0C 00 08 D0 EB 48 B5 20 5A 87 D6 12 00 8F 5D"),
    (ConfigureGpsFeed(GpsFeed.EXTERNAL), "CC 0B 04 01 01 DD 37"),
    (VehicleAngles(r(123.4567), r(-10.0), r(5.5)),
     "CC 0B 05 0C 87 D6 12 00 60 79 FE FF D8 D6 00 00 DB A1"),
    (VehicleAngularVelocities(r(1.0), r(-0.5), r(100.0)),
     "CC 0B 06 0C 10 27 00 00 78 EC FF FF 40 42 0F 00 13 CF"),
    (SetAntennaPosition(0.25, -0.1, -0.05), "CC 0B 07 06 FA 00 9C FF CE FF 46 A1"),
    (AntennaPositionRequest(), "CC 0B 08 00 DF 61"),
    (AntennaPositionReport(0.25, -0.1, -0.05), "CC 0B 09 06 FA 00 9C FF CE FF 48 B1"),
    (SetIrPalette(3), "CC 0C 01 02 03 00 DE 14"),
    (IrPaletteReport(3), "CC 0C 02 02 03 00 DF 18"),
]


def test_every_packet_has_a_vector() -> None:
    assert {type(packet) for packet, _ in PACKET_VECTORS} == set(ALL_PACKETS)


@pytest.mark.parametrize(("packet", "wire"), PACKET_VECTORS, ids=lambda v: type(v).__name__)
def test_packet_encodes_to_vector(packet, wire: str) -> None:
    assert packet.encode() == hexbytes(wire)


@pytest.mark.parametrize(("packet", "wire"), PACKET_VECTORS, ids=lambda v: type(v).__name__)
def test_vector_decodes_to_packet(packet, wire: str) -> None:
    decoded = decode_packet(decode_frame(hexbytes(wire)))
    assert type(decoded) is type(packet)
    for name, value in vars(packet).items():
        got = getattr(decoded, name)
        if isinstance(value, float):
            # one device count of the coarsest scale (deg*100 -> 1.7e-4 rad)
            assert got == pytest.approx(value, abs=2e-4), name
        else:
            assert got == value, name


def test_scaling_to_si() -> None:
    angles = decode_packet(decode_frame(hexbytes("CC 09 06 06 B0 B9 28 23 00 00 95 69")))
    assert angles.pan == pytest.approx(-math.pi)
    assert angles.tilt == pytest.approx(math.pi / 2)
    antenna = AntennaPositionReport.from_payload(hexbytes("E8 03 00 00 18 FC"))
    assert (antenna.x, antenna.y, antenna.z) == (1.0, 0.0, -1.0)
    position = SystemPositionReport.from_payload(hexbytes("00 08 D0 EB 48 B5 20 5A 87 D6 12 00"))
    assert position.latitude == pytest.approx(-33.8688)
    assert position.altitude == pytest.approx(12.34567)


def test_roll_field_is_always_zero_on_the_wire() -> None:
    assert SetAngles(r(1), r(2)).to_payload()[4:] == b"\x00\x00"
    # a device reporting a non-zero roll is accepted (roll ignored)
    report = AnglesReport.from_payload(hexbytes("64 00 C8 00 2C 01"))
    assert report.pan == pytest.approx(r(1.0))


@pytest.mark.parametrize(
    ("packet", "message"),
    [
        (SetAngles(r(327.68), 0.0), "pan"),
        (SetAngles(0.0, float("nan")), "tilt"),
        (SetRates(float("inf"), 0.0), "pan"),
        (SetZoom(1.01), "zoom"),
        (SetZoom(-0.001), "zoom"),
        (SetTelemetryRate(0), "telemetry rate"),
        (SetTelemetryRate(201), "telemetry rate"),
        (SetTelemetryRate(10.5), "whole number"),
        (SetMode(8), "not a U-Camera mode"),
        (SetMode(-1), "not a U-Camera mode"),
        (ConfigureGpsFeed(2), "GPS feed"),
        (GpsPositionVelocities(90.5, 0.0, 0.0), "latitude"),
        (GpsPositionVelocities(0.0, -181.0, 0.0), "longitude"),
        (GpsPositionVelocities(0.0, 0.0, 21475.0), "altitude"),
        (GpsVelocities(2.2e7, 0.0, 0.0), "velocity north"),
        (VehicleAngles(0.0, 2.0, 0.0), "pitch"),
        (SetAntennaPosition(32.768, 0.0, 0.0), "antenna x"),
        (SetIrPalette(65536), "IR palette"),
        (SetIrPalette(-1), "IR palette"),
    ],
)
def test_out_of_range_values_are_refused(packet, message: str) -> None:
    with pytest.raises(RangeError, match=message):
        packet.encode()


def test_wrong_payload_length_is_a_payload_error() -> None:
    with pytest.raises(PayloadError, match="needs 6 payload bytes, got 5"):
        decode_packet(Frame(0x09, 0x06, b"\x00" * 5))


def test_unknown_packet_is_reported_not_crashed() -> None:
    with pytest.raises(UnknownPacketError, match="category 0x0D id 0x01"):
        decode_packet(Frame(0x0D, 0x01, b""))


def test_unknown_mode_number_is_kept() -> None:
    report = ModeReport.from_payload(b"\x09\x00")
    assert report.mode == 9


def test_reported_zoom_out_of_range_is_refused() -> None:
    with pytest.raises(RangeError, match="zoom"):
        ZoomReport.from_payload(b"\x00\x40")  # 16384


def test_frame_errors() -> None:
    with pytest.raises(FrameError, match="shorter"):
        decode_frame(b"\xcc\x04")
    with pytest.raises(FrameError, match="sync"):
        decode_frame(b"\xcd\x04\x01\x00\xd1\x3e")
    with pytest.raises(FrameError, match="length byte"):
        decode_frame(b"\xcc\x04\x01\x01\xd1\x3e")
    with pytest.raises(FrameError, match="exceeds"):
        encode_frame(1, 1, bytes(256))
