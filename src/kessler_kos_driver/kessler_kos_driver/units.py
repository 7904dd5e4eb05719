"""SI <-> motor rotations for one kOS joint: the driver's one unit rule (pure Python, no ROS).

The kOS device counts **motor rotations** (document "Units": positions, begin and end marks
in rotations, speeds in rotations/s) and says nothing of the gears, belts or lead screws
between a motor and its joint; its MaxMax speeds (165 rotations/s, 9,900 rpm) are those of a
motor shaft. So the SI value of a joint comes from what the user measured on the rig
(docs/interface.md and the Kessler manual, "Units and joints"):

* a calibrated axis with a span: ``offset + rotations * span / end_position``. ``span``
  (``calibrated_spans``) is how far the joint moves from the begin mark to the end mark,
  signed in the joint's own REP-103 direction ("1.20 m of rail", "+90 deg of pan");
  ``end_position`` is the end mark the device reports, in rotations (its begin mark is 0
  once calibrated: document "MarkBeginPosition", "Calibration"), so the sign of the motor's
  count never has to be known;
* otherwise (no span, or the axis is not calibrated): ``offset + rotations * scale``
  (``joint_scales``, SI per rotation, default 2*pi: motor-shaft radians, not the joint).

``offset`` (``joint_offsets``) is the SI value at rotation 0, the begin mark.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

#: the default joint_scales: one motor revolution per rotation, i.e. motor-shaft radians
MOTOR_RADIANS_PER_ROTATION = 2.0 * math.pi
#: the diagnostics ``units`` value of an axis that reports motor-shaft radians
MOTOR_RADIANS = 'motor radians'


@dataclass(frozen=True)
class Conversion:
    """SI = offset + rotations * per_rotation, for one joint at one calibration."""

    per_rotation: float   # SI per rotation; negative when the motor counts against REP-103
    offset: float         # SI at rotation 0 (the begin mark)
    from_span: bool       # calibrated_spans applies (else joint_scales)

    def to_si(self, rotations: float) -> float:
        return self.offset + rotations * self.per_rotation

    def to_rotations(self, si: float) -> float:
        return (si - self.offset) / self.per_rotation

    def rate_to_si(self, rotations_per_s: float) -> float:
        """A signed velocity (no offset)."""
        return rotations_per_s * self.per_rotation

    def rate_to_rotations(self, si_per_s: float) -> float:
        return si_per_s / self.per_rotation

    def magnitude_to_si(self, rotations: float) -> float:
        """A speed or acceleration limit, without direction."""
        return rotations * abs(self.per_rotation)

    @property
    def motor_radians(self) -> bool:
        """The joint reports motor-shaft radians: no span applies and the scale is 2*pi."""
        return not self.from_span and math.isclose(abs(self.per_rotation),
                                                   MOTOR_RADIANS_PER_ROTATION, rel_tol=1e-9)

    def describe(self) -> str:
        """The diagnostics ``units`` value."""
        if self.motor_radians:
            return MOTOR_RADIANS
        return 'SI (calibrated_spans)' if self.from_span else 'SI (joint_scales)'


@dataclass(frozen=True)
class JointUnits:
    """One joint's unit parameters."""

    span: float = 0.0                               # SI begin -> end mark; 0 = no span
    offset: float = 0.0                             # SI at the begin mark
    scale: float = MOTOR_RADIANS_PER_ROTATION       # SI per rotation without a span

    def conversion(self, end_position: float) -> Conversion:
        """The conversion at this calibration (``end_position`` 0: not calibrated)."""
        if self.span and end_position:
            return Conversion(self.span / end_position, self.offset, True)
        return Conversion(self.scale, self.offset, False)


def joint_units(
    joint_count: int, spans: Sequence[float], offsets: Sequence[float], scales: Sequence[float]
) -> list[JointUnits]:
    """The per-joint units from the three parameters; ValueError names the bad one."""
    checks = (('joint_scales', scales, 'finite non-zero values'),
              ('calibrated_spans', spans, 'finite values (0 = no span for that joint)'),
              ('joint_offsets', offsets, 'finite values'))
    for name, values, what in checks:
        values = list(values)
        zero_allowed = name != 'joint_scales'
        if len(values) != joint_count or not all(
                math.isfinite(v) and (zero_allowed or v != 0.0) for v in values):
            raise ValueError(f'parameter {name}: need {joint_count} {what}, one per joint, '
                             f'got {values}')
    return [JointUnits(span, offset, scale)
            for span, offset, scale in zip(spans, offsets, scales, strict=True)]
