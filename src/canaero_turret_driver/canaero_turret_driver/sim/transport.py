"""Turret simulator transports: a python-can bus runner, slcan on a pty, a socketcand bridge."""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Iterable

import can

from .model import TurretSimulator

LOG = logging.getLogger("canaero_turret_sim")


class BusSimRunner:
    """Runs a simulator on a python-can bus (virtual, socketcan, ...) in a thread."""

    def __init__(self, simulator: TurretSimulator, bus: can.BusABC,
                 period: float = 0.005) -> None:
        self.simulator = simulator
        self.bus = bus
        self.period = period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="canaero-sim-bus",
                                        daemon=True)

    def start(self) -> BusSimRunner:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _send(self, frames: Iterable[can.Message]) -> None:
        for frame in frames:
            try:
                self.bus.send(frame, timeout=0.1)
            except can.CanError as exc:
                LOG.warning("simulator could not send: %s", exc)

    def _run(self) -> None:
        next_poll = time.monotonic()
        while not self._stop.is_set():
            timeout = max(0.0, next_poll - time.monotonic())
            try:
                frame = self.bus.recv(timeout=timeout)
            except (can.CanError, OSError, ValueError) as exc:
                LOG.warning("simulator receive error: %s", exc)
                time.sleep(self.period)
                frame = None
            if frame is not None:
                self._send(self.simulator.handle(frame))
            now = time.monotonic()
            if now >= next_poll:
                next_poll = now + self.period
                self._send(self.simulator.poll(now))


def encode_slcan(frame: can.Message) -> bytes:
    """A frame as an slcan (Lawicel) ASCII record."""
    data = bytes(frame.data)
    if frame.is_extended_id:
        head = f"T{frame.arbitration_id:08X}{len(data)}"
    else:
        head = f"t{frame.arbitration_id:03X}{len(data)}"
    return (head + data.hex().upper()).encode("ascii") + b"\r"


class SlcanSession:
    """The adapter side of slcan: parses host commands, forwards frames both ways.

    Commands answered: O/L (open), C (close), S0-S8/sXXXX (bitrate), V/v/N (version,
    serial), F (status flags), Z/M/m/X/Q (accepted, no effect); tIIIL..., TIIIIIIIIL...
    (transmit). Unknown or malformed records get BEL (0x07), as a Lawicel adapter does.
    """

    MAX_LINE = 64

    def __init__(self, simulator: TurretSimulator) -> None:
        self.simulator = simulator
        self.is_open = False
        self._buffer = bytearray()
        self.rejected_records = 0

    def on_bytes(self, data: bytes) -> bytes:
        self._buffer.extend(data)
        out = bytearray()
        while True:
            end = self._buffer.find(b"\r")
            if end < 0:
                if len(self._buffer) > self.MAX_LINE:
                    self._buffer.clear()
                    self.rejected_records += 1
                    out += b"\a"
                break
            record = bytes(self._buffer[:end])
            del self._buffer[:end + 1]
            out += self._record(record.strip(b"\n"))
        return bytes(out)

    def _record(self, record: bytes) -> bytes:
        if not record:
            return b"\r"
        command, rest = chr(record[0]), record[1:]
        if command in "OL":
            self.is_open = True
            return b"\r"
        if command == "C":
            self.is_open = False
            return b"\r"
        if command in "SsZMmXQ":
            return b"\r"
        if command in "Vv":
            return b"V1013\r"
        if command == "N":
            return b"NSIM1\r"
        if command == "F":
            return b"F00\r"
        if command in "tT":
            frame = self._parse_frame(command, rest)
            if frame is None:
                self.rejected_records += 1
                return b"\a"
            replies = self.simulator.handle(frame) if self.is_open else []
            return b"z\r" + b"".join(encode_slcan(f) for f in replies)
        self.rejected_records += 1
        return b"\a"

    @staticmethod
    def _parse_frame(command: str, rest: bytes) -> can.Message | None:
        id_len = 3 if command == "t" else 8
        try:
            text = rest.decode("ascii")
            can_id = int(text[:id_len], 16)
            dlc = int(text[id_len])
            payload = bytes.fromhex(text[id_len + 1:id_len + 1 + 2 * dlc])
        except (ValueError, IndexError, UnicodeDecodeError):
            return None
        if dlc > 8 or len(payload) != dlc:
            return None
        return can.Message(arbitration_id=can_id, is_extended_id=command == "T", data=payload)

    def poll(self) -> bytes:
        frames = self.simulator.poll()
        if not self.is_open:
            return b""
        return b"".join(encode_slcan(frame) for frame in frames)


