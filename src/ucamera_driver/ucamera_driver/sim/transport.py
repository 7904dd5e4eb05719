"""U-Camera simulator: faults on sent frames, the pty session and the simulator with its console."""

from __future__ import annotations

import logging
import random
import threading
import time
from dataclasses import dataclass, field

from gimbal_driver_common.sim_control import ControlError, SimControl
from gimbal_driver_common.sim_requests import LateReplies
from gimbal_driver_common.sim_server import PtySimServer

from ..protocol import (
    FrameParser,
    ProtocolError,
    decode_packet,
    expected_payload_length,
    mode_name,
)
from .handlers import REQUESTS
from .model import SimConfig, UCameraModel

LOG = logging.getLogger("ucamera_sim")


@dataclass
class Faults:
    """Fault switches applied to what the simulator sends."""

    corrupt_probability: float = 0.0
    drop_probability: float = 0.0
    corrupt_next: int = 0
    seed: int = 1234
    rng: random.Random = field(init=False)

    def __post_init__(self) -> None:
        self.rng = random.Random(self.seed)

    def apply(self, frame: bytes) -> bytes:
        if self.drop_probability and self.rng.random() < self.drop_probability:
            return b""
        corrupt = self.corrupt_next > 0 or (
            self.corrupt_probability and self.rng.random() < self.corrupt_probability
        )
        if corrupt:
            self.corrupt_next = max(0, self.corrupt_next - 1)
            data = bytearray(frame)
            index = self.rng.randrange(1, len(data))  # keep the sync byte
            data[index] ^= 1 << self.rng.randrange(8)
            return bytes(data)
        return frame


class UCameraSession:
    """One link's byte handling (the server makes one per pty generation). The answer to a
    delayed request (``delay``) waits in :attr:`late` until :meth:`poll` writes it, whole,
    between the periodic reports."""

    def __init__(self, sim: UCameraSim) -> None:
        self._sim = sim
        self._parser = FrameParser(expected_payload_length)
        self._next_report = 0.0
        self.late: LateReplies[bytes] = LateReplies()

    def on_bytes(self, data: bytes) -> bytes:
        out = bytearray()
        for frame in self._parser.feed(data):
            try:
                packet = decode_packet(frame)
            except ProtocolError as exc:
                self._sim.bad_packets += 1
                LOG.debug("ignored frame: %s", exc)
                continue
            answers = [self._sim.faults.apply(answer.encode())
                       for answer in self._sim.model.handle(packet)]
            seconds = self._sim.model.request_faults.delay_of(type(packet).__name__)
            if seconds and answers:
                self.late.hold(answers, seconds)
            else:
                out += b"".join(answers)
        self._sim.checksum_errors = self._parser.stats.checksum_errors
        return bytes(out)

    def poll(self) -> bytes:
        model = self._sim.model
        now = time.monotonic()
        model.step(now)
        if model.silent(now):  # a held answer waits for the gimbal to speak again
            return b""
        out = bytearray(b"".join(self.late.due(now)))
        if now < self._next_report:
            return bytes(out)
        period = 1.0 / max(1, model.telemetry_rate)
        self._next_report = max(self._next_report + period, now - period)
        for report in model.periodic_reports():
            out += self._sim.faults.apply(report.encode())
        return bytes(out)


