"""The U-Camera as a :class:`~gimbal_driver_common.device.Device` (no ROS).

Wraps one :class:`UCameraClient` and speaks the device contract: SI units,
REP-103 signs and joint names. Everything that converts between the gimbal and
ROS conventions lives here: axis signs (``invert_pan``/``invert_tilt``), the
set-point ramp that gives angle moves a speed (the gimbal has no speed input),
the "moving" bits, and (in its part ``functions``, ``device_functions.py``) the
external-feed frames (ENU/FLU in, NED/FRD out).

What lives where:

* ``protocol/``: the codec (packets, scaling, range checks);
* ``client.py``: the serial session (reader thread, requests, refresh at >= 10 Hz,
  link loss detection; no reconnect loop);
* this module: the adapter;
* ``device_functions.py``: the device extras the node exposes (modes, zoom, IR
  palette, external feed, non-volatile saves behind ``allow_nv_write``), the
  :class:`~.device_functions.UCameraFunctions` part of the adapter (``functions``);
* ``capabilities.py``: its capability objects (:class:`~.capabilities.PilotHoming`,
  :class:`~.capabilities.UCameraStatus`, :class:`~.capabilities.UCameraGeolocation`);
* ``node.py``: parameters, ``make_device()`` and the ROS topics and services of
  the extras.

Signs: the gimbal fixed frame of the manual (4.3.1) is X forward, Z down the
pan axis toward the camera, so Y points right: positive device pan turns right
and positive device tilt raises the camera. REP-103 wants positive pan to the
left, so pan is negated (``invert_pan``, default true) and tilt is kept.

Set-point ramp: a move with a speed ramps the angle set-point toward the
target, stepped on every angles report by ``speed * elapsed`` (real time since
the previous step), so the speed holds at any telemetry rate.

"Moving": the gimbal reports its *actual* axis rates (5.5.3.4), which on a
stabilised gimbal in flight follow the airframe even while it holds a
direction. So the adapter sets the moving bit from what the driver commanded:
in rates mode a non-zero commanded rate, and after a stop the reported rate
until it first falls under ``STOP_RATE`` (so the axis confirms the stop: a
SetRates the gimbal dropped reads moving); in angles mode a running set-point
ramp or a reported angle farther than ``goal_tolerance`` from the set-point.
In modes the gimbal drives itself (stow, pilot, init, autoalign, FFC) it sets
no bit, and the controller's one rule (reported speed) applies.
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

from gimbal_driver_common.config import Logger
from gimbal_driver_common.device import Device, DeviceInfo, JointSample, Moves, PostedWrite
from gimbal_driver_common.errors import Unsupported
from gimbal_driver_common.unanswered import ConnectReads

from .capabilities import PilotHoming, UCameraGeolocation, UCameraStatus
from .client import NotConnectedError, UCameraClient
from .device_functions import UCameraFunctions
from .protocol import AnglesReport, GimbalMode, GimbalType, GpsFeed, Packet

LOG = logging.getLogger(__name__)
#: rad/s: after a stop in rates mode an axis reads moving while its reported rate is above
#: this (a stabilised gimbal in calm flight holds its direction well under it)
STOP_RATE = 0.02


@dataclass
class UCameraSettings:
    """The node's parameters the device uses; the node shares one instance, so run-time
    parameter changes (timeouts, rates) reach the adapter without plumbing."""

    serial_port: str = "/dev/ttyUSB0"
    baudrate: int = 115200
    joint_names: tuple[str, str] = ("pan", "tilt")
    invert_pan: bool = True
    invert_tilt: bool = False
    telemetry_rate: int = 50
    refresh_rate: float = 10.0
    silence_timeout: float = 1.5
    request_timeout: float = 0.5
    connect_timeout: float = 3.0
    mode_timeout: float = 3.0
    home_timeout: float = 20.0
    gps_feed: str = ""
    antenna_position: Sequence[float] = field(default_factory=lambda: [0.0])
    ir_palette: int = -1
    allow_nv_write: bool = False


class UCameraDevice(Device):
    """One U-Camera in joint space (REP-103); thread-safe. Its extras are the part
    :attr:`functions`."""

    streamed = True  # angles arrive as periodic reports: publish each as it comes

    def post(self, moves: Moves, jogs: dict[str, float]) -> PostedWrite:
        """UCSP has no ACK: a set-point is one packet written to the serial line.
        Written from the caller's thread, with no answer to settle."""
        return self.write_now(moves, jogs)

    def __init__(
        self, settings: UCameraSettings, *, tolerance: Callable[[], float] = lambda: 0.01,
        on_report: Callable[[Packet, float], None] | None = None,
        log: Logger | logging.Logger = LOG,
    ) -> None:
        super().__init__()
        self.settings = settings
        self.tolerance = tolerance
        self.log = log
        self._listener = on_report
        self.client = UCameraClient(
            settings.serial_port, settings.baudrate, refresh_rate=settings.refresh_rate,
            silence_timeout=settings.silence_timeout, request_timeout=settings.request_timeout,
            on_report=self._on_report)
        self.antenna: tuple[float, ...] | None = None
        #: best-effort connect-time reads the gimbal left unanswered (a read-back, an
        #: identity detail); only the version answer and the angles reports are required
        self.unanswered = ConnectReads(lambda text: self.log.warning(text))
        self._lock = threading.RLock()  # set-point, ramp and jog state (several threads)
        self._setpoint: dict[str, float] = {}
        self._ramp: dict[str, tuple[float, float]] = {}  # joint -> (target, speed)
        self._ramp_time = 0.0
        self._jog_rates: dict[str, float] = {}
        #: joints stopped in rates mode whose reported rate has not fallen under
        #: STOP_RATE since: they read moving until it does (the axis confirms the stop)
        self._braking: set[str] = set()
        self._rates_check_pending = False
        self.functions = UCameraFunctions(self.client, settings, axes=self)
        self.capabilities.homing = PilotHoming(self)
        self.capabilities.status = UCameraStatus(self)
        self.capabilities.geolocation = UCameraGeolocation(self)

    # ---------------------------------------------------------------- frames
    @property
    def joint_names(self) -> tuple[str, str]:
        pan, tilt = self.settings.joint_names
        return pan, tilt

    def _signs(self) -> tuple[float, float]:
        return (-1.0 if self.settings.invert_pan else 1.0,
                -1.0 if self.settings.invert_tilt else 1.0)

    def to_device(self, joint_values: dict[str, float]) -> tuple[float, float]:
        """Joint values (REP-103) -> device (pan, tilt)."""
        pan_name, tilt_name = self.joint_names
        sign_pan, sign_tilt = self._signs()
        return sign_pan * joint_values[pan_name], sign_tilt * joint_values[tilt_name]

    def from_device(self, pan: float, tilt: float) -> dict[str, float]:
        """Device (pan, tilt) -> joint values (REP-103)."""
        sign_pan, sign_tilt = self._signs()
        pan_name, tilt_name = self.joint_names
        return {pan_name: sign_pan * pan, tilt_name: sign_tilt * tilt}

    # --------------------------------------------------------------- contract
    def open(self) -> DeviceInfo:
        """Open the link, read the identity, apply the connect-time settings."""
        client = self.client
        client.refresh_period = 1.0 / self.settings.refresh_rate
        version = client.start(timeout=self.settings.connect_timeout)
        self._forget_motion()
        self.unanswered.clear()
        try:
            self._apply_connect_settings()
            # a jog may have been running when the link was lost and the gimbal keeps its last
            # rates: stop it before anything else. The mode decides it; wait briefly for the
            # first report that carries it, else the first read() after connect decides.
            deadline = time.monotonic() + 1.0
            while (client.state().mode is None or client.state().gimbal_type is None) \
                    and time.monotonic() < deadline:
                time.sleep(0.02)
            self._rates_check_pending = True
            self._stop_rates_left_running()
        except Exception:
            client.stop()
            raise
        gimbal_type = client.state().gimbal_type
        kind = GimbalType(gimbal_type).name.lower() if gimbal_type in set(GimbalType) else "?"
        return DeviceInfo(
            model=f"Airelectronics U-Camera ({kind})",
            serial_number=version.serial_number,
            firmware_version=version.firmware,
            hardware_id=f"ucamera-{version.serial_number}",
        )

    def _apply_connect_settings(self) -> None:
        """The connect-time parameters (volatile until ~/save_configuration)."""
        client, settings = self.client, self.settings
        if settings.telemetry_rate:
            client.commands.set_telemetry_rate(settings.telemetry_rate, verify=False)
            # the read-back is best effort: the angles reports are what the node needs
            achieved = self.unanswered.read("TelemetryRateRequest", client.request_telemetry_rate)
            if achieved is not None and achieved != settings.telemetry_rate:
                self.log.warning(
                    f"telemetry_rate {settings.telemetry_rate} Hz requested, device reports "
                    f"{achieved} Hz")
        if settings.gps_feed:
            client.commands.configure_gps_feed(
                GpsFeed.EXTERNAL if settings.gps_feed == "external" else GpsFeed.INTERNAL)
        if len(settings.antenna_position) == 3:
            client.commands.set_antenna_position(*settings.antenna_position)
        if settings.ir_palette >= 0:
            client.commands.set_ir_palette(settings.ir_palette)
        self.antenna = self.unanswered.read("AntennaPositionRequest",
                                         client.request_antenna_position)


    def close(self) -> None:
        self.client.stop()

    def description(self) -> str:
        return f"serial://{self.settings.serial_port}?baudrate={self.settings.baudrate}"

    def link_healthy(self) -> bool:
        if not self.client.connected:
            raise NotConnectedError(
                f"U-Camera link down: {self.client.last_error or 'no telemetry'}")
        return True

    def _stop_rates_left_running(self) -> None:
        """Once the mode after a connect is known: in rates mode, set the rates to zero
        (unless this driver has commanded a jog since; safety on (re)connect)."""
        mode = self.client.state().mode
        if not self._rates_check_pending or mode is None:
            return
        self._rates_check_pending = False
        with self._lock:
            jogging = any(self._jog_rates.values())
        if mode == GimbalMode.RATES and not jogging:
            self.client.set_rates(0.0, 0.0)
            with self._lock:
                self._jog_rates = dict.fromkeys(self.joint_names, 0.0)
            self.log.warning("gimbal was in rates mode at connect: rates set to zero")

    def read(self) -> JointSample | None:
        self._stop_rates_left_running()
        state = self.client.state()
        if state.pan is None or state.tilt is None:
            return None
        positions = self.from_device(state.pan, state.tilt)
        rates = self.from_device(state.pan_rate or 0.0, state.tilt_rate or 0.0)
        return JointSample(
            positions=positions, velocities=rates,
            stamp=state.angles_time, moving=self._moving_bits(positions, rates, state.mode))

    def _moving_bits(self, positions: dict[str, float], rates: dict[str, float],
                     mode: int | None) -> dict[str, bool]:
        """From what the driver commanded (see the module docstring); after a stop in rates
        mode, from the reported rate until it first falls under STOP_RATE."""
        with self._lock:
            if self._jog_rates and mode == GimbalMode.RATES:
                bits = {}
                for name, rate in self._jog_rates.items():
                    braking = name in self._braking and abs(rates.get(name, 0.0)) > STOP_RATE
                    if not braking:
                        self._braking.discard(name)
                    bits[name] = rate != 0.0 or braking
                return bits
            if self._setpoint and mode == GimbalMode.ANGLES:
                band = self.tolerance()
                return {name: name in self._ramp or abs(positions[name] - target) > band
                        for name, target in self._setpoint.items()}
        return {}

    def move(self, moves: Moves) -> None:
        current = self._current_positions()
        with self._lock:
            for name in self.joint_names:
                self._setpoint.setdefault(name, current.get(name, 0.0))
            self._jog_rates.clear()
            for name, (target, speed) in moves.items():
                if speed is None:
                    self._ramp.pop(name, None)
                    self._setpoint[name] = target
                else:
                    # the gimbal has no speed input: ramp the angle set-point from where it is
                    self._setpoint[name] = current.get(name, self._setpoint[name])
                    self._ramp[name] = (target, speed)
            self._ramp_time = time.monotonic()
            self.client.set_angles(*self.to_device(self._setpoint))

    def step_ramp(self) -> None:
        """Advance the ramped set-points by the real time elapsed since the last step.

        Runs on each angles report (the telemetry rate, 50 Hz by default).
        """
        with self._lock:
            if not self._ramp:
                return
            now = time.monotonic()
            elapsed, self._ramp_time = now - self._ramp_time, now
            for name, (target, speed) in list(self._ramp.items()):
                error = target - self._setpoint[name]
                step = speed * elapsed
                if abs(error) <= step:
                    self._setpoint[name] = target
                    self._ramp.pop(name)
                else:
                    self._setpoint[name] += math.copysign(step, error)
            try:
                self.client.set_angles(*self.to_device(self._setpoint))
            except Exception as exc:  # noqa: BLE001 - the reader thread must go on
                self._ramp.clear()
                self.log.warning(f"move set-point not sent, ramp dropped: {exc}")

    def jog(self, velocities: dict[str, float]) -> None:
        with self._lock:
            self._ramp.clear()  # a jog replaces any ramped move (one mode for both axes)
            for name in self.joint_names:
                self._jog_rates.setdefault(name, 0.0)
            self._jog_rates.update(velocities)
            for name, velocity in velocities.items():  # a zero jog is that axis' stop
                (self._braking.add if velocity == 0.0 else self._braking.discard)(name)
            self._setpoint.clear()
            self.client.set_rates(*self.to_device(self._jog_rates))

    def stop(self, joints: Sequence[str] | None = None) -> None:
        """Rates mode: zero rates (still stabilised); else angles at the reported angles."""
        with self._lock:
            if joints is not None and self._jog_rates and set(joints) != set(self.joint_names):
                for name in joints:  # expired jog of some joints: zero only those rates
                    self._jog_rates[name] = 0.0
                    self._braking.add(name)
                self.client.set_rates(*self.to_device(self._jog_rates))
                return
            self._forget_motion()
            self.client.hold()
            if self.client.desired_mode == GimbalMode.RATES:
                self._jog_rates = dict.fromkeys(self.joint_names, 0.0)
                self._braking = set(self.joint_names)
            else:
                state = self.client.state()
                self._setpoint = self.from_device(state.pan or 0.0, state.tilt or 0.0)

    def reset_faults(self) -> str:
        raise Unsupported("the U-Camera protocol (UCSP) has no fault-reset command")

    def release_axes(self, then: Callable[[], None]) -> None:
        """A device mode takes the axes: the set-point, ramp and jog end, and ``then``
        (the mode command) goes out under the same hold of the motion lock."""
        with self._lock:
            self._forget_motion()
            then()

    def _forget_motion(self) -> None:
        with self._lock:
            self._ramp.clear()
            self._jog_rates.clear()
            self._braking.clear()
            self._setpoint.clear()

    def _current_positions(self) -> dict[str, float]:
        state = self.client.state()
        if state.pan is None or state.tilt is None:
            return {}
        return self.from_device(state.pan, state.tilt)

    def _on_report(self, packet: Packet, stamp: float) -> None:
        """Runs on the client's reader thread for every received packet."""
        if isinstance(packet, AnglesReport):
            self.step_ramp()
            self.notify_data()  # publish joint_states now
        if self._listener is not None:
            self._listener(packet, stamp)
