"""The Capture pedestal's status report (no ROS): diagnostics parts and ~/status decoded
from the registers the last poll cached (:mod:`.protocol.registers`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from gimbal_driver_common.device import (
    AxisStateCode,
    StatusReport,
)
from gimbal_driver_common.diagnostics import ActiveFlag, Level, StatusPart

from .protocol.registers import AXIS_REGISTERS, CSR, SYSTEM_REGISTERS, SYSTEM_STATE

if TYPE_CHECKING:
    from .device import CaptureDevice

def axis_flags(registers: dict[str, int]) -> list[ActiveFlag]:
    """Active flags of one axis' polled registers (MER, DER, SRH, SRL, MSR, CMER, OPR),
    decoded from those the device reports: a register it does not answer is no flag (read
    as 0, SRL's active-low "axis_off" would refuse every move)."""
    return [a for r in AXIS_REGISTERS if r.name in registers for a in r.decode(registers[r.name])]


def system_flags(registers: dict[str, int]) -> list[ActiveFlag]:
    """Active flags of the system registers the device reports (CSR, SYS)."""
    return [a for r in SYSTEM_REGISTERS if r.name in registers
            for a in r.decode(registers[r.name])]



class CaptureStatus(StatusReport):
    """Diagnostics and ~/status from the registers the last poll cached."""

    def __init__(self, device: CaptureDevice) -> None:
        self.device = device

    def parts(self) -> list[StatusPart]:
        device = self.device
        status = device.status_snapshot()
        if not status:
            return [StatusPart('device', Level.STALE, 'no register data yet')]
        parts = []
        client = device.client
        for joint in device.joint_names:
            registers = status['axes'].get(joint)
            if registers is None:
                parts.append(StatusPart(joint, Level.STALE, 'registers unavailable'))
                continue
            values = [(f'{name}_raw', f'0x{value:04X}') for name, value in registers.items()]
            if not registers:
                values.append(('registers', 'the device reports none (see device status)'))
            current = status['current'].get(joint)
            if current is not None:
                values.append(('current_A', f'{current:.3f}'))
            values.append(('axis_id', str(device.axis(joint))))
            parts.append(StatusPart.from_flags(joint, axis_flags(registers), values))
        system = status.get('system', {})
        active = system_flags(system)
        values = [(f'{name}_raw', f'0x{value:04X}') for name, value in system.items()]
        values += [(f'error.{name}', text) for name, text in status.get('errors', {}).items()
                   if text]
        values += [(f'problem.{i}', text) for i, text in enumerate(status['problems'])]
        unsupported = dict(client.unsupported)
        values += [(f'unsupported.{name}', f'{answer}; not sent again on this connection')
                   for name, answer in unsupported.items()]
        # replies of the wrong kind, counted per command (those of unsupported ones too)
        values += [(f'wrong_reply.{name}', f'{answer} ({count}x)')
                   for name, (count, answer) in dict(client.wrong_replies).items()]
        # identity getters that failed otherwise (no reply, another NACK)
        values += [(f'identity.{name}', how) for name, how in device.identity.problems.items()
                   if name not in unsupported]
        silent = client.unanswered.silent()
        values += client.unanswered.diagnostics()
        values += [('link', client.description)] + [
            (f'link.{k}', str(v)) for k, v in client.stats.items()
        ] + [('link.garbage_bytes', str(client.garbage_bytes)),
             ('link.reads', 'batched (one write per poll)' if client.batching else
              'one request at a time' + (' (batched reads came back incomplete)'
                                         if client.batch_reads else ''))]
        part = StatusPart.from_flags('device', active, values)
        if status.get('emergency_stop'):
            part.level = max(part.level, Level.WARN)
            part.message = 'emergency stop flag set (MOT_SetEmgStopAxes 0 clears it); ' + (
                part.message)
            part.values.append(('emergency_stop', 'True'))
        texts = [t for t in status.get('errors', {}).values() if t]
        if texts:
            part.message += ' | ' + '; '.join(texts)
        if unsupported:  # informational: an optional function the device lacks
            part.message += ' | device does not know: ' + ', '.join(unsupported)
        if silent:  # the device answers the rest: named, asked again after a back-off
            part.level = max(part.level, Level.WARN)
            part.message += ' | unanswered: ' + ', '.join(
                f'{r.name} ({r.in_a_row}x)' for r in silent)
        wrong = [name for name in client.wrong_replies if name not in unsupported]
        if wrong:  # answered, but not as the protocol says: named, not called silence
            part.message += ' | wrong kind of reply from: ' + ', '.join(wrong)
        parts.append(part)
        return parts

    def mode(self) -> str:
        status = self.device.status_snapshot()
        if status.get('emergency_stop'):
            return 'emergency_stop'
        names = [a.flag.name for a in SYSTEM_STATE.decode(status.get('system', {}).get('SYS', 0))]
        return '+'.join(names) if names else 'manual'

    def axis_details(self, joint: str) -> dict[str, object]:
        status = self.device.status_snapshot()
        registers = status.get('axes', {}).get(joint)
        system = status.get('system', {})
        if registers is None:
            return {}
        active = axis_flags(registers)
        names = {a.flag.name for a in active}
        details: dict[str, object] = {
            'active_errors': sorted({a.key for a in active if a.flag.level > Level.OK}),
            'homed': not registers.get('OPR', 0) & (1 << 1),
            'calibrated': not registers.get('OPR', 0) & (1 << 1),
        }
        if 'fault' in names:
            details['state'] = AxisStateCode.FAULT
        elif 'homing_active' in names:
            details['state'] = AxisStateCode.HOMING
        elif 'axis_off' in names:
            details['state'] = AxisStateCode.DISABLED
        elif system.get('SYS', 0) & (1 << 2) and self.device.axis(joint) in (1, 2):
            details['state'] = AxisStateCode.SCANNING
        return details

    def errors(self) -> list[str]:
        status = self.device.status_snapshot()
        system = status.get('system', {})
        flags = [a.key for a in CSR.decode(system.get('CSR', 0)) if a.flag.level > Level.OK]
        return flags + [text for text in status.get('errors', {}).values() if text]