class UCameraSim:
    """Model + pseudo-terminal server + fault injection."""

    def __init__(self, config: SimConfig | None = None, link_path: str | None = None) -> None:
        self.model = UCameraModel(config)
        self.faults = Faults()
        self.bad_packets = 0
        self.checksum_errors = 0
        self.server = PtySimServer(lambda: UCameraSession(self), link_path=link_path,
                                   poll_interval=0.002)
        self._noise_rate = 0.0
        self._controls: SimControl | None = None
        self._noise_thread: threading.Thread | None = None
        self._stop = threading.Event()

    @property
    def port_name(self) -> str:
        return self.server.port_name

    def start(self) -> UCameraSim:
        self.server.start()
        self._noise_thread = threading.Thread(target=self._noise_loop, daemon=True,
                                              name="ucamera-sim-noise")
        self._noise_thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self.server.stop()
        if self._noise_thread is not None:
            self._noise_thread.join(timeout=1.0)

    def __enter__(self) -> UCameraSim:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    # --- fault injection -------------------------------------------------
    def inject_noise(self, count: int, include_sync: bool = True) -> None:
        """Send ``count`` random bytes (optionally including false 0xCC syncs)."""
        data = bytearray(self.faults.rng.randrange(256) for _ in range(count))
        if include_sync and count >= 4:
            data[self.faults.rng.randrange(count - 3)] = 0xCC
        self.server.inject(bytes(data))

    def set_noise_rate(self, bytes_per_second: float) -> None:
        """Continuous background noise; 0 turns it off."""
        self._noise_rate = max(0.0, bytes_per_second)

    def set_silent(self, silent: bool) -> None:
        """Stop sending (and answering) while keeping the link up."""
        self.server.set_silent(silent)

    def corrupt(self, next_frames: int = 0, probability: float | None = None) -> None:
        """Flip one bit in the next ``next_frames`` frames and/or at random."""
        self.faults.corrupt_next += next_frames
        if probability is not None:
            self.faults.corrupt_probability = probability

    def drop_frames(self, probability: float) -> None:
        self.faults.drop_probability = probability

    def drop_link(self, offline_for: float = 0.0) -> None:
        """Destroy the pty (as an unplugged adapter); recreate it after ``offline_for`` s."""
        self.server.drop_link(offline_for)

    def _noise_loop(self) -> None:
        while not self._stop.wait(0.1):
            if self._noise_rate > 0:
                self.inject_noise(max(1, int(self._noise_rate * 0.1)))

    # --- control verbs (shared protocol + U-Camera's own) -----------------
    @property
    def controls(self) -> SimControl:
        if self._controls is None:
            control = SimControl(
                "ucamera_sim", self.state, links=[self.server],
                no_nack="UCSP has no acknowledge or negative acknowledge",
                no_fault="UCSP reports no fault register (and has no fault reset)",
                clear_device=self._clear_injected,
                axes=lambda: (self.model.pan, self.model.tilt),
                request_names=lambda: REQUESTS, request_faults=self.model.request_faults)
            control.add_verb("noise", lambda a: self.inject_noise(int(a[0]) if a else 64),
                             "noise [N] (random bytes with false 0xCC syncs)")
            control.add_verb("noise_rate", lambda a: self.set_noise_rate(float(a[0])),
                             "noise_rate BYTES_PER_S")
            control.add_verb("corrupt", lambda a: self.corrupt(int(a[0]) if a else 1),
                             "corrupt [N] (flip a bit in the next N frames)")
            control.add_verb("corrupt_rate", lambda a: self.corrupt(probability=float(a[0])),
                             "corrupt_rate P")
            control.add_verb("drop_rate", lambda a: self.drop_frames(float(a[0])),
                             "drop_rate P (lose sent frames)")
            control.add_verb("gnss", self._set_gnss,
                             "gnss LAT LON ALT: the on-board GPS position (deg, deg, m)")
            self._controls = control
        return self._controls

    def _set_gnss(self, args: list[str]) -> None:
        if len(args) != 3:
            raise ControlError("gnss LAT LON ALT")
        latitude, longitude, altitude = (float(a) for a in args)
        with self.model.lock:
            self.model.internal_position = (latitude, longitude, altitude)

    def command(self, line: str) -> str:
        """Run one control request (``help`` lists the verbs); return the answer line."""
        return self.controls.execute(line)

    def _clear_injected(self) -> None:
        self.set_noise_rate(0.0)
        self.faults.corrupt_next = 0
        self.faults.corrupt_probability = 0.0
        self.faults.drop_probability = 0.0

    def state(self) -> dict:
        """The ``state`` answer: axes in radians (device frame: pan positive clockwise)."""
        model = self.model
        with model.lock:
            return {
                "axes": {"pan": model.pan.snapshot(), "tilt": model.tilt.snapshot()},
                "mode": mode_name(model.mode), "zoom": model.zoom,
                "telemetry_rate": model.telemetry_rate, "silent": self.server.silent,
                "bad_packets": self.bad_packets, "checksum_errors": self.checksum_errors,
                "nv_saves": model.nv_saves, "ffc_saves": model.ffc_saves,
                "gps_feed": model.gps_feed.name.lower(),
                "vehicle_angles": model.vehicle_angles, "received": dict(model.received),
            }
