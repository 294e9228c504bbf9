"""Is the GPS clock off? Its time offset against the wheels.

A fix stamped delta seconds late was taken where the antenna was delta
seconds earlier. An estimate fitted to such fixes follows them, and its own
residuals hide most of the offset; the wheels do not. Over windows of WINDOW
seconds, the wheels' own path (dead reckoning with the estimated scale
factors, lever arm applied) is moved by the rigid map that best fits the
fixes, once for each trial offset: the offset with the smallest misfit is
the window's, and a parabola through the misfits gives its sigma. Combined
over the windows they give the log's offset; windows that disagree show a
clock that jumps. (A receiver latency of 0.1-0.5 s is common;
ESTIMATION-NOTES.md: 0.3 s biased a wheel scale by 3 % with nothing flagged.)
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph import state as S
from odomgraph.factors._math import robust_sigma

#: An offset is reported when it is this many sigmas from 0, and at least MIN_OFFSET.
N_SIGMA = 5.0
MIN_OFFSET = 0.05
#: Window length [s], and the trial offsets [s].
WINDOW = 10.0
TRIALS = np.arange(-3.0, 3.0001, 0.1)
FINE = 0.02


@dataclass(frozen=True)
class Offset:
    delta: float
    """How late the stamps are [s] (positive: each fix was taken before its stamp)."""
    sigma: float
    """Its 1-sigma [s]."""
    t0: float
    t1: float
    """The span it was fitted on [s]."""

    @property
    def significant(self) -> bool:
        return abs(self.delta) > max(N_SIGMA * self.sigma, MIN_OFFSET)


def wheel_antenna(log, scales):
    """(times (K+1,), antenna positions (K+1, 2)) of dead reckoning from the
    first wheel measurement with the given scale factors."""
    t, dr = wheel_poses(log, scales)
    lx, ly = log.robot.gps_lever_arm
    c, s = np.cos(dr[:, 2]), np.sin(dr[:, 2])
    return t, np.stack([dr[:, 0] + c * lx - s * ly, dr[:, 1] + s * lx + c * ly], -1)


def wheel_poses(log, scales):
    from odomgraph.estimators.measurements import dead_reckoning, from_log
    return dead_reckoning(from_log(log), log.robot.track_width, scales)


def rigid_misfit(d, p, w):
    """Weighted rigid-fit residual sum of squares of p ~ R d + c (closed form)."""
    from odomgraph.estimators.initial import rigid_fit
    phi, c = rigid_fit(d, p, w)
    cs, sn = np.cos(phi), np.sin(phi)
    r = p - np.stack([cs * d[:, 0] - sn * d[:, 1], sn * d[:, 0] + cs * d[:, 1]], -1) - c
    return float(np.sum(w[:, None] * r**2))


class _Path:
    """The wheels' dead-reckoned poses, and the antenna on them at any time,
    for a lever arm changed by ``dl`` (robot frame) from the configured one."""

    def __init__(self, log, scales):
        self.t, self.pose = wheel_poses(log, scales)
        # Each column contiguous once: np.interp copies a strided column on
        # every call, which made the windows' many small calls O(log length)
        # each (the check took 12 s of a one-hour batch run).
        self._x, self._y, self._th = (np.ascontiguousarray(self.pose[:, i]) for i in range(3))
        self.lever = np.array(log.robot.gps_lever_arm, float)
        # The derivative is taken over a span of several wheel intervals: the
        # interpolated path has a kink at each node (a 0.02 s step saw them
        # as a misfit curvature 100x the true one).
        self.h = max(0.1, 2.0 * float(np.median(np.diff(self.t)))) if len(self.t) > 1 else 0.1

    def heading(self, t):
        return np.interp(t, self.t, self._th)

    def antenna(self, t, dl=(0.0, 0.0)):
        lx, ly = self.lever + np.asarray(dl, float)
        th = self.heading(t)
        c, s = np.cos(th), np.sin(th)
        return np.stack([np.interp(t, self.t, self._x) + c * lx - s * ly,
                         np.interp(t, self.t, self._y) + s * lx + c * ly], -1)

    def velocity(self, t, dl=(0.0, 0.0)):
        return (self.antenna(t + self.h, dl) - self.antenna(t - self.h, dl)) / (2.0 * self.h)


def _window_system(path: _Path, tf, p, w, delta: float, dl=(0.0, 0.0)):
    """The window's fixes against the wheels' antenna path shifted by
    ``delta``, the rigid map fitted out: (A (2n, 3), r (2n,), chi2, dof) with
    r the whitened residual and A its derivative against (delta, lever x,
    lever y), both projected off the rigid map's tangent space (a change of
    the parameters that the window's rotation and translation absorb tells
    nothing), so that r ~ A (change) + noise; A.T A is the window's Fisher
    information. dof counts the rigid map and the offset only."""
    from odomgraph.estimators.initial import rigid_fit
    ts = tf - delta
    d = path.antenna(ts, dl)
    phi, c = rigid_fit(d, p, w)
    R = np.array([[np.cos(phi), -np.sin(phi)], [np.sin(phi), np.cos(phi)]])
    md = d @ R.T
    r = p - md - c
    n = len(tf)
    sw = np.sqrt(w)[:, None]
    nuisance = [np.tile([1.0, 0.0], (n, 1)), np.tile([0.0, 1.0], (n, 1)), np.stack([-md[:, 1], md[:, 0]], -1)]
    th = path.heading(ts)
    cq, sq = np.cos(th), np.sin(th)
    # p = R a(tf - delta) + c: a later stamp moves the model back along the path
    cols = [-(path.velocity(ts, dl) @ R.T), np.stack([cq, sq], -1) @ R.T, np.stack([-sq, cq], -1) @ R.T]
    U = np.stack([(sw * u).ravel() for u in nuisance], -1)
    A = np.stack([(sw * u).ravel() for u in cols], -1)
    rr = (sw * r).ravel()
    q, _ = np.linalg.qr(U)
    A = A - q @ (q.T @ A)
    rr = rr - q @ (q.T @ rr)
    return A, rr, float(rr @ rr), max(1, 2 * n - 4)


def _trial_misfits(path: _Path, tf, p, w) -> np.ndarray:
    """(len(TRIALS),) each trial offset's rigid misfit of one window's fixes
    ((n,) stamps tf, (n, 2) positions p, (n,) weights w) against the
    antenna path, per fix on the path (rigid_misfit of the fixes whose
    shifted time falls on it, times n / their count). All trials at once:
    a fix off the path takes weight 0, which drops it from the fit exactly
    (one trial at a time, the hour-long log's check took 1.9 s of its 2.7)."""
    ts = tf[None, :] - TRIALS[:, None]                              # (T, n)
    ok = (ts >= path.t[0]) & (ts <= path.t[-1])
    d = path.antenna(ts.ravel()).reshape(*ts.shape, 2)               # (T, n, 2)
    wk = w[None, :] * ok
    total = wk.sum(1)
    wn = wk / np.where(total > 0, total, 1.0)[:, None]
    md = np.einsum("tn,tnk->tk", wn, d)
    mp = wn @ p
    a, b = d - md[:, None, :], p[None] - mp[:, None, :]
    phi = np.arctan2(np.sum(wn * (a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]), 1),
                     np.sum(wn * (a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]), 1))
    cs, sn = np.cos(phi)[:, None], np.sin(phi)[:, None]
    # p ~ R d + c with c = mp - R md, so the residual is b - R a
    rx = b[..., 0] - (cs * a[..., 0] - sn * a[..., 1])
    ry = b[..., 1] - (sn * a[..., 0] + cs * a[..., 1])
    misfit = np.sum(wk * (rx**2 + ry**2), 1)
    return misfit * len(tf) / np.maximum(1, ok.sum(1))


