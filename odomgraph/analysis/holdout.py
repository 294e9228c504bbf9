"""Do the calibrated parameters predict data they were not fitted to?

``calibrate`` fits its scale factors on the first TRAIN_SHARE of the log and
scores them here on the rest, against the nominal parameters, before it
writes anything (issue 12: a track width 20 % off was written with a tight
sigma and no warning). The scores need no estimator, so neither parameter
set is favoured by the fit's own start or state:

- **fixes**: the wheels' own path (dead reckoning with the given scale
  factors, GPS lever arm applied) over WINDOW-second windows that hold no
  slip (by the full-log estimate: slip bends the path whatever the
  parameters), each moved by
  the rigid map that best fits that window's fixes (analysis.timing uses the
  same fit). Wrong scale factors bend and stretch the path, which no rigid
  map undoes; the score is the RMS fix residual [m].
- **gyro** (no fixes): the wheels' yaw rate against the gyro, a constant bias
  fitted for each parameter set; the score is the RMS rate residual [rad/s].
  It judges the left/right ratio and the track, which is all a gyro can.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Share of the log (by time) the parameters are fitted on; the rest is held out.
TRAIN_SHARE = 0.7
#: Window [s] of the fix score, and the fewest fixes a window is scored with.
WINDOW = 10.0
MIN_FIXES = 5
#: Calibrated parameters pass when their held-out score is at most this
#: multiple of the nominal one (noise makes equal parameters differ slightly).
TOLERANCE = 1.02


@dataclass(frozen=True)
class HeldOut:
    """One held-out comparison."""
    kind: str
    """"fixes" (score in m) or "gyro" (score in rad/s)."""
    t0: float
    t1: float
    """The held-out span [s]."""
    nominal: float
    calibrated: float
    """The score of each parameter set (smaller is better)."""
    n: int
    """Measurements scored."""

    @property
    def unit(self) -> str:
        return "m" if self.kind == "fixes" else "rad/s"

    @property
    def passed(self) -> bool:
        return self.calibrated <= TOLERANCE * self.nominal

    def text(self) -> str:
        what = "fix residual RMS" if self.kind == "fixes" else "gyro-vs-wheels yaw-rate RMS"
        return (f"held-out {what} over t={self.t0:.0f}-{self.t1:.0f} s ({self.n} {'fixes' if self.kind == 'fixes' else 'gyro samples'}): "
                f"nominal {self.nominal:.4g} {self.unit}, calibrated {self.calibrated:.4g} {self.unit}")


def split_time(log) -> float | None:
    """The time [s] the training part ends at: TRAIN_SHARE of the span in
    which the absolute sensor (or the gyro, without one) overlaps the wheels;
    None: too little. The overlap, not the sensor's own span: a bag whose GPS
    and IMU ran 150 s before the wheel driver started put the split before
    the first wheel row (a hostile probe: an IndexError in calibrate)."""
    wheels = log.encoders if log.encoders is not None else log.wheel_speeds
    if wheels is None or len(wheels.t) < 2:
        return None
    for s in (log.gps, log.gyro):
        if s is None or len(s.t) < 2 * MIN_FIXES:
            continue
        a, b = max(s.t[0], wheels.t[0]), min(s.t[-1], wheels.t[-1])
        inside = (s.t >= a) & (s.t <= b)
        if inside.sum() >= 2 * MIN_FIXES:
            t = s.t[inside]
            return float(t[0] + TRAIN_SHARE * (t[-1] - t[0]))
    return None


def score_fixes(log, scales, t0: float, t1: float, window: float = WINDOW, skip=()) -> tuple[float, int] | None:
    """(RMS rigid-window fix residual [m], fixes scored) over [t0, t1] in
    windows of about ``window`` seconds, or None. Windows that overlap a
    ``skip`` span (t_a, t_b) are left out: a slip bends the wheels' path
    whatever the parameters, and would decide the contest by itself."""
    from odomgraph.analysis.timing import rigid_misfit, wheel_antenna
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    g = log.gps
    if g is None or len(g.t) < MIN_FIXES:
        return None
    t_dr, a_dr = wheel_antenna(log, tuple(scales))
    inside = (g.t >= max(t0, t_dr[0])) & (g.t <= min(t1, t_dr[-1]))
    if inside.sum() < MIN_FIXES:
        return None
    sse, n = 0.0, 0
    for a, b in _windows(t0, t1, window, skip):
        sel = inside & (g.t >= a) & (g.t <= b)
        if sel.sum() < MIN_FIXES:
            continue
        tf = g.t[sel]
        d = np.stack([np.interp(tf, t_dr, a_dr[:, 0]), np.interp(tf, t_dr, a_dr[:, 1])], -1)
        p = np.stack([g.x[sel], g.y[sel]], -1)
        # Equal weights: the score is a distance, and the comparison is the same for both sets.
        sse += rigid_misfit(d, p, np.ones(len(tf)))
        n += int(sel.sum())
    return (float(np.sqrt(sse / n)), n) if n else None


def _windows(t0: float, t1: float, window: float, skip=()) -> list[tuple[float, float]]:
    """Windows of about ``window`` seconds covering [t0, t1] outside the
    ``skip`` spans: each slip-free stretch of at least half a window is cut
    into equal windows."""
    free, a = [], t0
    for sa, sb in sorted(skip):
        if sb <= a or sa >= t1:
            continue
        if sa > a:
            free.append((a, sa))
        a = max(a, sb)
    if a < t1:
        free.append((a, t1))
    out = []
    for a, b in free:
        if b - a < 0.5 * window:
            continue
        n = max(1, int(round((b - a) / window)))
        edges = np.linspace(a, b, n + 1)
        out += list(zip(edges[:-1], edges[1:]))
    return out


def score_gyro(log, scales, t0: float, t1: float, skip=()) -> tuple[float, int] | None:
    """(RMS of gyro minus the wheels' yaw rate, a bias removed [rad/s], samples)
    over [t0, t1] outside the ``skip`` spans, or None."""
    rate = wheel_yaw_rate_at_gyro(log, scales)
    if rate is None:
        return None
    t, g, w = rate
    sel = (t >= t0) & (t <= t1)
    for sa, sb in skip:
        sel &= ~((t >= sa) & (t <= sb))
    if sel.sum() < MIN_FIXES:
        return None
    r = g[sel] - w[sel]
    r = r - np.median(r)
    return float(np.sqrt(np.mean(r**2))), int(sel.sum())


def wheel_yaw_rate_at_gyro(log, scales=(1.0, 1.0, 1.0)):
    """(gyro times, gyro rate, the wheels' yaw rate there) [s, rad/s, rad/s],
    within the span the wheels cover; None without a gyro or wheels."""
    from odomgraph.factors.encoder import body_velocity
    from odomgraph.estimators.measurements import from_log
    if log.gyro is None or len(log.gyro.t) < 2:
        return None
    w = from_log(log).wheel
    _, om = body_velocity(w.m[:, 0], w.m[:, 1], 0.0, 0.0, *scales, log.robot.track_width)
    # Encoder speeds are interval means: they stand for the interval's middle.
    tw = w.t if w.dt is None else w.t - 0.5 * w.dt
    gt = log.gyro.t
    keep = (gt >= tw[0]) & (gt <= tw[-1])
    if keep.sum() < 2:
        return None
    return gt[keep], log.gyro.omega[keep], np.interp(gt[keep], tw, om)


def slip_spans(est, n_sigma: float = 3.0, floor: float = 0.02, pad: float = 1.0) -> list[tuple[float, float]]:
    """The spans [s] where ``est`` finds a wheel slipping (|slip| above
    n_sigma of its sigma and ``floor`` m/s), each widened by ``pad`` seconds."""
    from odomgraph import state as S
    sl = np.abs(est.mean[:, S.SLIP])
    sig = est.sigma[:, S.SLIP] if est.sigma is not None else np.zeros_like(sl)
    on = np.any((sl > n_sigma * sig) & (sl > floor), axis=1)
    spans, start = [], None
    for t, o in zip(est.t, on):
        if o and start is None:
            start = t
        elif not o and start is not None:
            spans.append((start - pad, t + pad))
            start = None
    if start is not None:
        spans.append((start - pad, est.t[-1] + pad))
    return spans


def held_out(log, nominal, calibrated, t0: float, skip=()) -> HeldOut | None:
    """Score both scale-factor triples on the log after ``t0`` outside the
    ``skip`` spans (slip_spans): on the fixes when there are enough, else on
    the gyro; None when neither can be scored."""
    t1 = log.t_end
    for kind, score in (("fixes", score_fixes), ("gyro", score_gyro)):
        use = skip
        a = score(log, nominal, t0, t1, skip=use)
        if a is None and skip:
            # Slip over the whole held-out part is the fit failing (a late GPS
            # makes it see slip everywhere), not a reason to skip the fixes.
            use = ()
            a = score(log, nominal, t0, t1, skip=use)
        if a is None:
            continue
        b = score(log, calibrated, t0, t1, skip=use)
        return HeldOut(kind, t0, t1, a[0], b[0], a[1])
    return None