class SocketcandSession:
    """One TCP client of a socketcand-style bridge (the daemon's ASCII "rawmode" protocol).

    All sessions and the simulator share an in-process python-can `virtual` bus (`hub`),
    so the bridge behaves like a CAN bus: a frame a client sends reaches the simulator and
    every other client, and every broadcast reaches every client. python-can's
    `socketcand` interface connects with `channel=<name>, host=127.0.0.1, port=<port>`.

    Handshake: "< hi >" on connect, "< open <bus> >" -> "< ok >", "< rawmode >" -> "< ok >";
    then "< send <id> <len> <b0> ... >" from the client and "< frame <id> <sec.usec> <hex> >"
    to it. Frames start `RAW_SETTLE_S` after rawmode because python-can reads each
    handshake reply with a single recv() and must not get a frame glued to it.
    """

    RAW_SETTLE_S = 0.05
    MAX_RECORD = 200

    def __init__(self, hub_channel: str) -> None:
        self._bus = can.Bus(interface="virtual", channel=hub_channel)
        self._buffer = ""
        self._greeted = False
        self._opened = False
        self._raw_since: float | None = None
        self.rejected_records = 0

    def on_bytes(self, data: bytes) -> bytes:
        self._buffer += data.decode("ascii", "replace")
        out = []
        while True:
            start = self._buffer.find("<")
            end = self._buffer.find(">", start + 1) if start >= 0 else -1
            if start < 0 or end < 0:
                if start < 0 or len(self._buffer) - start > self.MAX_RECORD:
                    self._buffer = ""
                break
            record = self._buffer[start + 1:end].split()
            self._buffer = self._buffer[end + 1:]
            out.append(self._record(record))
        return "".join(out).encode("ascii")

    def _record(self, words: list[str]) -> str:
        if not words:
            return ""
        command = words[0]
        if command == "open" and len(words) == 2:
            self._opened = True
            return "< ok >"
        if command == "rawmode" and self._opened:
            self._raw_since = time.monotonic()
            return "< ok >"
        if command == "send" and self._raw_since is not None:
            frame = self._parse_send(words[1:])
            if frame is not None:
                with contextlib.suppress(can.CanError):
                    self._bus.send(frame)
                return ""
        self.rejected_records += 1
        return ""  # socketcand ignores what it does not understand

    @staticmethod
    def _parse_send(words: list[str]) -> can.Message | None:
        try:
            can_id, length = int(words[0], 16), int(words[1], 16)
            data = bytes(int(word, 16) for word in words[2:2 + length])
        except (ValueError, IndexError):
            return None
        if length > 8 or len(data) != length or can_id > 0x1FFFFFFF:
            return None
        return can.Message(arbitration_id=can_id, is_extended_id=len(words[0]) > 3,
                           data=data)

    def poll(self) -> bytes:
        if not self._greeted:
            self._greeted = True
            return b"< hi >"
        frames = []
        while True:
            frame = self._bus.recv(timeout=0)
            if frame is None:
                break
            frames.append(frame)
        if self._raw_since is None or time.monotonic() - self._raw_since < self.RAW_SETTLE_S:
            return b""
        return "".join(encode_socketcand(frame) for frame in frames).encode("ascii")

    def on_disconnect(self) -> None:
        self._bus.shutdown()


def encode_socketcand(frame: can.Message) -> str:
    can_id = f"{frame.arbitration_id:08X}" if frame.is_extended_id else \
        f"{frame.arbitration_id:03X}"
    stamp = frame.timestamp or time.time()
    return f"< frame {can_id} {stamp:.6f} {bytes(frame.data).hex().upper()} >"