def _windows(log, path: _Path, skip=()):
    """[(t0, fix selection)] of the WINDOW-second windows with enough fixes,
    outside the ``skip`` spans."""
    g = log.gps
    out = []
    for a in np.arange(max(g.t[0], path.t[0]) + 1.0, min(g.t[-1], path.t[-1]) - 1.0 - WINDOW, WINDOW):
        if any(sa < a + WINDOW and sb > a for sa, sb in skip):
            continue
        sel = (g.t >= a) & (g.t < a + WINDOW)
        if sel.sum() >= MIN_FIXES:
            out.append((float(a), sel))
    return out


def _inside(path: _Path, tf, delta):
    """The fixes whose shifted time falls on the wheels' path (outside it the
    interpolation holds the end pose, which looks like standing still)."""
    ts = tf - delta
    return (ts >= path.t[0]) & (ts <= path.t[-1])


def _prepare(log):
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    g = log.gps
    if g is None or len(g.t) < MIN_FIXES:
        return log, None, None
    sig = g.sigma if g.sigma is not None else np.full(len(g.t), log.robot.gps_sigma)
    return log, np.stack([g.x, g.y], -1), 1.0 / sig**2


#: A window needs this many fixes.
MIN_FIXES = 10
#: A window whose offset sigma (its Fisher information: the antenna motion
#: that no rigid move of the window mimics) is wider than this tells nothing
#: about the clock: on a straight line or a constant-curvature arc at
#: constant speed, a time shift is a move along the path.
MAX_WINDOW_SIGMA = 0.5


