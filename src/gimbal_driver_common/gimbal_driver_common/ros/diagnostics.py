"""Build diagnostic_msgs/DiagnosticStatus from decoded device state."""

from __future__ import annotations

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from gimbal_driver_common.diagnostics import StatusPart

__all__ = ['StatusPart', 'to_message']


def to_message(node_name: str, hardware_id: str, status: StatusPart) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=bytes([int(status.level)]),
        name=f'{node_name}: {status.part}',
        message=status.message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=str(v)) for k, v in status.values],
    )
