"""U-Camera simulator: speaks UCSP on a pseudo-terminal (``ucamera_sim``).

The device model follows chapter 4 and 5 of the user manual:

* power-up: INIT mode, points to pan 0 / tilt 0, then ANGLES mode (4.1);
* ANGLES slews to the commanded angles, RATES integrates the commanded rates,
  STOW goes to pan 0 / tilt +90, PILOT to pan 0 / tilt 0 (4.2);
* GYRO/FULL AUTOALIGN point to 0/0, hold still for a while, then switch to
  ANGLES (4.6); FFC CALIBRATION (IR gimbals only) points to pan 0 / tilt 90,
  calibrates and switches to ANGLES (4.7). After these the angles target is the
  last commanded angles;
* Set Angles / Set Rates take effect only in their own mode (5.5.3.3, 5.5.3.5);
* every periodic report (reconstructed 5.6, ``PERIODIC_REPORTS``) is sent at
  the telemetry rate (1..200 Hz); requests are answered before the next reports;
* Save Configuration makes the gimbal silent and deaf for ``save_pause`` s
  (5.5.1.1) and stores telemetry rate, antenna position, GPS feed and palette
  (``nv``); Save FFC is counted (IR only).

Motion: each axis runs on the shared trapezoidal model
(``gimbal_driver_common.sim_motion``), accelerating at ``acceleration`` up to ``max_rate``,
and stops at its mechanical limits (pan +-180 deg, tilt -90..+90 deg: the manual gives no
figures, these are simulator assumptions, see the README).

Faults (API, CLI flags, and the shared control verbs of
``gimbal_driver_common.sim_control`` on stdin and the TCP console): garbage/noise bytes,
silence, corrupted bytes in outgoing frames, dropped outgoing frames, link drop (pty
destroyed and recreated behind the same path). UCSP has no NACK and no fault register:
``nack`` and ``fault`` answer why.
"""

from __future__ import annotations

import argparse
import logging
import math
import random
import sys
import threading
import time
from dataclasses import dataclass, field

from gimbal_driver_common.sim_control import ControlError, SimControl, run_simulator
from gimbal_driver_common.sim_motion import AxisMotion
from gimbal_driver_common.sim_server import PtySimServer

from .protocol import (
    AnglesReport,
    AntennaPositionReport,
    AntennaPositionRequest,
    ConfigureGpsFeed,
    FrameParser,
    GimbalMode,
    GimbalType,
    GimbalTypeReport,
    GpsFeed,
    GpsPositionVelocities,
    GpsVelocities,
    IrPaletteReport,
    ModeReport,
    Packet,
    ProtocolError,
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
    VehicleAngles,
    VehicleAngularVelocities,
    VersionReport,
    VersionRequest,
    ZoomReport,
    decode_packet,
    expected_payload_length,
    mode_name,
)

LOG = logging.getLogger("ucamera_sim")

PAN_LIMITS = (-math.pi, math.pi)
TILT_LIMITS = (-math.pi / 2, math.pi / 2)
STOW_POSITION = (0.0, math.pi / 2)  # 4.2: tilt +90, pan 0
PILOT_POSITION = (0.0, 0.0)
FFC_POSITION = (0.0, math.pi / 2)  # 4.7
AUTOMATIC_MODES = {GimbalMode.INIT, GimbalMode.GYRO_AUTOALIGN, GimbalMode.FULL_AUTOALIGN,
                   GimbalMode.FFC_CALIBRATION}


@dataclass
class SimConfig:
    """Tunable behaviour; durations are short so tests stay fast."""

    gimbal_type: GimbalType = GimbalType.IR
    telemetry_rate: int = 50
    max_rate: float = math.radians(60.0)  # rad/s
    acceleration: float = math.radians(240.0)  # rad/s^2
    zoom_speed: float = 1.0 / 3.0  # fraction per second (full range in 3 s)
    init_time: float = 0.5
    autoalign_time: float = 2.0
    ffc_time: float = 1.0
    save_pause: float = 1.0
    latitude: float = 40.4168
    longitude: float = -3.7038
    altitude: float = 650.0
    version: VersionReport = field(
        default_factory=lambda: VersionReport(1201, 2304, 30105, 30102, 7)
    )