def window_offsets(log, scales=(1.0, 1.0, 1.0), skip=(), max_misfit: float | None = None) -> list[Offset]:
    """The GPS offset of each WINDOW-second window with enough fixes and motion,
    left after the configured [gps] time_offset (measurements.clean). Windows
    that overlap a ``skip`` span are left out, and with ``max_misfit`` those
    whose best shifted fit still leaves more than that many times the fix
    variance: a slip bends the wheels' path there, which no time shift
    explains, while a clock offset is explained exactly by one.

    Each window's offset is the best of TRIALS, refined by Gauss-Newton; its
    sigma is from the window's Fisher information (widened by a misfit
    beyond the fix sigma), and windows where it exceeds MAX_WINDOW_SIGMA are
    left out."""
    log, P, W = _prepare(log)
    if P is None:
        return []
    g = log.gps
    path = _Path(log, scales)
    out = []
    for a, sel in _windows(log, path, skip):
        tf, p, w = g.t[sel], P[sel], W[sel]

        # coarse over TRIALS (per fix: the fixes on the path change with the shift)
        coarse = _trial_misfits(path, tf, p, w)
        i = int(np.argmin(coarse))
        if i == 0 or i == len(TRIALS) - 1:
            continue                                   # outside the range tried: cannot tell
        delta, ok = float(TRIALS[i]), None
        for _ in range(8):
            ok = _inside(path, tf, delta)
            if ok.sum() < MIN_FIXES:
                break
            A, r, chi2, dof = _window_system(path, tf[ok], p[ok], w[ok], delta)
            info = float(A[:, 0] @ A[:, 0])
            if info <= 0:
                break
            step = float(np.clip(A[:, 0] @ r / info, -0.1, 0.1))
            delta += step
            if abs(step) < 1e-4:
                break
        if ok is None or ok.sum() < MIN_FIXES or not (TRIALS[0] < delta < TRIALS[-1]):
            continue
        A, r, chi2, dof = _window_system(path, tf[ok], p[ok], w[ok], delta)
        info = float(A[:, 0] @ A[:, 0])
        if info <= 0:
            continue
        if max_misfit is not None and chi2 / dof > max_misfit:
            continue
        s2 = max(1.0, chi2 / dof)                      # misfit beyond the fix sigma widens it
        sigma = float(np.sqrt(s2 / info))
        # The information is local: a misfit as flat as the noise far from the
        # minimum (a straight or circular stretch, where the minimum sat at
        # the edge of the first wheel movement, 1.4 s "late") is no offset.
        flat = TRIALS[coarse - coarse.min() <= s2]
        sigma = max(sigma, float(np.max(np.abs(flat - delta))))
        if sigma > MAX_WINDOW_SIGMA:
            continue
        out.append(Offset(delta, sigma, a, a + WINDOW))
    return out


