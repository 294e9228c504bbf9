"""Does the estimate's distance scale agree with the fixes? A check that no estimator can bend.

With a weak speed reference (0.5 m GPS at 2 Hz) the paper's EKF update
(EKFOptions.encoder_scale_gain) overestimates ticks per metre by up to 14 %,
7 of its own sigmas, and so did isam2 and
fixed-lag (6 %) before their walks were taken in wheel-speed units
(benchmarks/results/weak_gps.md): a Gaussian random walk on the speeds is
cheapest when the speeds are small, and the encoder model lets the scale
factors pay for that. Every residual the estimator keeps looks fine, because
the estimator chose them. The fixes themselves say otherwise, and the wheels
can be asked directly:

the wheels' antenna path, dead-reckoned with the estimate's final scale
factors (timing.wheel_antenna), is cut into windows (10 to 160 s:
WINDOWS) outside the slips the estimate found (holdout.slip_spans), and each window's fixes
are fitted with a rotation, a translation and one scale ``s`` common to all
windows (a pooled Procrustes fit with scale). ``s`` is the factor by which
the fixes find the path longer than the estimate's wheel scale makes it: an
estimate whose ticks/m are 14 % too large gives s = 1.14. Its sigma is the
larger of the fit's own (the residual scatter measured, so a wrong GPS sigma
in robot.toml does not matter) and the spread of the windows' own scales
(which also holds when the fixes' errors persist within a window).

The estimate is flagged when s is more than DISAGREE sigmas
(PathScale.sigma_difference: the check and the estimate read the same
fixes) and more than MIN_REL from 1. Measured (benchmarks/weak_gps.py and
the tests): the shrunk EKF of the paper scenario is flagged, and so were
isam2 and fixed-lag with plain walks (2 of 3 seeds each); batch on the same
logs, and every estimator on the OptiOdom runs and on the simulated
scenarios with their own GPS, are not.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph import state as S
from odomgraph.analysis.holdout import _windows

#: Window lengths [s] tried; the one with the smallest sigma is used (longer
#: windows see more of the path's size, until the dead reckoning's own drift
#: inside them adds more scatter than the extent gains), and the fewest fixes
#: a window is used with. Taking the smallest of five sigmas errs small, so
#: the check flags somewhat more often than DISAGREE alone says; MIN_REL and
#: MODEL_SIGMA are what keep right estimates on precise fixes unflagged.
WINDOWS = (10.0, 20.0, 40.0, 80.0, 160.0)
MIN_FIXES = 5
#: Fewest windows the pooled scale is judged from (the spread needs a few).
MIN_WINDOWS = 3
#: A disagreement must exceed this many combined sigmas...
DISAGREE = 3.5
#: ...and this relative size (the dead reckoning's own interpolation and the
#: lever arm's small-angle effects are below it).
MIN_REL = 0.005
#: Fixes beyond this many robust sigmas of the first fit are left out (an outlier is not scale).
OUTLIER = 4.0
#: Relative 1-sigma added to the check's own in quadrature: the dead
#: reckoning's interpolation between wheel rows and its model error. With
#: precise fixes the fit alone claims 0.05 %, and a probe measured the
#: check 0.1-0.25 % off on right estimates.
MODEL_SIGMA = 0.0015


@dataclass(frozen=True)
class PathScale:
    """The fixes' verdict on the estimate's distance scale."""
    s: float
    """Factor [-] by which the fixes find the path longer than the estimate's scale factors make it."""
    sigma: float
    """Its 1-sigma [-]."""
    sigma_estimate: float
    """The estimate's own 1-sigma of its common (mean ticks/m) scale [-]."""
    windows: int
    fixes: int
    window: float
    """The window length [s] used."""

    @property
    def z(self) -> float:
        """|s - 1| in combined sigmas."""
        return abs(self.s - 1.0) / max(self.sigma_difference, 1e-12)

    @property
    def sigma_difference(self) -> float:
        """1-sigma of s - 1 for an estimate that is right and as honest as it
        says. Both read the same fixes, so their errors are not independent:
        for an efficient estimate the difference's variance is the check's
        minus the estimate's (Hausman), and where the check is the more
        precise of the two (a filter with good fixes), the estimate's minus
        the check's. Floored at half the larger sigma: neither is the
        efficient estimate, so the difference never vanishes (a probe: an
        EKF 1.3 of its sigmas off was flagged at z 3.8 under a floor of half
        the combined sigma)."""
        return float(np.sqrt(max(abs(self.sigma**2 - self.sigma_estimate**2),
                                 0.25 * max(self.sigma, self.sigma_estimate) ** 2)))

    @property
    def disagrees(self) -> bool:
        return self.z > DISAGREE and abs(self.s - 1.0) > MIN_REL


