"""A gap in the fixes that the wheels slipped in: when, the log cannot say.

Between two fixes far apart (a GPS outage, a beacon out of sight) only the
wheels and the gyro speak. If the fixes after the gap say the robot went
less far than its wheels turned, the wheels slipped in the gap (a stall: held
against a drift, both wheels spinning), but the gyro cannot say when: both
wheels spinning together turn nothing. A smoother puts that slip where its
prior likes it best (the sparse slip prior: all at once, anywhere), and the
positions inside the gap are then off by up to the slip's distance along
the track, at the sigma of a robot whose slip is known. A hostile probe's
yard log (a 10 s stall inside a 14 s GPS outage) had batch 0.5-1.2 m off at
sigma 1-4 cm (z 58), status ok.

``widen_gaps`` gives the rows inside each such gap the variance of that
unknown timing, in x and in y: D^2 f (1 - f), D the common-mode slip
distance the estimate puts in the gap and f the row's fraction of it (a
Brownian bridge: nothing at the fixes either side, sigma D/2 mid-gap). Rows of a
whole-log smoother only (batch, isam2's smoothed states): a causal row
cannot know yet how the gap ends.
"""
from __future__ import annotations

import numpy as np

from odomgraph import state as S

#: A gap is at least this long [s] and GAP_INTERVALS median fix intervals...
MIN_GAP = 2.0
GAP_INTERVALS = 3.0
#: ...and the slip distance in it at least this [m] to count.
MIN_DISTANCE = 0.05


def fix_times(meas) -> np.ndarray:
    """Sorted times [s] of the absolute fixes (GPS and ranges) in
    ``meas`` (estimators.measurements.Measurements); empty without any."""
    ts = [m[0] for m in (meas.gps, meas.ranges) if m is not None and len(m[0])]
    return np.unique(np.concatenate(ts)) if ts else np.zeros(0)


def gaps(fix_t: np.ndarray) -> list[tuple[float, float]]:
    """(start, end) [s] of the gaps between consecutive fixes longer than
    MIN_GAP and GAP_INTERVALS median intervals."""
    if len(fix_t) < 3:
        return []
    d = np.diff(fix_t)
    long = np.flatnonzero(d > max(MIN_GAP, GAP_INTERVALS * float(np.median(d))))
    return [(float(fix_t[i]), float(fix_t[i + 1])) for i in long]


def widen_gaps(t: np.ndarray, mean: np.ndarray, sigma: np.ndarray, pose_cov: np.ndarray | None,
               fix_t: np.ndarray) -> list[tuple[float, float, float]]:
    """Rows t (N,) [s], mean and sigma (N, 11), pose_cov (N, 3, 3) or None,
    widened in place (x and y) inside each gap of ``fix_t`` where
    the estimate's common-mode slip covers MIN_DISTANCE or more (module
    docstring). Returns (start, end, distance [m]) of each gap widened."""
    out = []
    for a, b in gaps(fix_t):
        sel = np.flatnonzero((t > a) & (t < b))
        if sel.size < 2:
            continue
        s_cm = 0.5 * np.abs(mean[sel][:, S.SLIP].sum(1))            # common-mode slip [m/s]
        edges = np.concatenate([[a], 0.5 * (t[sel][1:] + t[sel][:-1]), [b]])
        dist = float(np.sum(s_cm * np.diff(edges)))
        if dist < MIN_DISTANCE:
            continue
        f = (t[sel] - a) / (b - a)
        var = dist ** 2 * f * (1.0 - f)
        # In x and y alike, not only along the heading: where the path
        # curves, slip moved to another time moves the row along another
        # direction (yard, a stall in a curve: 0.14 m across the track at a
        # cross-track sigma of 0.02 m).
        sigma[sel, 0] = np.sqrt(sigma[sel, 0] ** 2 + var)
        sigma[sel, 1] = np.sqrt(sigma[sel, 1] ** 2 + var)
        if pose_cov is not None:
            pose_cov[sel, 0, 0] += var
            pose_cov[sel, 1, 1] += var
        out.append((a, b, dist))
    return out


def warning(found: list[tuple[float, float, float]], t0: float) -> list[str]:
    """The one line saying which gaps were widened, or []."""
    if not found:
        return []
    parts = ", ".join(f"t={a - t0:.1f}-{b - t0:.1f} s ({d:.2f} m)" for a, b, d in found)
    return [f"the wheels slipped inside gaps in the fixes ({parts}): when inside each gap is not known, so the "
            "positions there carry up to that distance along the track in their sigma"]
