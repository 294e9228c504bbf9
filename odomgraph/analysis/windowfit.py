"""Slip inside the calibration window that only a fit shows.

Before anything is estimated, estimators.slipcheck compares the distance
the fixes moved, second by second, with the distance the wheels say, and
leaves out of the window (slip estimated, not forced to zero) what differs
by more than 30 % (a scale error of a few percent must stay far below). A
common-mode slip of both wheels of 0.2-0.25 m/s at about 1 m/s stays under
it, and an estimate that then holds slip at zero through it is pulled off
the fixes: a probe's yard logs had batch and isam2 0.5-0.85 m off at z
34-69 (here: 0.47 m at z 54, scale factors 7 sigma off), status ok.

After the fit the fixes say it plainly: inside the window they sit many
sigma from the estimate for seconds on end (per-second median of the
normalised distance 6-20 there; at most 1.9 anywhere on clean logs, and no
stretch found on 48 clean logs of both scenarios with GPS at 3-20 Hz and
0.02-0.2 m).
``stretches`` finds those seconds; the pipeline then runs again with them
out of the window (Schedule.slipping) and says so.
"""
from __future__ import annotations

import numpy as np

#: A second whose fixes' median distance from the estimate exceeds this many
#: sigmas (fix and row combined) is off...
U_OFF = 4.0
#: ...counted only with this many fixes in it (a median of one is a fix)...
MIN_FIXES = 3
#: ...and only in runs of this many seconds (one bad second is an outlier's).
MIN_RUN = 2
#: Stretches are widened by this much before and after [s]: slip ramps, and
#: a filter's rows drift off only after the slip began (the EKF's first
#: stretch on a probe's log started 3 s after the slip did).
PAD_BEFORE = 3.0
PAD_AFTER = 2.0


def stretches(est, log, t_start: float, t_switch: float | None, gps_scale: float = 1.0,
              rows: bool = True) -> list[tuple[float, float]]:
    """(start, end) [s] of the stretches of the calibration window [t_start,
    t_switch) where the GPS fixes sat far from ``est`` (an Estimate of ``log``)
    for MIN_RUN seconds or more; [] without GPS or a window. ``gps_scale``:
    the factor the run widened the fixes' sigma by (noise_scales). Without
    ``rows`` the distance is measured in the fixes' sigma alone: whether the
    fixes sit off the estimate's path by more than their noise, where the
    rows' own sigma is a dead reckoning's (analysis.sideways)."""
    from odomgraph.analysis.metrics import gps_residuals, gps_times
    if t_switch is None or log.gps is None or len(est.t) < 2:
        return []
    res = gps_residuals(est, log)
    if res is None:
        return []
    t, r, sig = res
    inside = (t >= t_start) & (t < t_switch)
    if inside.sum() < MIN_FIXES * MIN_RUN:
        return []
    t, r, sig = t[inside], r[inside], sig[inside] * gps_scale
    # A fix sent again unchanged (a receiver's stale copies) is one fix, as
    # the estimators read it (measurements): copies would make one fix a median.
    tg = gps_times(log)
    xy = np.stack([log.gps.x, log.gps.y], -1)[(tg >= est.t[0]) & (tg <= est.t[-1])][inside]
    fresh = np.concatenate([[True], np.any(np.diff(xy, axis=0) != 0.0, axis=1)])
    t, r, sig = t[fresh], r[fresh], sig[fresh]
    row = np.hypot(np.interp(t, est.t, est.sigma[:, 0]), np.interp(t, est.t, est.sigma[:, 1])) if rows else 0.0
    u = np.hypot(r[:, 0], r[:, 1]) / np.sqrt(sig**2 + row**2)
    sec = np.floor(t - t_start).astype(int)
    n = np.bincount(sec)
    off = np.zeros(len(n), bool)
    for k in np.flatnonzero(n >= MIN_FIXES):
        off[k] = float(np.median(u[sec == k])) > U_OFF
    out: list[tuple[float, float]] = []
    k = 0
    while k < len(off):
        if not off[k]:
            k += 1
            continue
        j = k
        while j + 1 < len(off) and off[j + 1]:
            j += 1
        if j - k + 1 >= MIN_RUN:
            out.append((max(t_start, t_start + k - PAD_BEFORE), min(t_switch, t_start + j + 1 + PAD_AFTER)))
        k = j + 1
    return out


#: How every line of this module begins (``said``).
SAID = "inside the calibration window ("


def said(line: str) -> bool:
    """Whether a warning is one of this module's (a second look at the window)."""
    return line.startswith(SAID) and "the fixes sat more than" in line


def warning(found: list[tuple[float, float]], resolved: bool) -> str:
    """The line naming the stretches, and whether the second run took the fixes back."""
    spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in found)
    head = (f"inside the calibration window ({spans}) the fixes sat more than {U_OFF:g} sigma from the estimate "
            "for seconds on end, where it held slip at zero: the wheels slipped there (both alike, which the "
            "check before the fit cannot see)")
    if resolved:
        return head + "; estimated again with slip estimated there"
    return head + "; estimated again with slip estimated there, and the fixes still disagree; not trustworthy"


def ekf_warning(found: list[tuple[float, float]]) -> str:
    """The EKF's line: flagged, not run again (pipeline._with_window_slip)."""
    spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in found)
    return (f"inside the calibration window ({spans}) the fixes sat more than {U_OFF:g} sigma from the EKF's "
            "estimate for seconds on end, where it held slip at zero: the wheels likely slipped in the window "
            "(both alike), and the EKF's scale factors took part of it up while it happened; --method batch "
            "finds and estimates such a slip; not trustworthy")


def failed_warning(found: list[tuple[float, float]], exc: Exception) -> str:
    """The line when the run with those seconds out of the window failed."""
    spans = ", ".join(f"{a:.1f}-{b:.1f} s" for a, b in found)
    # The failure's cause, where the log shows one (a clock offset, a
    # mounting mistake: pipeline), is said on its own line from the run that
    # stands; quoted here too it was said twice with two different figures.
    why = " ".join(str(exc).split()).split("; the log shows why: ")[0]
    return (f"inside the calibration window ({spans}) the fixes sat more than {U_OFF:g} sigma from the estimate "
            f"for seconds on end, where it held slip at zero, and the run with slip estimated there failed "
            f"({why}); not trustworthy")
