"""What the host asks the Capture controller for (no ROS): identity, registers, scans,
presets, IMU, GPS, tracking, power, digital I/O, and the requests it makes on its own
(:meth:`Polls.poll`: not asked again once the device does not know them). Two parts of
:class:`~.client.CaptureClient`: :class:`Polls` is handed the link
(:class:`~.link.CaptureLink`); :class:`DeviceRequests` the link and the parts it drives.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from .errors import (
    REQUEST_ERRORS,
    BackingOff,
    CaptureError,
    DeviceNack,
    DeviceTimeout,
    NotSupported,
    Preempted,
    WrongReply,
)
from .protocol import (
    GeoPoint,
    PresetRecord,
    ProtocolError,
    ReplyCode,
    command,
    ddmm_to_degrees,
)
from .protocol.registers import CSR_ERROR_STRINGS, CSR_PROTOCOL_ERROR, REGISTERS

if TYPE_CHECKING:  # the parts import this module for request_key: no import cycle at run time
    from .batch import BatchedReads
    from .link import CaptureLink
    from .motion import MotionRequests, StopAnswers

LOG = logging.getLogger('capture_driver.device_requests')

GPS_FIX_COMMANDS = ('GPS_PositionReady', 'GPS_GetLatitude', 'GPS_GetLongitude')

SCAN_COMMANDS = {
    'zigzag': 'SCN_StartScanZigZag',
    'snake': 'SCN_StartScanSnake',
    'square': 'SCN_StartScanSquare',
}


def request_key(name: str, axis: int | None) -> str:
    """How one request is named in the unanswered book and in diagnostics."""
    return f'{name} (axis {axis})' if axis else name


IDENTITY_GETTERS = (('serial_number', 'COM_GetSn'), ('firmware', 'COM_GetFw'),
                    ('hardware', 'COM_GetHw'), ('part_number', 'COM_GetPn'))


@dataclass
class Identity:
    serial_number: str = ''
    firmware: str = ''
    hardware: str = ''
    part_number: str = ''
    #: getter -> how it failed (the ones that gave no value)
    problems: dict[str, str] = field(default_factory=dict)


@dataclass
class TrackingState:
    """One camera's video-tracker state as the device reports it."""

    camera: int
    active: bool
    automatic: bool
    target_detected: bool

    @property
    def mode(self) -> str:
        if self.automatic:
            return 'auto'
        return 'manual' if self.active else 'off'