@dataclass(frozen=True)
class JointFit:
    """The GPS time offset and the lever arm's error fitted together over
    the windows (a forward lever-arm error moves the antenna along the track
    by a fixed distance, a time offset by one proportional to the speed)."""
    delta: float
    lever: tuple[float, float]
    """The lever arm the fixes say, minus the configured one (robot frame) [m]."""
    cov: np.ndarray
    """The covariance of (delta, lever x, lever y), from the fix sigma
    (widened by the misfit) or from the window-to-window scatter, whichever
    is wider."""
    along: float
    """The forward lever-arm error [m] that moves the antenna as one second
    of offset does (minus the speed, weighted as the information)."""
    t0: float
    t1: float
    n_windows: int
    travel: float = float("inf")
    """How far the robot's centre moved [m] over the windows fitted."""
    windows: tuple = ()
    """The start times [s] of the windows fitted."""

    @property
    def sigma(self) -> float:
        return float(np.sqrt(self.cov[0, 0]))

    @property
    def lever_sigma(self) -> tuple[float, float]:
        return float(np.sqrt(self.cov[1, 1])), float(np.sqrt(self.cov[2, 2]))

    @property
    def offset(self) -> Offset:
        return Offset(self.delta, self.sigma, self.t0, self.t1)

    def lever_off(self, axis: int) -> bool:
        """The lever arm's error along robot axis 0 (x) or 1 (y) is significant.
        Only where the robot's centre travelled MIN_LEVER_TRAVEL: turning on
        the spot, the antenna circles the centre, and a lever arm turned by
        any angle fits as well with the start heading turned back (the fit
        then reads the wheels' small scale-error drift as a lever arm: a
        probe's pivot-only log, "off by 0.54 m, sigma 0.01 m")."""
        if self.travel < MIN_LEVER_TRAVEL:
            return False
        return abs(self.lever[axis]) > max(N_SIGMA * self.lever_sigma[axis], MIN_LEVER)


#: A lever-arm error is reported when it is N_SIGMA from 0 and at least this [m],
#: and the robot's centre travelled at least MIN_LEVER_TRAVEL [m] over the fit.
MIN_LEVER = 0.05
MIN_LEVER_TRAVEL = 2.0
#: The joint fit's prior information on (offset [s], lever x, lever y [m]):
#: sigmas of 10 s and 10 m, so that a log that cannot tell one of them
#: (a straight line does not see the lever arm) reports it as undetermined.
PRIOR_INFO = np.diag([1e-2, 1e-2, 1e-2])
#: gps_offset (--time-offset) applies no offset whose sigma is wider than this [s]
#: (a log at one speed left 0.06 s, and a clean one of them -0.28 s).
MAX_APPLY_SIGMA = 0.05


