"""U-Camera device session over a serial port (no ROS).

:meth:`UCameraClient.start` opens the port and starts a
:class:`gimbal_driver_common.session.Session` on it (its reader thread is
``ucamera-reader``) that parses the telemetry stream (resynchronising after
noise), answers pending requests and, in its tick, re-sends the current mode
and angles/rates command at ``refresh_rate`` (the manual recommends at least
10 Hz, 5.1). When the port fails or the telemetry stops for
``silence_timeout`` seconds the session closes the port and ends with the
reason in :attr:`UCameraClient.last_error`; the client never reopens it by
itself: the controller's connection supervisor
(``gimbal_driver_common.controller``) calls :meth:`stop` and :meth:`start`
again. Errors are the core hierarchy (``gimbal_driver_common.errors``).

Values are SI in the *device* frame (radians, rad/s, metres); sign
conventions for ROS are applied by the node.

Modes that end by themselves (INIT, autoalign, FFC calibration) are sent once
and not refreshed: re-sending ANGLES during them would abort them. When the
device reports it has left such a mode, the refresh resumes in ANGLES, which
is where the gimbal returns (4.6, 4.7).
"""

from __future__ import annotations

import collections
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import replace

from gimbal_driver_common.errors import DeviceTimeout, LinkError
from gimbal_driver_common.session import Protocol, Session, StreamLink
from gimbal_driver_common.transport import ByteStream, SerialStream, TransportError

from .client_commands import QuietPeriod, UCameraCommands
from .client_types import (
    ONE_SHOT_MODES,
    PERSISTENT_MODES,
    ClientStats,
    GimbalState,
    NotConnectedError,
    RequestTimeoutError,
    UCameraError,
)
from .protocol import (
    AnglesReport,
    AntennaPositionReport,
    AntennaPositionRequest,
    FrameParser,
    GimbalMode,
    GimbalTypeReport,
    IrPaletteReport,
    ModeReport,
    Packet,
    PayloadError,
    ProtocolError,
    RatesReport,
    SetAngles,
    SetMode,
    SetRates,
    SystemPositionReport,
    TelemetryRateReport,
    TelemetryRateRequest,
    UnknownPacketError,
    VersionReport,
    VersionRequest,
    ZoomReport,
    decode_packet,
    expected_payload_length,
    mode_name,
)

LOG = logging.getLogger(__name__)

