"""kOS status (no ROS): the ErrorStatus latch, lock state and per-motor diagnostics in SI
(with the ``units`` key). A capability of :class:`~.device.KosDevice`.
"""

from __future__ import annotations

import logging
import threading
from typing import TYPE_CHECKING

from gimbal_driver_common.device import AxisStateCode, StatusReport
from gimbal_driver_common.diagnostics import Level, StatusPart

from .client import ErrorEvent
from .protocol import ERROR_CODES, ErrorCode, PlaybackMode, playback_state_name
from .units import Conversion, JointUnits

if TYPE_CHECKING:
    from .device import KosDevice


LOG = logging.getLogger('kessler_kos_driver.status')

# AuxInputStatus bits (document "AuxInputStatus"): buttons in this order; bit 4 = a slave
# controller is present.
AUX_INPUT_BUTTONS = ('master_tip', 'master_ring', 'slave_tip', 'slave_ring')
AUX_SLAVE_PRESENT_BIT = 4
#: ErrorStatus notifications kept for diagnostics until ~/reset_faults
LATCHED_ERRORS_MAX = 20


class KosStatus(StatusReport):
    """Diagnostics from the ErrorStatus latch, lock state, playback and MotorInfo (in SI)."""

    def __init__(self, device: KosDevice) -> None:
        self.device = device
        self.locked_out = False
        self._errors: list[ErrorEvent] = []
        self._lock = threading.Lock()

    def latch(self, event: ErrorEvent) -> None:
        """An ErrorStatus notification: kept until ~/reset_faults (or homing the axis)."""
        with self._lock:
            self._errors.append(event)
            del self._errors[:-LATCHED_ERRORS_MAX]
        if event.code == ErrorCode.LOCKED_OUT:
            self.locked_out = True
        joint = self.device.joint_of(event.motor_address)
        where = f'joint {joint!r}' if joint else f'motor {event.motor_address}'
        LOG.error('device error %d: %s (%s)', event.code, event.description, where)

    def clear(self, addresses: set[int] | None = None) -> int:
        """Forget the latched errors (of these motors only); returns how many."""
        with self._lock:
            before = len(self._errors)
            if addresses is None:
                self._errors.clear()
                self.locked_out = False
            else:
                self._errors = [e for e in self._errors if e.motor_address not in addresses]
            return before - len(self._errors)

    def latched(self) -> list[ErrorEvent]:
        with self._lock:
            return list(self._errors)

    def _device_wide(self, errors: list[ErrorEvent]) -> list[ErrorEvent]:
        addresses = {m.address for m in self.device.joints.values()}
        return [e for e in errors if e.motor_address not in addresses]

    def parts(self) -> list[StatusPart]:
        device, client = self.device, self.device.client
        errors = self.latched()
        device_errors = self._device_wide(errors)
        playback = playback_state_name(client.playback.status)
        aux = client.aux_inputs
        part = StatusPart('device', values=[
            ('lock', 'LOCKED (password rejected)' if self.locked_out else 'unlocked'),
            ('playback_status', playback),
            ('move_loaded', str(client.playback.loaded)),
            ('guid', client.guid),
            ('malformed_frames', str(client.malformed_frames)),
            ('unsupported_replies', str(client.unsupported_replies)),
            ('transport', 'usb' if client.usb is not None else 'tcp'),
            *([('usb_dropped_reports', str(client.usb_dropped_reports))]
              if client.usb is not None else []),
            ('aux_inputs', ' '.join(f'{n}={aux >> b & 1}'
                                    for b, n in enumerate(AUX_INPUT_BUTTONS))),
            ('slave_controller_present', str(bool(aux >> AUX_SLAVE_PRESENT_BIT & 1))),
            *sorted(device.functions.device_settings.items()),
            *client.unanswered.diagnostics(),
            *[(f'error_{e.code}', f'{e.description} (motor {e.motor_address})')
              for e in device_errors],
        ])
        if self.locked_out:
            part.level, part.message = Level.ERROR, 'device locked: password rejected'
        elif device_errors:
            part.level = Level.ERROR
            part.message = f'error {device_errors[-1].code}: {device_errors[-1].description}'
        elif client.unanswered:  # best effort at connect: the node works without it
            part.level = Level.WARN
            part.message = client.unanswered.summary()
        else:
            part.message = f'OK, playback {playback}'
        return [part] + [self._axis_part(name, errors) for name in device.joints]

    def _axis_part(self, name: str, errors: list[ErrorEvent]) -> StatusPart:
        device = self.device
        mapping = device.joints[name]
        motor = device.client.motors.get(mapping.address)
        part = StatusPart(name)
        if motor is None or not motor.online:
            part.level, part.message = Level.ERROR, f'motor {mapping.address} offline'
            part.values = [('motor_address', str(mapping.address)), ('online', 'False')]
            return part
        axis_errors = [e for e in errors if e.motor_address == mapping.address]
        units = device.conversion(name)
        part.values = [
            ('motor_address', str(mapping.address)), ('online', 'True'),
            ('calibrated', str(motor.calibrated)),
            *self._units_values(mapping.units, units, motor.calibrated),
            ('begin_position', f'{units.to_si(motor.begin_position):.6g}'),
            ('end_position', f'{units.to_si(motor.end_position):.6g}'),
            ('end_position_rotations', f'{motor.end_position:.6g}'),
            ('position_rotations', f'{motor.position:.6g}'),
            ('max_setup_speed', f'{units.magnitude_to_si(motor.max_setup_speed):.6g}'),
            ('max_move_speed', f'{units.magnitude_to_si(motor.max_move_speed):.6g}'),
            ('max_acceleration', f'{units.magnitude_to_si(motor.max_acceleration):.6g}'),
            ('fiz_motor', str(motor.is_fiz)),
            *[(f'error_{e.code}', e.description) for e in axis_errors],
        ]
        if axis_errors:
            part.level = Level.ERROR
            part.message = f'error {axis_errors[-1].code}: {axis_errors[-1].description}'
        elif not motor.calibrated:
            part.level = Level.WARN
            part.message = 'not calibrated (no playback, uncalibrated travel)'
        else:
            part.message = 'calibrated'
        return part

    @staticmethod
    def _units_values(parameters: JointUnits, units: Conversion,
                      calibrated: bool) -> list[tuple[str, str]]:
        """``units`` (``motor radians`` when neither a span nor a joint scale applies: level
        OK, the README says what to set), the SI per rotation in use and the offset."""
        values = [('units', units.describe()), ('si_per_rotation', f'{units.per_rotation:.6g}'),
                  ('offset', f'{units.offset:.6g}')]
        if parameters.span:
            values.append(('calibrated_span', f'{parameters.span:.6g}' if calibrated else
                           f'{parameters.span:.6g} (applies once the axis is calibrated)'))
        return values

    def mode(self) -> str:
        client = self.device.client
        mode = client.device_info.playback_mode if client.device_info else 0
        try:
            mode_name = PlaybackMode(mode).name.lower()
        except ValueError:
            mode_name = str(mode)
        return f'{mode_name}/{playback_state_name(client.playback.status)}'

    def errors(self) -> list[str]:
        return [f'{e.code}: {e.description}' for e in self._device_wide(self.latched())]

    def axis_details(self, joint: str) -> dict[str, object]:
        """calibrated/homed (kOS: the begin and end marks are set), the motor's latched
        errors, and the state DISABLED (offline), FAULT or PLAYBACK."""
        device = self.device
        address = device.joints[joint].address
        motor = device.client.motors.get(address)
        if motor is None:
            return {'state': AxisStateCode.DISABLED}
        errors = [ERROR_CODES[e.code].description if e.code in ERROR_CODES else
                  f'error {e.code}' for e in self.latched() if e.motor_address == address]
        details: dict[str, object] = {'calibrated': motor.calibrated,
                                      'homed': motor.calibrated, 'active_errors': errors}
        if not motor.online:
            details['state'] = AxisStateCode.DISABLED
        elif errors:
            details['state'] = AxisStateCode.FAULT
        elif device.client.playback_running:
            details['state'] = AxisStateCode.PLAYBACK
        return details