def joint_fit(log, scales=(1.0, 1.0, 1.0), delta0: float = 0.0, skip=(),
              max_misfit: float | None = None, hold_offset: bool = False, only=None) -> JointFit | None:
    """The time offset and lever-arm error fitted together (Gauss-Newton from
    ``delta0``, each window's rigid map fitted out), or None without enough
    windows. With ``max_misfit``, windows whose fit leaves more than that many
    times the fix variance are left out (slip). With ``hold_offset`` the
    offset stays at ``delta0``: the lever arm alone is fitted. ``only``: the
    windows to fit (JointFit.windows of another fit), whatever their misfit."""
    prior = PRIOR_INFO + (np.diag([1e12, 0.0, 0.0]) if hold_offset else 0.0)
    log, P, W = _prepare(log)
    if P is None:
        return None
    g = log.gps
    path = _Path(log, scales)
    wins = _windows(log, path, skip)
    th = np.array([delta0, 0.0, 0.0])

    def systems(th):
        out = []
        for a, sel in wins:
            tf, p, w = g.t[sel], P[sel], W[sel]
            ok = _inside(path, tf, th[0])
            if ok.sum() >= MIN_FIXES:
                A, r, chi2, dof = _window_system(path, tf[ok], p[ok], w[ok], th[0], th[1:])
                out.append((a, A, r, chi2, max(1, dof - 2)))
        return out

    # Windows the current fit cannot explain are bent by slip: they are left
    # out, and the set is chosen again at each step (a wrong lever arm bends
    # windows too, until it is fitted).
    chosen = None
    for it in range(20):
        every = systems(th)
        parts = [x for x in every if (x[0] in only if only is not None
                                      else max_misfit is None or x[3] / x[4] <= max_misfit)]
        if len(parts) < 2:
            return None
        N = sum(A.T @ A for _, A, _, _, _ in parts) + prior
        b = sum(A.T @ r for _, A, r, _, _ in parts) - prior @ (th - [delta0, 0.0, 0.0])
        step = np.clip(np.linalg.solve(N, b), -0.2, 0.2)
        th += step
        now = [x[0] for x in parts]
        if np.all(np.abs(step) < 1e-4) and now == chosen:
            break
        chosen = now
    parts = [x for x in systems(th) if x[0] in chosen]
    if not (TRIALS[0] < th[0] < TRIALS[-1]):
        return None
    if len(parts) < 2:
        return None
    N = sum(A.T @ A for _, A, _, _, _ in parts) + prior
    Ni = np.linalg.inv(N)
    chi2 = sum(x[3] for x in parts)
    dof = sum(x[4] for x in parts)
    model = Ni * max(1.0, chi2 / dof)
    # the windows' scores at the solution: their scatter is what systematic
    # errors of the wheels' path (scale, heading drift) leave
    sc = [A.T @ r for _, A, r, _, _ in parts]
    m = len(sc)
    sand = Ni @ sum(np.outer(x, x) for x in sc) @ Ni * m / max(1, m - 3)
    cov = model if model[0, 0] >= sand[0, 0] else sand
    # the forward lever-arm error that mimics a second of offset: minus the
    # speed along the robot's x axis, where the offset is seen
    ad = np.concatenate([x[1][:, 0] for x in parts])
    ax = np.concatenate([x[1][:, 1] for x in parts])
    along = float(ad @ ax / max(ax @ ax, 1e-12))
    travel = 0.0
    for a in chosen:
        k = (path.t >= a) & (path.t <= a + WINDOW)
        travel += float(np.sum(np.hypot(*np.diff(path.pose[k, 0:2], axis=0).T))) if k.sum() > 1 else 0.0
    return JointFit(float(th[0]), (float(th[1]), float(th[2])), cov, along,
                    parts[0][0], parts[-1][0] + WINDOW, m, travel, tuple(chosen))


def combine(parts: list[Offset]) -> Offset | None:
    """The weighted mean of window offsets, its sigma widened by their scatter.
    Windows far from the median (4 robust sigmas: a slip bends the wheels'
    path there) are left out."""
    if not parts:
        return None
    d = np.array([p.delta for p in parts])
    if len(d) >= 4:
        med = np.median(d)
        mad = robust_sigma(d - med)
        keep = np.abs(d - med) <= max(4.0 * mad, 0.02)
        parts = [p for p, k in zip(parts, keep) if k]
        d = d[keep]
    w = 1.0 / np.array([p.sigma for p in parts]) ** 2
    mean = float(np.sum(w * d) / w.sum())
    chi2 = float(np.sum(w * (d - mean) ** 2)) / max(1, len(d) - 1)
    return Offset(mean, float(np.sqrt(max(1.0, chi2) / w.sum())), parts[0].t0, parts[-1].t1)


def _consistent(parts: list[Offset]) -> bool:
    """The window offsets agree with their weighted mean within their sigmas
    (reduced chi-square below 4) and within 0.1 s."""
    d = np.array([p.delta for p in parts])
    w = 1.0 / np.array([p.sigma for p in parts]) ** 2
    mean = np.sum(w * d) / w.sum()
    return bool(np.sum(w * (d - mean) ** 2) / max(1, len(d) - 1) < 4.0 and np.max(np.abs(d - mean)) < 0.1)