class UCameraModel:
    """Device state and behaviour, independent of the link (survives link drops)."""

    def __init__(self, config: SimConfig | None = None, clock=time.monotonic) -> None:
        self.config = config or SimConfig()
        self._clock = clock
        self.lock = threading.RLock()
        cfg = self.config
        self.pan = AxisMotion(cfg.max_rate, cfg.acceleration, min_position=PAN_LIMITS[0],
                              max_position=PAN_LIMITS[1])
        self.tilt = AxisMotion(cfg.max_rate, cfg.acceleration, min_position=TILT_LIMITS[0],
                               max_position=TILT_LIMITS[1])
        self.mode = GimbalMode.INIT
        self.mode_since = clock()
        self.angles_target = (0.0, 0.0)
        self.commanded_angles = (0.0, 0.0)
        self.commanded_rates = (0.0, 0.0)
        self.zoom = 0.0
        self.zoom_target = 0.0
        self.telemetry_rate = self.config.telemetry_rate
        self.ir_palette = 0
        self.gps_feed = GpsFeed.INTERNAL
        self.antenna = (0.0, 0.0, 0.0)
        self.external_position: tuple[float, float, float] | None = None
        self.external_velocity: tuple[float, float, float] | None = None
        self.vehicle_angles: tuple[float, float, float] | None = None
        #: the on-board GPS position (deg, deg, m; the `gnss` verb moves it)
        self.internal_position = (self.config.latitude, self.config.longitude,
                                  self.config.altitude)
        self.vehicle_rates: tuple[float, float, float] | None = None
        self.busy_until = 0.0  # NV write in progress: no telemetry, commands ignored
        self.nv_saves = 0
        self.ffc_saves = 0
        self.nv: dict[str, object] = {}
        self.received: dict[str, int] = {}
        self.ignored: dict[str, int] = {}
        self._last_step = clock()

    # --- commands --------------------------------------------------------
    def handle(self, packet: Packet) -> list[Packet]:
        """Apply one received packet; return the immediate answers."""
        now = self._clock()
        with self.lock:
            name = type(packet).__name__
            if now < self.busy_until:
                self.ignored[name] = self.ignored.get(name, 0) + 1
                return []
            self.received[name] = self.received.get(name, 0) + 1
            answers: list[Packet] = []
            if isinstance(packet, SetMode):
                if packet.mode in set(GimbalMode):
                    self._set_mode(GimbalMode(packet.mode), now)
                else:
                    self.ignored[name] = self.ignored.get(name, 0) + 1
            elif isinstance(packet, SetAngles):
                self.commanded_angles = (packet.pan, packet.tilt)
                if self.mode == GimbalMode.ANGLES:
                    self.angles_target = self.commanded_angles
            elif isinstance(packet, SetRates):
                if self.mode == GimbalMode.RATES:
                    self.commanded_rates = (packet.pan, packet.tilt)
            elif isinstance(packet, SetZoom):
                self.zoom_target = packet.level
            elif isinstance(packet, SetTelemetryRate):
                if 1 <= packet.rate_hz <= 200:  # 5.5.2.5: 1 to 200 Hz
                    self.telemetry_rate = int(packet.rate_hz)
                else:
                    self.ignored[name] = self.ignored.get(name, 0) + 1
            elif isinstance(packet, TelemetryRateRequest):
                answers.append(TelemetryRateReport(self.telemetry_rate))
            elif isinstance(packet, VersionRequest):
                answers.append(self.config.version)
            elif isinstance(packet, SetAntennaPosition):
                self.antenna = (packet.x, packet.y, packet.z)
            elif isinstance(packet, AntennaPositionRequest):
                answers.append(AntennaPositionReport(*self.antenna))
            elif isinstance(packet, ConfigureGpsFeed):
                self.gps_feed = GpsFeed(packet.source)
            elif isinstance(packet, GpsPositionVelocities):
                self.external_position = (packet.latitude, packet.longitude, packet.altitude)
                self.external_velocity = (packet.north, packet.east, packet.down)
            elif isinstance(packet, GpsVelocities):
                self.external_velocity = (packet.north, packet.east, packet.down)
            elif isinstance(packet, VehicleAngles):
                self.vehicle_angles = (packet.yaw, packet.pitch, packet.roll)
            elif isinstance(packet, VehicleAngularVelocities):
                self.vehicle_rates = (packet.yaw_rate, packet.pitch_rate, packet.roll_rate)
            elif isinstance(packet, SetIrPalette):
                if self.config.gimbal_type == GimbalType.IR:
                    self.ir_palette = int(packet.palette)
            elif isinstance(packet, SaveConfiguration):
                self.nv = {"telemetry_rate": self.telemetry_rate, "antenna": self.antenna,
                           "gps_feed": self.gps_feed, "ir_palette": self.ir_palette}
                self.nv_saves += 1
                self.busy_until = now + self.config.save_pause
            elif isinstance(packet, SaveFfc):
                # 5.5.1.2 does not say the gimbal goes quiet (the IR module saves)
                if self.config.gimbal_type == GimbalType.IR:
                    self.ffc_saves += 1
            else:  # a report sent to the gimbal: a real device would ignore it
                self.ignored[name] = self.ignored.get(name, 0) + 1
            return answers

    def _set_mode(self, mode: GimbalMode, now: float) -> None:
        if self.mode == GimbalMode.INIT:
            return  # initialising: mode commands are ignored until it finishes
        if mode == GimbalMode.FFC_CALIBRATION and self.config.gimbal_type != GimbalType.IR:
            return  # IR only
        if mode == self.mode:
            return  # periodic refresh of the same mode changes nothing
        if mode == GimbalMode.ANGLES:
            self.angles_target = (self.pan.position, self.tilt.position)
            self.commanded_angles = self.angles_target
        if mode == GimbalMode.RATES:
            self.commanded_rates = (0.0, 0.0)
        LOG.info("mode %s -> %s", mode_name(self.mode), mode_name(mode))
        self.mode = mode
        self.mode_since = now

    # --- simulation step -------------------------------------------------
    def step(self, now: float | None = None) -> None:
        now = self._clock() if now is None else now
        with self.lock:
            dt = min(max(now - self._last_step, 0.0), 0.1)
            self._last_step = now
            cfg = self.config
            if self.mode == GimbalMode.RATES:
                for axis, rate in zip((self.pan, self.tilt), self.commanded_rates, strict=True):
                    axis.jog(rate)
            else:
                for axis, goal in zip((self.pan, self.tilt), self._mode_target(), strict=True):
                    axis.move_to(goal)
            for axis in (self.pan, self.tilt):
                axis.step(dt)
            self._finish_automatic_mode(now)
            zoom_step = cfg.zoom_speed * dt
            self.zoom += max(-zoom_step, min(zoom_step, self.zoom_target - self.zoom))

    def _mode_target(self) -> tuple[float, float]:
        if self.mode == GimbalMode.ANGLES:
            return self.angles_target
        if self.mode == GimbalMode.STOW:
            return STOW_POSITION
        if self.mode == GimbalMode.FFC_CALIBRATION:
            return FFC_POSITION
        return PILOT_POSITION  # pilot, init, autoalign

    def _at(self, target: tuple[float, float]) -> bool:
        return (abs(self.pan.position - target[0]) < 1e-4
                and abs(self.tilt.position - target[1]) < 1e-4)

    def _finish_automatic_mode(self, now: float) -> None:
        if self.mode not in AUTOMATIC_MODES:
            return
        duration = {
            GimbalMode.INIT: self.config.init_time,
            GimbalMode.GYRO_AUTOALIGN: self.config.autoalign_time,
            GimbalMode.FULL_AUTOALIGN: self.config.autoalign_time,
            GimbalMode.FFC_CALIBRATION: self.config.ffc_time,
        }[self.mode]
        if not self._at(self._mode_target()):
            self.mode_since = now  # the timer starts once the pose is reached
            return
        if now - self.mode_since >= duration:
            LOG.info("%s finished -> angles", mode_name(self.mode))
            self.mode = GimbalMode.ANGLES
            self.mode_since = now
            self.angles_target = self.commanded_angles

    # --- reports ---------------------------------------------------------
    def silent(self, now: float | None = None) -> bool:
        return (self._clock() if now is None else now) < self.busy_until

    def periodic_reports(self) -> list[Packet]:
        with self.lock:
            if self.gps_feed == GpsFeed.EXTERNAL and self.external_position is not None:
                position = self.external_position
            else:
                position = self.internal_position
            reports: list[Packet] = [
                ModeReport(self.mode),
                AnglesReport(self.pan.position, self.tilt.position),
                RatesReport(self.pan.velocity, self.tilt.velocity),
                ZoomReport(round(self.zoom * 16383) / 16383),
                GimbalTypeReport(self.config.gimbal_type),
                SystemPositionReport(*position),
            ]
            if self.config.gimbal_type == GimbalType.IR:
                reports.append(IrPaletteReport(self.ir_palette))
            return reports


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
    """One link's byte handling (the server makes one per pty generation)."""

    def __init__(self, sim: UCameraSim) -> None:
        self._sim = sim
        self._parser = FrameParser(expected_payload_length)
        self._next_report = 0.0

    def on_bytes(self, data: bytes) -> bytes:
        out = bytearray()
        for frame in self._parser.feed(data):
            try:
                packet = decode_packet(frame)
            except ProtocolError as exc:
                self._sim.bad_packets += 1
                LOG.debug("ignored frame: %s", exc)
                continue
            for answer in self._sim.model.handle(packet):
                out += self._sim.faults.apply(answer.encode())
        self._sim.checksum_errors = self._parser.stats.checksum_errors
        return bytes(out)

    def poll(self) -> bytes:
        model = self._sim.model
        now = time.monotonic()
        model.step(now)
        if model.silent(now) or now < self._next_report:
            return b""
        period = 1.0 / max(1, model.telemetry_rate)
        self._next_report = max(self._next_report + period, now - period)
        out = bytearray()
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
                clear_device=self._clear_injected)
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
        with self.model.lock:
            self.model.internal_position = tuple(float(a) for a in args)

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