def path_scale(est, log) -> PathScale | None:
    """The pooled windowed scale of the fixes against ``est``'s wheel path
    (module docstring), or None: no GPS, too few usable windows, or no path."""
    from odomgraph.analysis.holdout import slip_spans
    from odomgraph.analysis.timing import wheel_antenna
    from odomgraph.errors import OdomgraphError
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    g = log.gps
    if g is None or len(g.t) < MIN_WINDOWS * MIN_FIXES or len(est.t) < 2:
        return None
    k = est.mean[-1, S.SCALE]
    if not np.all(np.isfinite(k)):
        return None
    try:
        t_dr, a_dr = wheel_antenna(log, tuple(float(v) for v in k))
    except OdomgraphError:      # a log the dead reckoning cannot run on: nothing to check against
        return None
    keep = (g.t >= max(est.t[0], t_dr[0])) & (g.t <= min(est.t[-1], t_dr[-1]))
    held = est.held_out.get("gps") if est.held_out else None
    if held is not None and np.size(held):
        keep &= ~np.isin(g.t, held)
    sig = g.sigma if g.sigma is not None else np.full(len(g.t), log.robot.gps_sigma)
    keep &= np.isfinite(sig) & (sig > 0)
    best = None
    for window in WINDOWS:
        fit = _fit_windows(g, keep, sig, t_dr, a_dr, float(est.t[0]), float(est.t[-1]), window, slip_spans(est))
        if fit is not None and (best is None or fit[1] < best[1]):
            best = fit
    if best is None:
        return None
    s, sigma, n_win, n_fix, window = best
    sigma = float(np.hypot(sigma, MODEL_SIGMA))
    C = est.scale_cov()
    c = np.array([0.5, 0.5, 0.0])
    var_est = float(c @ C @ c)
    if not np.isfinite(var_est):
        return None
    sig_est = float(np.sqrt(max(var_est, 0.0)))
    k_mean = 0.5 * (k[0] + k[1])
    return PathScale(s=float(s), sigma=float(sigma), sigma_estimate=sig_est / max(k_mean, 1e-9),
                     windows=n_win, fixes=n_fix, window=window)


def _fit_windows(g, keep, sig, t_dr, a_dr, t0: float, t1: float, window: float, skip):
    """(s, sigma_s, windows, fixes, window) of the pooled fit over windows of
    about ``window`` seconds, or None with fewer than MIN_WINDOWS usable."""
    wins = []
    for a, b in _windows(t0, t1, window, skip):
        sel = keep & (g.t >= a) & (g.t <= b)
        if sel.sum() < MIN_FIXES:
            continue
        tf = g.t[sel]
        d = np.stack([np.interp(tf, t_dr, a_dr[:, 0]), np.interp(tf, t_dr, a_dr[:, 1])], -1)
        p = np.stack([g.x[sel], g.y[sel]], -1)
        wins.append((d, p, 1.0 / sig[sel] ** 2))
    if len(wins) < MIN_WINDOWS:
        return None
    fit = _pooled(wins)
    if fit is None:
        return None
    # Second pass without the fixes the first fit calls outliers.
    u = np.concatenate(fit[2])
    # u are 2-D residual norms: their median is 1.1774 sigma (Rayleigh)
    cap = OUTLIER * max(float(np.median(u)) / 1.1774, 1e-12)
    wins = [(d[m], p[m], w[m]) for (d, p, w), r in zip(wins, fit[2]) for m in [np.abs(r) <= cap]
            if m.sum() >= MIN_FIXES]
    if len(wins) < MIN_WINDOWS:
        return None
    fit = _pooled(wins)
    if fit is None:
        return None
    return fit[0], fit[1], len(wins), int(sum(len(w) for _, _, w in wins)), window