def gps_offset(log, scales=(1.0, 1.0, 1.0)) -> Offset | None:
    """The log's GPS time offset against the wheels (see the module doc),
    fitted together with the lever arm, or None when the log does not
    determine it to MAX_APPLY_SIGMA (too little motion, or a speed too
    constant to tell an offset from a lever-arm error)."""
    fixed = combine(window_offsets(log, scales, max_misfit=MAX_MISFIT))
    j = joint_fit(log, scales, fixed.delta if fixed is not None else 0.0, max_misfit=MAX_MISFIT)
    if j is None:
        # Fewer than two windows the wheels' path fits: with scale factors far
        # off (--time-offset starts from the nominal ones: 3 % left one window
        # of five) the windows' own offsets are a first guess, which the
        # estimate's scale factors then refine (the offset is measured again
        # relative to it, with the lever arm free).
        return combine(window_offsets(log, scales))
    if j.sigma > MAX_APPLY_SIGMA:
        return None
    return j.offset


def gps_offset_warnings(log, est) -> list[str]:
    """One line each for a GPS clock that is off over the log, or that jumps,
    and for a GPS lever arm that is off (it moves the antenna along the track
    as a time offset does: the two are fitted together, and named apart when
    the log can tell them, by a speed that varies or by turning).

    The wheels' path is drawn with the estimated scale factors, and again
    with the nominal ones when those differ by more than IMPLAUSIBLE: an
    estimate fitted to late fixes bends its scale factors to follow them
    (a 1 s late GPS gave scales of 1.42 and 0.77), and its own path then
    hides the offset. Windows bent by slip are left out (MAX_MISFIT: a late
    slip made a false 0.22 s "jump" that refused good logs)."""
    k = tuple(float(v) for v in est.mean[-1, S.SCALE])
    out, fitted = [], 0
    for scales in ([k] + ([(1.0, 1.0, 1.0)] if max(abs(v - 1.0) for v in k) > IMPLAUSIBLE else [])):
        parts = window_offsets(log, scales, max_misfit=MAX_MISFIT)
        if fitted and len(parts) < max(2, fitted // 2):
            # The nominal path fits far fewer windows than the estimate's:
            # the scale factors really are that far off, and the one or two
            # windows a wrong path still fits say nothing of the clock (a
            # probe's log, scales 0.9/1.1/0.85 and exact stamps: five windows
            # at -0.001 s with the estimate's, one at a false +0.46 s with
            # nominal). Half as many is still asked: an estimate bent by late
            # fixes fits its windows too (a probe: 0.3 s late, scales 15 %
            # off, named only at nominal).
            break
        fitted = len(parts)
        fixed = combine(parts)
        j = joint_fit(log, scales, fixed.delta if fixed is not None else 0.0, max_misfit=MAX_MISFIT)
        held = joint_fit(log, scales, 0.0, max_misfit=MAX_MISFIT, hold_offset=True)
        sigma = getattr(est, "sigma", None)
        if (scales is k and sigma is not None and j is not None
                and (j.offset.significant or any(j.lever_off(i) for i in (0, 1)))):
            # (only where a line would be said: three more fits each for j and held)
            j = _with_scale_uncertainty(log, j, k, sigma[-1, S.SCALE])
            held = None if held is None else _with_scale_uncertainty(log, held, k, sigma[-1, S.SCALE], True)
        out = _offset_lines(parts, j, log.robot.gps_lever_arm, held)
        if out:
            break
    return out


def _with_scale_uncertainty(log, j: JointFit, scales, sigma, hold_offset: bool = False) -> JointFit:
    """``j`` with the estimate's scale-factor uncertainty (``sigma`` (3,))
    added to its covariance: the fit drawn again with each scale factor one
    sigma up, its (offset, lever arm) moved by J, and J diag(sigma^2) J^T
    added. The wheels' path drawn with scale factors a short calibration
    window left 1 % uncertain is off by as much over every window alike,
    and the lever arm takes it up without scattering (a probe's 45 min log:
    the EKF's scale factors 1.3 sigma off, the lever arm "off by -0.14 m,
    sigma 0.02 m", the log degraded and its calibration refused)."""
    from dataclasses import replace as _replace
    th = np.array([j.delta, *j.lever])
    add = np.zeros((3, 3))
    for c in range(3):
        if not sigma[c] > 0:
            continue
        up = list(scales)
        up[c] += float(sigma[c])
        # the same windows: a window set chosen again by its misfit jumps with the path
        j2 = joint_fit(log, tuple(up), j.delta, hold_offset=hold_offset, only=j.windows)
        if j2 is None:
            continue
        d = np.array([j2.delta, *j2.lever]) - th
        add += np.outer(d, d)
    return _replace(j, cov=j.cov + add)


#: Scale factors further than this from nominal are not trusted to draw the wheels' path.
IMPLAUSIBLE = 0.10
#: A window whose best time-shifted rigid fit leaves more than this many
#: times the fix variance is bent by slip, not shifted by the clock.
MAX_MISFIT = 9.0


def _offset_lines(parts: list[Offset], j: JointFit | None = None, lever=(0.0, 0.0),
                  held: JointFit | None = None) -> list[str]:
    """The lines for window offsets ``parts`` (lever arm as configured), the
    joint fit ``j`` of offset and lever arm, and ``held``, the lever arm
    fitted alone. Either is named only when its own fit and the joint one
    both find it: where the two are nearly alike, the joint fit's small
    leftover difference is not evidence (a clean log at one speed came out
    -0.28 +- 0.06 s there)."""
    whole = combine(parts)
    out = []
    alone = whole is not None and whole.significant
    time_off = alone and (j is None or j.offset.significant)
    lever_off = j is not None and any(j.lever_off(i) and (held is None or held.lever_off(i)) for i in (0, 1))
    if time_off:
        o = j.offset if j is not None else whole
        out.append(f"GPS time stamps look {o.delta:+.2f} s late (sigma {o.sigma:.2f} s) against the wheels: "
                   "a receiver latency or clock offset biases the calibration; set [gps] time_offset in "
                   "robot.toml, or estimate it with --time-offset")
    if lever_off:
        said = [f"{j.lever[i]:+.2f} m along the robot's {ax} axis (sigma {j.lever_sigma[i]:.2f} m; the fixes put "
                f"the antenna at {ax} = {lever[i] + j.lever[i]:.2f} m, robot.toml has {lever[i]:.2f} m)"
                for i, ax in enumerate("xy") if j.lever_off(i) and (held is None or held.lever_off(i))]
        out.append(f"the GPS lever arm looks off by about {' and '.join(said)} against the wheels: it biases the "
                   "calibration like a time offset; check [gps] lever_arm (not [gps] time_offset)")
    elif not time_off and alone:
        # With the lever arm held, an offset shows; with it free, neither
        # does: at one speed the two move the antenna alike.
        by = f" by about {j.along * whole.delta:+.2f} m" if j is not None else ""
        out.append(f"GPS time stamps look {whole.delta:+.2f} s late (sigma {whole.sigma:.2f} s) against the wheels, "
                   f"or the GPS lever arm is off{by} along the robot's x axis: this log cannot "
                   "tell the two apart (its speed hardly varies and it hardly turns); check [gps] lever_arm "
                   "before you set [gps] time_offset")
    if lever_off:
        return out                                     # a wrong lever arm bends the windows: no jump to look for
    found = jump(parts)
    if found is not None:
        t_at, a, b = found
        out.append(f"the GPS clock seems to jump by {b.delta - a.delta:+.2f} s near t={t_at:.0f} s "
                   f"(offsets {a.delta:+.2f} s before, {b.delta:+.2f} s after)")
    return out


def jump(parts: list[Offset], min_offset: float = MIN_OFFSET) -> tuple[float, Offset, Offset] | None:
    """A clock that jumps: (the time [s] of the first window after it, the
    offset before, the offset after: their t0, t1 span the windows each
    side), or None. The windows before and after
    a point disagree, and each side agrees with itself (windows that scatter
    everywhere say the wheels' path is off, from wrong parameters or a
    mounting mistake, not the clock). The window that holds the jump sees
    part of each clock: it may be left out."""
    for k in range(2, len(parts) - 1):
        for gap in (0, 1):
            before, after = parts[:k], parts[k + gap:]
            if len(after) < 2 or not (_consistent(before) and _consistent(after)):
                continue
            a, b = combine(before), combine(after)
            if abs(b.delta - a.delta) > max(N_SIGMA * np.hypot(a.sigma, b.sigma), min_offset):
                return after[0].t0, a, b
    return None