def build_arg_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ucamera_sim",
        description="Airelectronics U-Camera simulator on a pseudo-terminal (UCSP, 115200 8N1). "
        "Prints a JSON ready line with the serial port path to open; reads control verbs on "
        "stdin and on a TCP console (type help).",
    )
    parser.add_argument("--link", default=None,
                        help="stable symlink to create for the pty (default: a temp path)")
    parser.add_argument("--gimbal-type", choices=["ir", "daylight"], default="ir")
    parser.add_argument("--telemetry-rate", type=int, default=50, help="Hz, 1..200")
    parser.add_argument("--max-rate", type=float, default=60.0, help="deg/s per axis")
    parser.add_argument("--acceleration", type=float, default=240.0, help="deg/s^2")
    parser.add_argument("--init-time", type=float, default=0.5, help="s in INIT at power-up")
    parser.add_argument("--autoalign-time", type=float, default=2.0, help="s")
    parser.add_argument("--ffc-time", type=float, default=1.0, help="s")
    parser.add_argument("--save-pause", type=float, default=1.0,
                        help="s of silence after Save Configuration")
    parser.add_argument("--noise-rate", type=float, default=0.0, help="garbage bytes/s")
    parser.add_argument("--corrupt-rate", type=float, default=0.0,
                        help="probability that a sent frame gets one bit flipped")
    parser.add_argument("--drop-rate", type=float, default=0.0,
                        help="probability that a sent frame is lost")
    parser.add_argument("--control-port", type=int, default=0,
                        help="control console on 127.0.0.1 (0 = any free port, -1 = none); "
                             "the same verbs are read on stdin")
    parser.add_argument("--log-level", default="INFO")
    return parser