def _pooled(wins):
    """(s, sigma_s, per-window whitened residual norms) of the pooled fit
    p ~ s R_w d + c_w over windows of (d (n, 2), p (n, 2), weights (n,)), or
    None when the path has no extent."""
    num = den = 0.0
    parts = []
    for d, p, w in wins:
        wn = w / w.sum()
        dc, pc = d - wn @ d, p - wn @ p
        cross = float(np.sum(w * (dc[:, 0] * pc[:, 1] - dc[:, 1] * pc[:, 0])))
        dot = float(np.sum(w * (dc[:, 0] * pc[:, 0] + dc[:, 1] * pc[:, 1])))
        phi = np.arctan2(cross, dot)
        cs, sn = np.cos(phi), np.sin(phi)
        rd = np.stack([cs * dc[:, 0] - sn * dc[:, 1], sn * dc[:, 0] + cs * dc[:, 1]], -1)
        n_w, d_w = float(np.sum(w[:, None] * rd * pc)), float(np.sum(w[:, None] * rd**2))
        parts.append((rd, pc, w, n_w, d_w))
        num += n_w
        den += d_w
    if den <= 0:
        return None
    s = num / den
    sse, n, res = 0.0, 0, []
    for rd, pc, w, _, _ in parts:
        r = pc - s * rd
        sse += float(np.sum(w[:, None] * r**2))
        n += len(w)
        res.append(np.sqrt(w) * np.hypot(r[:, 0], r[:, 1]))
    dof = 2 * n - 3 * len(parts) - 1
    if dof <= 0:
        return None
    # The fit's own variance, with the residual scatter measured (a wrong
    # configured sigma cancels), and the windows' spread around the pool
    # (which holds when errors persist inside a window); the larger counts.
    var_fit = (sse / dof) / den
    s_w = np.array([n_w / d_w if d_w > 0 else s for _, _, _, n_w, d_w in parts])
    d_ws = np.array([d_w for *_, d_w in parts])
    var_spread = float(np.sum(d_ws**2 * (s_w - s) ** 2)) / den**2 * len(parts) / (len(parts) - 1)
    return s, float(np.sqrt(max(var_fit, var_spread))), res


def path_scale_warnings(est, log) -> list[str]:
    """One line when the fixes and ``est``'s scale factors disagree on the
    distance travelled (PathScale.disagrees), else []."""
    ps = path_scale(est, log)
    if ps is None or not ps.disagrees:
        return []
    longer = ps.s > 1.0
    why = ("the speed has likely shrunk against a weak speed reference (README, Known limitations)" if longer
           else "the speed is too large: the scale factors (ticks/m) came out too small")
    advice = "more or better fixes" if est.method == "batch" else "try --method batch, or more or better fixes"
    return [f"{est.method}: the fixes find the path {abs(ps.s - 1.0):.1%} (+- {ps.sigma:.1%}) "
            f"{'longer' if longer else 'shorter'} than the estimate's scale factors make it ({ps.windows} windows of "
            f"{ps.window:g} s, {ps.fixes} fixes; the estimate claims its common scale to +- "
            f"{ps.sigma_estimate:.1%}): {why}; {advice}"]