class UCameraClient(Protocol):
    """Session with one U-Camera; thread-safe. The client is its session's protocol; its
    device-function commands are the part :attr:`commands`."""

    _reading: Session  # the session whose reader runs the protocol methods

    def __init__(
        self,
        port: str | None = None,
        baudrate: int = 115200,
        *,
        stream_factory: Callable[[], ByteStream] | None = None,
        refresh_rate: float = 10.0,
        silence_timeout: float = 1.5,
        request_timeout: float = 0.5,
        save_pause_grace: float = 3.0,
        one_shot_timeout: float = 2.0,
        on_report: Callable[[Packet, float], None] | None = None,
    ) -> None:
        if stream_factory is None:
            if not port:
                raise ValueError("a serial port (or a stream factory) is needed")
            stream_factory = lambda: SerialStream(port, baudrate)  # noqa: E731
        if refresh_rate <= 0:
            raise ValueError("refresh_rate must be > 0 Hz")
        self._stream_factory = stream_factory
        self._session: Session | None = None
        self.description = stream_factory().description
        self.refresh_period = 1.0 / refresh_rate
        self.silence_timeout = silence_timeout
        self.request_timeout = request_timeout
        #: the silence an NV save may add (``save_pause_grace``), opened by ``commands``
        self.quiet = QuietPeriod(save_pause_grace)
        self.one_shot_timeout = one_shot_timeout
        self._on_report = on_report

        self._lock = threading.RLock()
        self._parser = FrameParser(expected_payload_length)
        self._state = GimbalState()
        self._angle_times: collections.deque[float] = collections.deque(maxlen=512)
        self.stats = ClientStats()
        self.version: VersionReport | None = None
        self.last_error = ""
        self.mode_error = ""  # a self-ending mode the gimbal did not enter (until next mode)

        self._desired_mode: GimbalMode | None = None
        self._desired_angles: tuple[float, float] | None = None
        self._desired_rates: tuple[float, float] | None = None
        self._one_shot: GimbalMode | None = None
        self._one_shot_seen = False
        self._one_shot_sent = 0.0

        self._sessions = 0
        self._last_rx = 0.0
        self._last_packet = 0.0  # any well-framed packet, understood or not
        self._alive = False
        self._next_refresh = 0.0
        self.commands = UCameraCommands(self, self.quiet)

    # --- lifecycle -------------------------------------------------------
    def start(self, timeout: float = 3.0) -> VersionReport:
        """Open the port, start the session and read the device identity.

        Raises :class:`NotConnectedError` when the port does not open or the link dies
        meanwhile, :class:`RequestTimeoutError` when the gimbal does not answer within
        ``timeout``; nothing is left running then. Callable again after :meth:`stop`.
        """
        if self._session is not None:
            raise UCameraError("client already started")
        stream = self._stream_factory()
        try:
            stream.open()
        except TransportError as exc:
            self.last_error = str(exc)
            raise self._no_answer(NotConnectedError, timeout, str(exc)) from exc
        if self._sessions:
            self.stats.reconnects += 1
        self._sessions += 1
        self._parser.reset()
        with self._lock:  # the mode may have changed while the link was down: unknown again
            self._state = replace(self._state, mode=None)
        self._last_rx = self._last_packet = time.monotonic()
        self._next_refresh = 0.0
        self.last_error = ""
        LOG.info("opened %s", stream.description)
        self._session = Session(StreamLink(stream, 1024), self, "ucamera", read_timeout=0.02,
                                link_error=NotConnectedError).start()
        deadline = time.monotonic() + timeout
        last_failure = "no answer"
        while time.monotonic() < deadline and not self.link_down:
            try:
                return self.request_version(min(self.request_timeout,
                                                max(0.05, deadline - time.monotonic())))
            except UCameraError as exc:
                last_failure = str(exc)
                time.sleep(0.05)
        # the session's reason (read failure, no telemetry) says more than a timeout
        link_died = self.link_down
        reason = self.last_error or last_failure
        self.stop()
        raise self._no_answer(NotConnectedError if link_died else RequestTimeoutError,
                              timeout, reason)

    def _no_answer(self, kind: type[UCameraError], timeout: float, reason: str) -> UCameraError:
        return kind(
            f"U-Camera on {self.description} did not answer Request Gimbal Version within "
            f"{timeout:g} s ({reason}); check cable, power, port name and baud rate (115200 8N1)"
        )

    def stop(self) -> None:
        """End the session and close the port (commands already sent stay in effect)."""
        session, self._session = self._session, None
        if session is not None:
            session.close()
        self._alive = False

    @property
    def running(self) -> bool:
        return self._session is not None

    @property
    def connected(self) -> bool:
        """True while the port is open and telemetry is arriving."""
        return self._alive

    @property
    def link_down(self) -> bool:
        """True once the session gave the link up (reason in :attr:`last_error`)."""
        session = self._session
        return session is not None and not session.alive

    def state(self) -> GimbalState:
        with self._lock:
            return self._state

    @property
    def desired_mode(self) -> GimbalMode | None:
        return self._desired_mode

    @property
    def pending_automatic_mode(self) -> GimbalMode | None:
        """The self-ending mode the client is waiting on (autoalign, FFC, init)."""
        return self._one_shot

    def telemetry_rate_achieved(self, window: float = 2.0) -> float:
        """Angles reports per second over the last ``window`` seconds."""
        now = time.monotonic()
        with self._lock:
            recent = [t for t in self._angle_times if now - t <= window]
        if len(recent) < 2:
            return 0.0
        span = max(now - recent[0], recent[-1] - recent[0])
        return (len(recent) - 1) / span if span > 0 else 0.0

    # --- requests --------------------------------------------------------
    def request(self, packet: Packet, answer: type[Packet], timeout: float | None = None,
                attempts: int = 2) -> Packet:
        """Send ``packet`` and wait for the ``answer`` packet type."""
        timeout = self.request_timeout if timeout is None else timeout
        for _ in range(max(1, attempts)):
            with self._live_session().expect(lambda reply: type(reply) is answer) as pending:
                self.send(packet)
                try:
                    return pending.next(timeout)
                except DeviceTimeout:
                    continue
        raise RequestTimeoutError(
            f"no {answer.TITLE} from the U-Camera within {timeout:g} s "
            f"({attempts} attempt(s)) on {self.description}"
        )

    def request_version(self, timeout: float | None = None) -> VersionReport:
        version = self.request(VersionRequest(), VersionReport, timeout)
        assert isinstance(version, VersionReport)
        self.version = version
        return version

    def request_telemetry_rate(self, timeout: float | None = None) -> int:
        report = self.request(TelemetryRateRequest(), TelemetryRateReport, timeout)
        assert isinstance(report, TelemetryRateReport)
        return report.rate_hz

    def request_antenna_position(self, timeout: float | None = None) -> tuple[float, ...]:
        report = self.request(AntennaPositionRequest(), AntennaPositionReport, timeout)
        assert isinstance(report, AntennaPositionReport)
        return (report.x, report.y, report.z)

    # --- commands --------------------------------------------------------
    def _live_session(self) -> Session:
        session = self._session
        if session is None or not session.alive:
            raise NotConnectedError(
                f"U-Camera link {self.description} is down"
                + (f" ({self.last_error})" if self.last_error else "")
            )
        return session

    def send(self, packet: Packet) -> None:
        """Encode (range-checked first) and write one packet."""
        data = packet.encode()  # raises RangeError before anything is written
        session = self._live_session()
        try:
            session.write(data)
        except LinkError as exc:
            self.last_error = f"write failed: {exc}"
            raise NotConnectedError(f"write to U-Camera failed: {exc}") from exc
        self.stats.commands_sent += 1

    def set_mode(self, mode: int) -> None:
        """Select a mode; persistent ones are refreshed, self-ending ones sent once."""
        try:
            mode = GimbalMode(mode)
        except ValueError:
            SetMode(mode).encode()  # raises RangeError naming the valid modes
            raise
        packet = SetMode(mode)
        packet.encode()
        self.mode_error = ""
        with self._lock:
            if mode in ONE_SHOT_MODES:
                self._one_shot, self._one_shot_seen = mode, False
                self._one_shot_sent = time.monotonic()
            else:
                self._one_shot = None
                self._desired_mode = mode
        self.send(packet)

    def set_angles(self, pan: float, tilt: float) -> None:
        """Point to (pan, tilt) rad in ANGLES mode (switching mode if needed)."""
        packet = SetAngles(pan, tilt)
        packet.encode()
        with self._lock:
            self._desired_angles = (pan, tilt)
            switch = self._desired_mode != GimbalMode.ANGLES or self._one_shot is not None
        if switch:
            self.set_mode(GimbalMode.ANGLES)
        self.send(packet)

    def set_rates(self, pan_rate: float, tilt_rate: float) -> None:
        """Turn at (pan, tilt) rad/s in RATES mode (switching mode if needed)."""
        packet = SetRates(pan_rate, tilt_rate)
        packet.encode()
        with self._lock:
            self._desired_rates = (pan_rate, tilt_rate)
            switch = self._desired_mode != GimbalMode.RATES or self._one_shot is not None
        if switch:
            self.set_mode(GimbalMode.RATES)
        self.send(packet)

    def hold(self) -> None:
        """Stop moving: zero rates in RATES mode, else hold the reported angles."""
        if self._desired_mode == GimbalMode.RATES and self._one_shot is None:
            self.set_rates(0.0, 0.0)
        else:
            self.hold_angles()

    def hold_angles(self) -> None:
        """ANGLES mode at the last reported angles (stops any motion and automatic mode)."""
        state = self.state()
        if state.pan is None or state.tilt is None:
            raise NotConnectedError("no angles reported yet: cannot hold position")
        self.set_angles(state.pan, state.tilt)

    # --- session protocol (on the reader thread) ---------------------------------
    def connection_made(self, session: Session) -> None:
        self._reading = session
        session.on(Packet, self._dispatch)

    def tick(self, now: float) -> float | None:
        """Give the link up after a silence; re-send the mode and set-point when due."""
        quiet = self.silence_timeout + self.quiet.extra(now)
        if now - self._last_rx > quiet:
            self.stats.silences += 1
            raise NotConnectedError(self._no_telemetry(now))
        if now >= self._next_refresh:
            self._next_refresh = now + self.refresh_period
            self._refresh(now)
        return None

    def connection_lost(self, error: LinkError | None) -> None:
        """The session ended: keep why (a write failure already said it)."""
        if error is not None and not self.last_error.startswith("write failed"):
            self.last_error = str(error)
        self._alive = False

    def _no_telemetry(self, now: float) -> str:
        """Why the link is given up: the gimbal sent nothing, or only packets the driver
        does not understand (it answered, but not as the manual says: not silence)."""
        quiet = f"{now - self._last_rx:.1f} s"
        if self._last_packet > self._last_rx:
            return (f"no telemetry the driver understands for {quiet}: the gimbal sends "
                    f"packets, but of unknown ids ({self.stats.unknown_packets} so far) or with "
                    f"bad payloads ({self.stats.bad_payloads}); another firmware?")
        return f"no telemetry for {quiet}"

    def data_received(self, data: bytes) -> None:
        frames = self._parser.feed(data)
        stats = self._parser.stats
        self.stats.checksum_errors = stats.checksum_errors
        self.stats.length_errors = stats.length_errors
        self.stats.discarded_bytes = stats.discarded_bytes
        for frame in frames:
            self._last_packet = time.monotonic()
            try:
                packet = decode_packet(frame)
            except UnknownPacketError:
                self.stats.unknown_packets += 1  # other firmware packets: ignored
                continue
            except (PayloadError, ProtocolError) as exc:
                self.stats.bad_payloads += 1
                LOG.debug("bad payload: %s", exc)
                continue
            self.stats.frames += 1
            self._last_rx = time.monotonic()
            self._alive = True
            self._reading.dispatch(packet)

    def _dispatch(self, packet: Packet) -> None:
        wall = time.time()
        with self._lock:
            state = self._state
            if isinstance(packet, AnglesReport):
                state = replace(state, pan=packet.pan, tilt=packet.tilt, angles_time=wall)
                self._angle_times.append(time.monotonic())
            elif isinstance(packet, RatesReport):
                state = replace(state, pan_rate=packet.pan, tilt_rate=packet.tilt)
            elif isinstance(packet, ModeReport):
                state = replace(state, mode=packet.mode)
                self._track_one_shot(packet.mode)
            elif isinstance(packet, ZoomReport):
                state = replace(state, zoom=packet.level)
            elif isinstance(packet, GimbalTypeReport):
                state = replace(state, gimbal_type=packet.gimbal_type)
            elif isinstance(packet, IrPaletteReport):
                state = replace(state, ir_palette=packet.palette)
            elif isinstance(packet, SystemPositionReport):
                state = replace(state, latitude=packet.latitude, longitude=packet.longitude,
                                altitude=packet.altitude, position_time=wall)
            self._state = state
        if self._on_report is not None:
            try:
                self._on_report(packet, wall)
            except Exception:
                LOG.exception("report callback failed")

    def _track_one_shot(self, reported: int) -> None:
        """Follow a self-ending mode: wait for it to start, then to end in ANGLES."""
        if self._one_shot is None:
            return
        if reported == self._one_shot:
            self._one_shot_seen = True
        elif self._one_shot_seen:
            LOG.info("%s finished; device reports %s", mode_name(self._one_shot),
                     mode_name(reported))
            self._one_shot = None
            if reported in PERSISTENT_MODES:
                self._desired_mode = GimbalMode(reported)

    def _refresh(self, now: float) -> None:
        """Periodic re-send of mode and angles/rates (5.1: ~10 Hz at least)."""
        with self._lock:
            if self._one_shot is not None:
                if not self._one_shot_seen and now - self._one_shot_sent > self.one_shot_timeout:
                    self.mode_error = (f"gimbal did not enter {mode_name(self._one_shot)} "
                                       "(FFC needs an IR gimbal; INIT ignores commands)")
                    self.last_error = self.mode_error
                    LOG.warning(self.mode_error)
                    self._one_shot = None
                return
            mode, angles, rates = self._desired_mode, self._desired_angles, self._desired_rates
        if mode is None or not self._alive:
            return
        try:
            self.send(SetMode(mode))
            if mode == GimbalMode.ANGLES and angles is not None:
                self.send(SetAngles(*angles))
            elif mode == GimbalMode.RATES and rates is not None:
                self.send(SetRates(*rates))
        except UCameraError as exc:
            LOG.debug("refresh skipped: %s", exc)