class Polls:
    """The requests the host makes on its own, over the link it is handed: asked once, not
    again once the device does not know them (the link's :attr:`~.link.CaptureLink.unsupported`),
    backed off when unanswered (its :attr:`~.link.CaptureLink.unanswered`)."""

    def __init__(self, link: CaptureLink) -> None:
        self._link = link

    def explain_nack(self, exc: DeviceNack) -> DeviceNack:
        """Add the controller's own reason (ERR_GetProtocolErrorString) to an 0xA6 NACK."""
        if exc.code != ReplyCode.INVALID_COMMAND or exc.detail:
            return exc
        try:
            detail = self.optional('ERR_GetProtocolErrorString')
        except CaptureError:  # the link went
            return exc
        return DeviceNack(exc.request, exc.code, detail, exc.doubt) if detail else exc

    def run(self, name: str, axis: int | None = None, value: Any = None) -> Any:
        """:meth:`request`, with the controller's reason attached to an 0xA6 NACK."""
        try:
            return self._link.request(name, axis, value)
        except DeviceNack as exc:
            raise self.explain_nack(exc) from None

    def poll(self, name: str, axis: int | None = None) -> Any:
        """A getter the host asks on its own (identity, probes, registers, sensor polls).

        Some of these opcodes are reconstructions, and a device may lack the function. When
        the device answers 0xA6, or answers with the wrong kind of reply (an ACK: a
        controller that acknowledges what it does not know), the command lands in
        :attr:`unsupported` with that answer and is never sent again on this connection
        (:class:`NotSupported`, now and on every later call), so the host does not keep
        raising the controller's protocol-error flag; the one flag an 0xA6 raised is cleared
        again when it is the only CSR bit set (ERR_ClearErrors would otherwise also clear
        real errors). Other NACKs raise as :meth:`request` does, for this call only.

        A timeout is not retried and does not count toward calling the device silent; the
        getter is then asked again only after a back-off that doubles with every timeout in
        a row (:attr:`unanswered`, named in diagnostics): until then it raises
        :class:`BackingOff` without sending anything, so an optional sensor the device
        never answers costs the link one timeout per back-off, not one per ask.
        """
        answer = self._link.unsupported.get(name)
        if answer is not None:
            raise NotSupported(name, answer)
        key = request_key(name, axis)
        waiting = self._link.unanswered.waiting(key)
        if waiting is not None:
            record, left = waiting
            raise BackingOff(key, record.in_a_row, left)
        opcode = f'0x{command(name).opcode:04X}'
        try:
            value = self._link.request(name, axis, optional=True)
        except Preempted:
            raise  # a stop or a motion command needed the link: not the device's silence
        except DeviceTimeout:
            self.went_unanswered(name, axis)
            raise
        except WrongReply as exc:
            self.not_supported(name, f'{opcode} answered {exc.answer}, expected {exc.expected}')
            raise NotSupported(name, self._link.unsupported[name]) from exc
        except DeviceNack as exc:
            if exc.code != ReplyCode.INVALID_COMMAND:
                raise
            self.not_supported(name, f'{opcode} answered NACK 0xA6', exc)
            raise NotSupported(name, self._link.unsupported[name]) from exc
        self._link.unanswered.answered(key)
        return value

    def went_unanswered(self, name: str, axis: int | None = None) -> None:
        """``name`` got no answer at all: asked again after its back-off (said once)."""
        key = request_key(name, axis)
        record = self._link.unanswered.timed_out(key)
        if record.in_a_row == 1:
            LOG.warning('%s went unanswered; asked again after a growing back-off', key)

    def answered(self, name: str, axis: int | None = None) -> None:
        """``name`` was answered (in a batch): asked as usual again."""
        self._link.unanswered.answered(request_key(name, axis))

    def optional(self, name: str, axis: int | None = None) -> Any:
        """:meth:`poll`, with None for every answer that is not the value."""
        try:
            return self.poll(name, axis)
        except (NotSupported, BackingOff):
            return None
        except (DeviceNack, DeviceTimeout) as exc:
            LOG.info('%s', exc)
            return None

    def not_supported(self, name: str, answer: str, nack: DeviceNack | None = None) -> None:
        """Record ``name`` as unknown to the device (said once, here); for an 0xA6, with the
        device's reason, and the protocol-error flag it raised cleared."""
        self._link.unsupported[name] = answer  # first: explaining it asks the device again
        if nack is not None:
            detail = self.explain_nack(nack).detail
            if detail:
                self._link.unsupported[name] = f'{answer} "{detail}"'
        LOG.warning('%s: the device does not support it (%s); not sent again on this '
                    'connection', name, self._link.unsupported[name])
        if nack is not None:
            self.clear_own_protocol_error()

    def clear_own_protocol_error(self) -> None:
        with contextlib.suppress(CaptureError, ProtocolError):
            if self.optional('ERR_CaptureSystemRegister') == CSR_PROTOCOL_ERROR:
                self._link.request('ERR_ClearErrors')


