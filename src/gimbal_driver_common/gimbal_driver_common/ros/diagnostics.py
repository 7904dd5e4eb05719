"""Build diagnostic_msgs/DiagnosticStatus from decoded device state."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue

from gimbal_driver_common.diagnostics import ActiveFlag, Level, flags_to_key_values, summarize


@dataclass
class StatusPart:
    """One DiagnosticStatus before naming: ``part`` becomes ``<node name>: <part>``."""

    part: str
    level: Level = Level.OK
    message: str = 'OK'
    values: list[tuple[str, str]] = field(default_factory=list)

    @classmethod
    def from_flags(
        cls,
        part: str,
        active: Iterable[ActiveFlag],
        extra_values: Iterable[tuple[str, str]] = (),
        ok_message: str = 'OK',
    ) -> StatusPart:
        """A status whose level and message come from decoded register flags."""
        active = list(active)
        level, message = summarize(active, ok_message)
        return cls(part, level, message, [*extra_values, *flags_to_key_values(active)])


def to_message(node_name: str, hardware_id: str, status: StatusPart) -> DiagnosticStatus:
    return DiagnosticStatus(
        level=bytes([int(status.level)]),
        name=f'{node_name}: {status.part}',
        message=status.message,
        hardware_id=hardware_id,
        values=[KeyValue(key=str(k), value=str(v)) for k, v in status.values],
    )
