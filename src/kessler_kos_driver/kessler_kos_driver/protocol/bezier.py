"""Cubic Bezier segments in the device's normalised (time, position) space, and a keyframe
fitter.

The device plays, per axis, a chain of cubic Beziers whose control points are (time, position)
pairs, both normalised: time as a fraction of the move duration, position as a fraction of the
calibrated range (0 = BeginPosition, 1 = EndPosition).

Fitting (keyframes -> segments) is a cubic Hermite spline written as Beziers: the time control
points are spaced at thirds (time is then linear in the curve parameter, so position is a
function of time), and the position control points are P1 = y0 + m0*h/3, P2 = y1 - m1*h/3.
Tangents without user velocities follow Fritsch-Carlson/PCHIP (monotone, |m| <= 3*secant), which
keeps P1 and P2 between the two keyframes: the curve cannot overshoot a keyframe, let alone the
calibrated range. The move starts and ends at rest. User velocities are honoured but clamped so
P1 and P2 stay inside [0, 1] (a Bezier stays inside the hull of its control points).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .errors import TrajectoryError

Quad = tuple[float, float, float, float]
SegmentPoints = tuple[Quad, Quad]      # (times, positions)
_SAMPLES = 48


def _cubic(c: Sequence[float], u: float) -> float:
    v = 1.0 - u
    return v * v * v * c[0] + 3 * v * v * u * c[1] + 3 * v * u * u * c[2] + u * u * u * c[3]


def _d1(c: Sequence[float], u: float) -> float:
    v = 1.0 - u
    return 3 * (v * v * (c[1] - c[0]) + 2 * v * u * (c[2] - c[1]) + u * u * (c[3] - c[2]))


def _d2(c: Sequence[float], u: float) -> float:
    return 6 * ((1.0 - u) * (c[2] - 2 * c[1] + c[0]) + u * (c[3] - 2 * c[2] + c[1]))


def evaluate(times: Sequence[float], positions: Sequence[float], u: float) -> tuple[float, float]:
    """Point of the segment at curve parameter u in [0, 1]."""
    return _cubic(times, u), _cubic(positions, u)


def parameter_at_time(times: Sequence[float], t: float) -> float:
    """Curve parameter where the (monotone) time polynomial equals t, by bisection."""
    if t <= times[0]:
        return 0.0
    if t >= times[3]:
        return 1.0
    lo, hi = 0.0, 1.0
    for _ in range(48):
        mid = 0.5 * (lo + hi)
        if _cubic(times, mid) < t:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def position_at(segments: Sequence[SegmentPoints], t: float) -> float:
    """Normalised position of a segment chain at normalised time t (clamped to 0..1)."""
    if not segments:
        raise TrajectoryError('no segments')
    t = min(max(t, 0.0), 1.0)
    for times, positions in segments:
        if t <= times[3]:
            return _cubic(positions, parameter_at_time(times, t))
    times, positions = segments[-1]
    return positions[3]


def segment_peak_rates(times: Sequence[float], positions: Sequence[float]) -> tuple[float, float]:
    """Peak |dp/dt| and |d2p/dt2| of one segment in normalised units (sampled)."""
    peak_v = peak_a = 0.0
    for i in range(_SAMPLES + 1):
        u = min(max(i / _SAMPLES, 1e-4), 1 - 1e-4)
        dt, dp = _d1(times, u), _d1(positions, u)
        if dt <= 1e-9:
            if abs(dp) > 1e-9:
                return math.inf, math.inf   # vertical: position jumps in zero time
            continue
        ddt, ddp = _d2(times, u), _d2(positions, u)
        peak_v = max(peak_v, abs(dp / dt))
        peak_a = max(peak_a, abs((ddp * dt - dp * ddt) / dt**3))
    return peak_v, peak_a


def _pchip_tangents(times: Sequence[float], values: Sequence[float]) -> list[float]:
    n = len(times)
    h = [times[k + 1] - times[k] for k in range(n - 1)]
    d = [(values[k + 1] - values[k]) / h[k] for k in range(n - 1)]
    m = [0.0] * n
    for k in range(1, n - 1):
        if d[k - 1] * d[k] <= 0:
            continue
        w1 = 2 * h[k] + h[k - 1]
        w2 = h[k] + 2 * h[k - 1]
        m[k] = (w1 + w2) / (w1 / d[k - 1] + w2 / d[k])
    return m


def fit_keyframes(
    times: Sequence[float],
    positions: Sequence[float],
    velocities: Sequence[float] | None = None,
) -> list[SegmentPoints]:
    """Bezier segments through normalised keyframes.

    times: strictly increasing, within [0, 1]; positions within [0, 1]; velocities (optional)
    in normalised position per normalised time. A hold segment is added before the first
    keyframe if it is after 0, and after the last if it is before 1.
    """
    if len(times) != len(positions) or not times:
        raise TrajectoryError('keyframes need one position per time, and at least one')
    if velocities is not None and len(velocities) != len(times):
        raise TrajectoryError('velocities must be empty or one per keyframe')
    for k, (t, p) in enumerate(zip(times, positions, strict=True)):
        if not (math.isfinite(t) and math.isfinite(p)):
            raise TrajectoryError(f'keyframe {k}: time and position must be finite')
        if not 0.0 <= t <= 1.0:
            raise TrajectoryError(f'keyframe {k}: time {t:.6g} is outside the move (0..1)')
        if not 0.0 <= p <= 1.0:
            raise TrajectoryError(
                f'keyframe {k}: position {p:.6g} is outside the calibrated range (0..1)'
            )
        if k and t <= times[k - 1]:
            raise TrajectoryError(f'keyframe {k}: times must be strictly increasing')
    ts, ps = list(times), list(positions)
    vs = list(velocities) if velocities is not None else None
    if ts[0] > 0.0:
        ts.insert(0, 0.0)
        ps.insert(0, ps[0])
        if vs is not None:
            vs.insert(0, 0.0)
    if ts[-1] < 1.0:
        ts.append(1.0)
        ps.append(ps[-1])
        if vs is not None:
            vs.append(0.0)
    if len(ts) == 1:  # single keyframe exactly at 0 and 1 cannot happen; guard anyway
        raise TrajectoryError('a move needs keyframes spanning time 0..1')
    tangents = vs if vs is not None else _pchip_tangents(ts, ps)
    segments: list[SegmentPoints] = []
    for k in range(len(ts) - 1):
        t0, t1 = ts[k], ts[k + 1]
        y0, y1 = ps[k], ps[k + 1]
        h = t1 - t0
        p1 = min(max(y0 + tangents[k] * h / 3.0, 0.0), 1.0)
        p2 = min(max(y1 - tangents[k + 1] * h / 3.0, 0.0), 1.0)
        segments.append(((t0, t0 + h / 3.0, t1 - h / 3.0, t1), (y0, p1, p2, y1)))
    return segments