def config_from_args(args: argparse.Namespace) -> SimConfig:
    if not 1 <= args.telemetry_rate <= 200:
        raise SystemExit("--telemetry-rate must be within 1..200 Hz")
    return SimConfig(
        gimbal_type=GimbalType.IR if args.gimbal_type == "ir" else GimbalType.DAYLIGHT,
        telemetry_rate=args.telemetry_rate,
        max_rate=math.radians(args.max_rate),
        acceleration=math.radians(args.acceleration),
        init_time=args.init_time,
        autoalign_time=args.autoalign_time,
        ffc_time=args.ffc_time,
        save_pause=args.save_pause,
    )


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--ros-args" in argv:  # started by a ROS launch file: those arguments are not ours
        argv = argv[: argv.index("--ros-args")]
    args = build_arg_parser().parse_args(argv)
    logging.basicConfig(level=args.log_level.upper(), format="%(name)s: %(message)s")
    sim = UCameraSim(config_from_args(args), link_path=args.link)
    sim.set_noise_rate(args.noise_rate)
    sim.corrupt(probability=args.corrupt_rate)
    sim.drop_frames(args.drop_rate)
    try:
        sim.start()
    except OSError as exc:
        raise SystemExit(f"ucamera_sim: cannot create the pseudo-terminal link "
                         f"{args.link or ''}: {exc}") from exc
    LOG.info("U-Camera simulator serving on %s", sim.port_name)
    try:
        run_simulator(sim.controls, {"pty": sim.port_name}, args.control_port)
    finally:
        sim.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