class DeviceRequests:
    """Device functions of :class:`~.client.CaptureClient`: requests over the link, the
    host's own polls, the batched register reads and the motion part's stops."""

    def __init__(self, link: CaptureLink, polls: Polls, batch: BatchedReads,
                 motion: MotionRequests) -> None:
        self._link = link
        self._polls = polls
        self._batch = batch
        self._motion = motion

    def identity(self) -> Identity:
        """Serial number, firmware, hardware and part number, best effort: blank where the
        getter is not answered with data, and how it failed in ``problems``."""
        ident = Identity()
        for attr, name in IDENTITY_GETTERS:
            try:
                value = self._polls.poll(name)
            except NotSupported as exc:
                ident.problems[name] = exc.answer
                continue
            except (DeviceNack, DeviceTimeout) as exc:
                ident.problems[name] = str(exc)
                continue
            setattr(ident, attr, f'{value:g}' if isinstance(value, float) else str(value))
        return ident

    def read_axis(self, axis: int, with_current: bool = False) -> tuple[float, float, float | None]:
        """Load position (deg), speed (deg/s) and optionally current (mA) of one axis."""
        position = self._link.request('MOT_GetLoadPosition', axis)
        speed = self._link.request('MOT_GetMotorSpeed', axis)
        current = self._link.request('MOT_GetMotorCurrent', axis) if with_current else None
        return position, speed, current

    def stop_all(self, axes: list[int]) -> StopAnswers:
        """Stop every axis, then loops and scans, all written at once
        (:meth:`MotionRequests.stop_axes`)."""
        answers = self._motion.stop_axes(axes, programs=True)
        for name, exc in answers.programs.items():
            LOG.debug('stop: %s: %s', name, exc)
        return answers

    def reset_faults(self, axis: int) -> None:
        """4.10: "send the 'Reset faults' and the 'AxisOn' commands"."""
        self._polls.run('MOT_ResetFaults', axis)
        self._polls.run('MOT_AxisOn', axis)

    def registers(self, axis: int | None, also: Sequence[str] = ()) -> dict[str, Any]:
        """Raw per-axis registers (``axis``) or system registers (``None``): those the
        device reports; a register getter it does not answer with data is left out and
        not asked again (:meth:`poll`). ``also``: more getters of the same axis read in
        the same batch, under their own names, as optional as the registers (one round
        trip for the status refresh instead of one per getter)."""
        wanted = [(register.name, register.command) for register in REGISTERS.values()
                  if register.per_axis == (axis is not None)]
        wanted += [(name, name) for name in also]
        values = self._batch.read_many([(getter, axis) for _, getter in wanted],
                                       optional=True)
        return {name: value for (name, _), value in zip(wanted, values, strict=True)
                if value is not None}

    def error_strings(self, csr: int) -> dict[str, str]:
        """Detailed device error text for every set CSR bit that has one (and the device
        answers with data)."""
        texts = {}
        for bit, name in CSR_ERROR_STRINGS.items():
            if csr & (1 << bit):
                try:
                    texts[name] = self._polls.poll(name)
                except NotSupported:
                    continue
                except REQUEST_ERRORS as exc:
                    texts[name] = f'unavailable ({exc})'
        return texts

    def configure_scan(self, yaw_min: float, yaw_max: float, pitch_min: float, steps: int,
                       step_height: float, speed: float) -> None:
        """4.3: every scan parameter is sent before each scan (defaults are 0)."""
        for name, value in (
            ('SCN_SetYawMin', yaw_min), ('SCN_SetYawMax', yaw_max),
            ('SCN_SetPitchMin', pitch_min), ('SCN_SetNumSteps', steps),
            ('SCN_SetStepHeight', step_height), ('SCN_SetScanSpeed', speed),
        ):
            self._polls.run(name, None, value)

    def start_scan(self, pattern: str) -> None:
        try:
            name = SCAN_COMMANDS[pattern]
        except KeyError:
            raise CaptureError(
                f'pattern {pattern!r} not available; the device has {sorted(SCAN_COMMANDS)}'
            ) from None
        self._polls.run(name)

    def set_preset(self, index: int, name: str, angles: list[float]) -> None:
        a = [*angles, *([0.0] * 6)]  # the record holds six angles: padded, then cut
        full = (a[0], a[1], a[2], a[3], a[4], a[5])
        self._polls.run('PRST_SetPreset', index, PresetRecord(name, full))

    def get_preset(self, index: int) -> PresetRecord:
        return self._polls.run('PRST_GetPreset', index)

    def preset_indices(self) -> list[int]:
        flags = self._link.request('PRST_GetPresetFlag')
        return [bit + 1 for bit in range(15) if flags & (1 << bit)]

    def imu(self) -> dict[str, float]:
        """Euler angles (deg) and gyro rates (deg/s); :class:`NotSupported` once the device
        does not answer one of the six with data."""
        names = ('IMU_GetRoll', 'IMU_GetPitch', 'IMU_GetYaw',
                 'IMU_GetGyroX', 'IMU_GetGyroY', 'IMU_GetGyroZ')
        keys = ('roll', 'pitch', 'yaw', 'gyro_x', 'gyro_y', 'gyro_z')
        return {key: self._polls.poll(name) for key, name in zip(keys, names, strict=True)}

    def gps_fix(self) -> tuple[bool, float, float] | None:
        """(position valid, latitude deg, longitude deg), converted from DDMM.mmmm (4.4.1);
        None once the device does not answer one of the three with data (the fix poll then
        stops); a timeout or another NACK raises, for this read only."""
        if any(name in self._link.unsupported for name in GPS_FIX_COMMANDS):
            return None  # nothing is sent for a fix the device cannot give
        try:
            ready, latitude, longitude = (self._polls.poll(name) for name in GPS_FIX_COMMANDS)
        except NotSupported:
            return None
        return bool(ready), ddmm_to_degrees(latitude), ddmm_to_degrees(longitude)

    def goto_lla(self, target: int, point: GeoPoint) -> None:
        self._polls.run('GPS_SetTargetLLA', target, point)
        self._polls.run('GPS_GoToTarget', target)

    # -------------------------------------------------- first-class device functions
    def set_tracking(self, camera: int, mode: int) -> None:
        """VDT_setTrackingOn: 0 off, 1 manual, 2 automatic (4.11.1) for camera 0..3."""
        self._polls.run('VDT_setTrackingOn', camera, mode)

    def tracking_state(self, camera: int) -> TrackingState:
        """Tracking active, automatic mode and target detection of one camera (4.11.2-4)."""
        return TrackingState(
            camera=camera,
            active=bool(self._polls.poll('VDT_isTrackingOn', camera)),
            automatic=bool(self._polls.poll('VDT_isAutoModeOn', camera)),
            target_detected=bool(self._polls.poll('VDT_isTargetDetected', camera)),
        )

    def set_axis_power(self, axis: int, on: bool) -> None:
        """MOT_AxisOn / MOT_AxisOff (4.2.11-12). Switching on also cancels the motion the
        drive buffered while off (AxisOn would resume it) by stopping the axis."""
        if on:
            self._polls.run('MOT_AxisOn', axis)
            self._motion.stop_axis(axis)
        else:
            self._polls.run('MOT_AxisOff', axis)

    def digital_io(self, numbers: list[int]) -> dict[int, bool]:
        """State of digital I/O 1..6 (COM_getDigitalIO, the number in the axis byte)."""
        return {n: bool(self._polls.poll('COM_getDigitalIO', n)) for n in numbers}

    def set_digital_output(self, number: int, on: bool) -> None:
        self._polls.run('COM_setDigitalIO', number, int(on))

    def gps_heading(self) -> tuple[bool, float]:
        """(heading valid, system heading in compass degrees clockwise from north)."""
        ready = bool(self._polls.poll('GPS_HeadingReady'))
        return ready, self._polls.poll('GPS_GetHeading')

    def stored_targets(self) -> dict[int, GeoPoint]:
        """Targets 1..15 that hold a position (4.4.12: a cleared target reads all zero)."""
        targets = {}
        for number in range(1, 16):
            point = self._link.request('GPS_GetTargetLLA', number)
            if (point.longitude, point.latitude, point.altitude) != (0.0, 0.0, 0.0):
                targets[number] = point
        return targets
