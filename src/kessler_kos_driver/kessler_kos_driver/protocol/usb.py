"""kOS over USB HID: report framing (document "USB Notes"), pure Python.

The document's rules: every kOS message is preceded by the report ID byte 0x01 and the packet
is padded to 64 bytes with 0x00; on responses the first byte is stripped and the size field of
the kOS header says how many bytes to take from the packet; a six-byte keep-alive
(04 00 06 00 00 00) must be sent every 4 s; UserPassword and DevicePassword are not used.

Reconstruction decisions (the notes are four lines long):
- "padded to 64 bytes" counts the report ID: a report is 1 ID byte + 63 message bytes, the
  64-byte packet of a full-speed HID interrupt endpoint. The size is a parameter
  (`report_size`) in case a device declares 64 data bytes after the ID.
- The size field is the header's UInt16 MessageLength (the notes say "size byte": for every
  message that fits one packet its high byte is 0). A message longer than one report is
  carried on in the following reports (report ID + the next 63 bytes); the receiver takes
  MessageLength bytes across as many reports as needed and drops the padding of the last one.
  The notes do not say how long messages (TrajectoryData, long DeviceInfo) are split; this is
  the only reading that keeps the header's length meaningful.
- A report whose ID is not 0x01, or that starts no plausible kOS header while no message is
  pending, is dropped and counted (padding-only reports, other report IDs).
"""

from __future__ import annotations

import struct

from .constants import HEADER_SIZE, PROTOCOL_VERSION

REPORT_ID = 0x01
REPORT_SIZE = 64                     # bytes on the wire per report, the ID included
USB_KEEPALIVE_PERIOD_S = 4.0
# ProtocolVersion 4, MessageLength 6, MessageID 0, MessageType 0: a bare header.
USB_KEEPALIVE = bytes((0x04, 0x00, 0x06, 0x00, 0x00, 0x00))

_LENGTH = struct.Struct('>H')


def _check_report_size(report_size: int) -> int:
    if not isinstance(report_size, int) or not HEADER_SIZE + 1 <= report_size <= 4096:
        raise ValueError(f'report_size must be an integer in [{HEADER_SIZE + 1}, 4096] bytes '
                         f'(report ID included), got {report_size!r}')
    return report_size


def encode_reports(message: bytes, report_size: int = REPORT_SIZE) -> list[bytes]:
    """Split one encoded kOS message into zero-padded output reports led by the report ID."""
    chunk = _check_report_size(report_size) - 1
    data = bytes(message)
    reports = []
    for start in range(0, len(data), chunk):
        body = data[start:start + chunk]
        reports.append(bytes((REPORT_ID,)) + body + bytes(chunk - len(body)))
    return reports


class ReportReassembler:
    """Turns received reports back into the kOS byte stream (padding removed).

    Feed every report as read from the device (report ID first); the returned bytes go to a
    :class:`~kessler_kos_driver.protocol.framing.FrameParser`.
    """

    def __init__(self) -> None:
        self._owed = 0                 # bytes of the current message still in later reports
        self.dropped_reports = 0       # foreign report IDs, padding, no header where one was due

    def feed(self, report: bytes) -> bytes:
        data = bytes(report)
        if not data:
            return b''
        if data[0] != REPORT_ID:
            self.dropped_reports += 1
            return b''
        body = data[1:]
        if self._owed:
            take = min(self._owed, len(body))
            self._owed -= take
            return body[:take]
        if len(body) < HEADER_SIZE or body[0] != PROTOCOL_VERSION:
            self.dropped_reports += 1
            return b''
        length = _LENGTH.unpack_from(body, 1)[0]
        if length < HEADER_SIZE:
            self.dropped_reports += 1
            return b''
        take = min(length, len(body))
        self._owed = length - take
        return body[:take]

    def reset(self) -> None:
        self._owed = 0

    @property
    def pending(self) -> int:
        """Bytes of a started message still expected in following reports."""
        return self._owed
