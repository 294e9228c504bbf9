"""The first state and its covariance, from the data when robot.toml has no [initial].

LOG_FORMAT forbids assuming a start at the origin. The start pose is fitted,
robustly, to the first seconds of absolute fixes (GPS, or multilateration of
the first ranges): the wheels' own path, dead reckoned with the nominal
parameters from the first wheel measurement, is mapped onto the fixes by the
rigid transform most of them agree with (``consensus_pose``). So an outlier
among the first fixes cannot poison the start, and a small robot that turns
at once still gets its heading. Every estimator starts at the first wheel
measurement; the fit reads up to CONSENSUS_WINDOW seconds of fixes ahead
(for a strictly causal start, give robot.toml an [initial] pose).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from odomgraph.factors import encoder
from odomgraph.factors._math import wrap_angle
from odomgraph.factors.motion import integrate
from odomgraph import state as S
from odomgraph.errors import NotEnoughDataError
from odomgraph.estimators.measurements import Measurements
from odomgraph.observability import UNPLACED_BY_RANGES, Observability, prior_scale_cov, structure
from odomgraph.estimators.slipcheck import slipping_stretches
from odomgraph.estimators.standstill import still_stretches
from odomgraph.io.robot import RobotConfig

#: Multilateration window: each beacon's latest range within it is combined [s].
_RANGE_WINDOW = 0.6
#: Longest window, where ranges come too slowly for three beacons inside
#: _RANGE_WINDOW (beacons polled in turn at 1 Hz each) [s]; the robot's
#: travel across it widens the fix's sigma.
_RANGE_WINDOW_MAX = 3.0


#: Ranges this much earlier than the first GPS fix are what the start is
#: fitted to [s] (a GPS receiver's usual start-up leaves the start to GPS).
_RANGES_FIRST = 5.0

#: The anchor's share of its fixes' information (Anchor): the filter takes
#: the fixes again at the rest (their variance / (1 - ANCHOR_SHARE)).
ANCHOR_SHARE = 0.5


@dataclass(frozen=True)
class Anchor:
    """The start fit's pose at its sensor's first measurement, when that came
    long after the start.

    The start (InitialState.x) is then this pose carried back along the
    wheels, with all the carrying back can have drifted: tens of metres and
    pi rad wide after half a minute. A filter linearised at such a guess
    went wrong at its first ranges (0.3 m off at sigma 0.03 m, z 13, or a
    divergence). At ``t`` the fixes know the pose far better; a filter takes
    it there (ekf.EKF._take_anchor). The fit and the filter share the fixes'
    information rather than count it twice: ``cov`` is the fit's covariance
    over ANCHOR_SHARE, and the filter takes the fit's fixes (up to ``until``)
    with their variance over 1 - ANCHOR_SHARE. (A prior worth one fix was
    too little for a heading: 1.8 rad wide, and the filter overconfident
    after; a filter that left the fixes out coasted through a 14 s window of
    0.5 Hz fixes and came out z 7.)
    """
    t: float
    """Time of the fit's sensor's first measurement [s]."""
    pose: np.ndarray
    """(3,) x, y [m], theta [rad] of the robot at t, world frame."""
    cov: np.ndarray
    """(3, 3) its covariance: the fit's, over ANCHOR_SHARE."""
    until: float
    """Last fix time the fit used [s]."""
    n: int
    """Fixes the fit used."""
    sensor: str = "gps"
    """The fit's sensor: "gps" or "ranges"."""


@dataclass(frozen=True)
class InitialState:
    t: float
    """Absolute start time [s]; measurements before it are not used."""
    x: np.ndarray
    """(11,) state."""
    P: np.ndarray
    """(11, 11) covariance. Its scale block pins what the log cannot determine
    (observability.prior_scale_cov)."""
    note: str
    observability: Observability = field(default_factory=Observability)
    warnings: tuple[str, ...] = ()
    slipping: tuple[tuple[float, float], ...] = ()
    """Stretches [s] where the fixes contradict the wheels (slipcheck): no
    schedule may take them as slip-free."""
    still: tuple[tuple[float, float], ...] = ()
    """[start, end] stretches [s] in which the robot stood still, seen whole
    (standstill.still_stretches): batch holds the slips at zero there (eq.
    35-36). The EKF decides the same causally (standstill.StillWatch);
    isam2 and fixed-lag take none."""
    heading_unknown: bool = False
    """The start's heading is unknown (the first fixes show no motion; sigma
    pi): until the motion shows it (estimators.heading), no estimator may
    claim one."""
    frame_free: bool = False
    """No absolute measurement placed the start: it is the origin, heading 0,
    the wheels' own frame (a stream starts again in the fixes' frame when
    they come: online.Online._anchor)."""
    anchor: Anchor | None = None
    """The pose at the first absolute measurement, when it came long after
    the start (see Anchor)."""


def _wheel_rates(robot: RobotConfig, meas: Measurements):
    v, w = encoder.body_velocity(meas.wheel.m[:, 0], meas.wheel.m[:, 1], 0.0, 0.0, 1.0, 1.0, 1.0,
                                 robot.track_width)
    return meas.wheel.t, v, w


class RangeFixes(NamedTuple):
    """Multilateration fixes of the ranging antenna (range_fixes)."""
    t: np.ndarray
    """(M,) stamp: the mean time of the fix's ranges [s]."""
    xy: np.ndarray
    """(M, 2) antenna position, world frame [m]."""
    sigma: np.ndarray
    """(M,) 1-sigma along the worst direction [m]."""
    lever: tuple[float, float]
    """The ranging antenna in the robot frame [m]."""
    newest: np.ndarray
    """(M,) time of the fix's newest range [s]."""


def range_fixes(meas: Measurements, robot: RobotConfig, limit: int | None = 400) -> RangeFixes | None:
    """Multilateration fixes (t, xy, sigma, lever arm) of the ranging antenna
    from the first ``limit`` ranges (all with None), by Gauss-Newton; None
    if no three beacons are ever in range together.

    A fix combines each beacon's latest range within _RANGE_WINDOW, or, when
    that holds fewer than three beacons (beacons polled in turn, slowly),
    within _RANGE_WINDOW_MAX. Its ranges are taken at different times on a
    moving robot: it is stamped at their mean time, where it lies for a
    steady motion (at the newest range's it lagged the robot by 0.2-0.3 s
    of travel, and a start fitted to such fixes was 3.5 sigma off). A fix
    from the longer window also carries, in its sigma, how far the antenna
    can have moved between its ranges and its stamp (the wheels' speed,
    with room for their scale factors): with only the 0.6 s window, a
    round-robin log at 1 Hz a beacon had no fix at all, and every estimator
    started at the origin and put the path 13 m off at z 12000, unflagged.
    """
    t, bxy, rr = meas.ranges
    out_t, out_p, out_s, out_new = [], [], [], []
    latest: dict[tuple, tuple[float, float]] = {}
    sig_r = robot.range_sigma + float(np.hypot(*robot.range_lever_arm))
    # the antenna's speed by the wheels, with room for their scale factors (an upper bound) [m/s]
    tw = meas.wheel.t
    v_wheel = (np.abs(0.5 * (meas.wheel.m[:, 0] + meas.wheel.m[:, 1]))
               + 0.5 * np.abs(meas.wheel.m[:, 1] - meas.wheel.m[:, 0]) / robot.track_width
               * float(np.hypot(*robot.range_lever_arm))) * (1.0 + 3.0 * robot.process.initial_scale_sigma)
    for k in range(len(t) if limit is None else min(len(t), limit)):
        latest[tuple(bxy[k])] = (t[k], rr[k])
        pts = [(np.array(b), r, tb) for b, (tb, r) in latest.items() if t[k] - tb <= _RANGE_WINDOW]
        slow = len(pts) < 3
        if slow:
            pts = [(np.array(b), r, tb) for b, (tb, r) in latest.items() if t[k] - tb <= _RANGE_WINDOW_MAX]
        if len(pts) < 3:
            continue
        B = np.array([p for p, _, _ in pts])
        R = np.array([r for _, r, _ in pts])
        p = B.mean(0) + 0.1
        for _ in range(20):
            d = p - B
            rng = np.maximum(np.linalg.norm(d, axis=1), 1e-6)
            J = d / rng[:, None]
            step, *_ = np.linalg.lstsq(J, R - rng, rcond=None)
            p = p + step
            if np.linalg.norm(step) < 1e-6:
                break
        JtJ = J.T @ J
        if np.linalg.cond(JtJ) > 1e6:
            continue
        tb = np.array([tb for _, _, tb in pts])
        err_r = sig_r
        if slow:
            # each range's error then holds the travel between it and the stamp,
            # magnified by the geometry as the ranges' own noise is
            i0, i1 = np.searchsorted(tw, [tb.min() - 0.5, tb.max() + 0.5])
            v = float(v_wheel[i0:max(i1, i0 + 1)].max()) if v_wheel.size else 0.0
            err_r = float(np.hypot(sig_r, v * float(np.max(np.abs(tb - tb.mean())))))
        cov = np.linalg.inv(JtJ) * err_r**2
        out_t.append(float(tb.mean())); out_p.append(p); out_s.append(float(np.sqrt(np.max(np.linalg.eigvalsh(cov)))))
        out_new.append(float(tb.max()))
    if not out_t:
        return None
    order = np.argsort(out_t, kind="stable")
    return RangeFixes(np.array(out_t)[order], np.array(out_p)[order], np.array(out_s)[order],
                      tuple(robot.range_lever_arm), np.array(out_new)[order])


def initial_state(robot: RobotConfig, meas: Measurements, pin: dict[str, str] | None = None) -> InitialState:
    """The first state and its covariance (see the module doc). ``pin``: scale
    combinations to hold at nominal besides those the structure cannot
    determine, with the reason (pipeline.estimate passes what a first run
    found the data barely inform)."""
    x = S.NOMINAL.copy()
    P = np.zeros((S.N, S.N))
    pn = robot.process
    P[S.BIAS, S.BIAS] = pn.initial_bias_sigma**2
    P[S.SLIP_L, S.SLIP_L] = P[S.SLIP_R, S.SLIP_R] = pn.initial_slip_sigma**2
    obs = structure(robot, meas)
    if pin:
        from dataclasses import replace
        obs = replace(obs, unobservable={**obs.unobservable, **{k: v for k, v in pin.items()
                                                                 if k not in obs.unobservable}})
    extra = () if obs.slip_observable else (
        "slip is not observable: nothing but the wheels sees the motion (no gyro, velocity sensor or absolute "
        "fixes), so it is taken as zero throughout (plain dead reckoning)",)
    P[np.ix_(S.SCALE, S.SCALE)] = prior_scale_cov(obs, pn.initial_scale_sigma)
    tw, vw, ww = _wheel_rates(robot, meas)

    def finish(t0, pose, pose_cov, note, warnings=(), heading_unknown=False, frame_free=False, anchor=None):
        if np.sum(tw >= t0) < 2:
            raise NotEnoughDataError(f"fewer than two wheel measurements after the estimator's start at "
                                     f"t={t0:.6g} s ({note}); the wheel odometry ends at t={tw[-1]:.6g} s")
        x[S.POSE] = pose
        x[S.THETA] = wrap_angle(pose[2])
        k = min(np.searchsorted(tw, t0), len(tw) - 1)
        x[S.V], x[S.OMEGA] = vw[k], ww[k]
        # Nominal wheel speeds are off by the unknown scale factors and any
        # slip: keep the velocity prior wide.
        P[S.V, S.V] = (0.2 + 0.1 * abs(vw[k])) ** 2
        P[S.OMEGA, S.OMEGA] = (0.2 + 0.1 * abs(ww[k])) ** 2
        P[np.ix_(S.POSE, S.POSE)] = pose_cov
        still, moved = still_stretches(meas, robot, float(t0), float(tw[-1]))
        return InitialState(float(t0), x, P, note, obs, tuple(warnings) + extra + tuple(moved),
                            tuple(slipping_stretches(meas, robot, float(t0), float(tw[-1]))), tuple(still),
                            heading_unknown, frame_free, anchor)

    if robot.initial is not None:
        i = robot.initial
        t0 = min([tw[0], *(s[0][0] for s in (meas.gyro, meas.gps, meas.ranges, meas.velocity) if s is not None)])
        return finish(t0, np.array([i.x, i.y, i.theta]), np.diag(np.square(i.sigma)),
                      "initial pose from robot.toml [initial]")

    fixes, source = None, ""
    if meas.gps is not None:
        fixes, source = (*meas.gps, robot.gps_lever_arm), "GPS"
    if meas.ranges is not None and (meas.gps is None or meas.ranges[0][0] < meas.gps[0][0] - _RANGES_FIRST):
        # Ranges alone, or long before the first GPS fix: the start is fitted
        # to the first measurements there are (fitted to GPS 40 s on, the
        # filter met 40 s of ranges with a start 10 m and 2 rad wide: z 36).
        rf = range_fixes(meas, robot)
        if rf is not None or fixes is None:
            fixes = None if rf is None else (rf.t, rf.xy, rf.sigma, rf.lever)
            source = "multilateration of the first ranges"
    if fixes is None:
        t0 = tw[0]
        msg = ("no absolute sensor and no [initial] pose in robot.toml: the start pose is taken as the origin, "
               "heading 0 (positions are relative to it)")
        if meas.ranges is not None:
            msg = UNPLACED_BY_RANGES
        return finish(t0, np.zeros(3), np.diag([1e-6, 1e-6, 1e-6]), msg, (msg,), frame_free=True)
    sensor = meas.gps if source == "GPS" else meas.ranges
    fit = consensus_pose(tw, meas.wheel.m[:, 0], meas.wheel.m[:, 1], _wheel_dt(meas), robot.track_width, *fixes,
                         pn.initial_scale_sigma, t_first=float(sensor[0][0]))
    if fit.anchor is not None and source != "GPS":
        # the anchor holds every range of the fit's fixes, up to the newest of the last one's
        from dataclasses import replace
        until = float(rf.newest[rf.t <= fit.anchor.until].max())
        fit = replace(fit, anchor=replace(fit.anchor, sensor="ranges", until=max(until, fit.anchor.until)))
    return finish(tw[0], fit.pose, fit.cov, f"initial pose from {source}: {fit.note}", fit.warnings,
                  heading_unknown=not fit.moved, anchor=fit.anchor)


# ------------------------------------------------------------- consensus start
#: Longest stretch of fixes the start is fitted on [s]: dead reckoning with
#: nominal parameters must stay close to the truth over it.
CONSENSUS_WINDOW = 30.0
#: Travel the window should contain for a heading [m], at least (or 20 fix sigmas).
CONSENSUS_TRAVEL = 2.0
#: RANSAC hypotheses (pairs of fixes) tried at most.
CONSENSUS_PAIRS = 600


@dataclass(frozen=True)
class ConsensusFit:
    pose: np.ndarray
    """(3,) (x, y, theta) of the robot at the first wheel measurement, world frame [m, rad]."""
    cov: np.ndarray
    """(3, 3) its covariance."""
    inliers: int
    outliers: int
    note: str
    warnings: tuple[str, ...] = ()
    moved: bool = True
    """False: the fixes showed no motion, so no heading (sigma pi)."""
    anchor: Anchor | None = None
    """The pose at the first absolute measurement, when it came late (Anchor)."""


def _wheel_dt(meas: Measurements) -> np.ndarray:
    """(K,) length of each wheel measurement's step for dead reckoning [s]:
    its encoder interval, each speed integrated over its own interval (see
    measurements.dead_reckoning); for wheel speeds, the time to the next one."""
    if meas.wheel.dt is not None:
        return meas.wheel.dt
    t = meas.wheel.t
    dt = np.diff(t)
    return np.append(dt, np.median(dt) if dt.size else 0.0)


def rigid_ransac(d: np.ndarray, p: np.ndarray, thr: np.ndarray, pairs: int = CONSENSUS_PAIRS):
    """RANSAC for the 2-D rigid map p ~ R(phi) d + c between two point sets.

    d, p: (M, 2) the same points in two frames; thr: (M,) inlier distance
    [m]. Hypotheses come from pairs of points far apart (a rotation needs a
    baseline); the best has the most inliers, then the smallest residuals.
    Returns (phi (H,), cx (H,), cy (H,), inlier mask (H, M), index of the
    best hypothesis). Deterministic (seeded).
    """
    m = len(d)
    rng = np.random.default_rng(0)
    sep = np.hypot(*(d[:, None, :] - d[None, :, :]).transpose(2, 0, 1))
    i_idx, j_idx = np.nonzero(np.triu(sep >= 0.3 * sep.max(), 1))
    if i_idx.size > pairs:
        pick = rng.choice(i_idx.size, pairs, replace=False)
        i_idx, j_idx = i_idx[pick], j_idx[pick]
    dp, dd = p[j_idx] - p[i_idx], d[j_idx] - d[i_idx]
    phi = np.arctan2(dp[:, 1], dp[:, 0]) - np.arctan2(dd[:, 1], dd[:, 0])
    c, sn = np.cos(phi), np.sin(phi)
    cx = p[i_idx, 0] - (c * d[i_idx, 0] - sn * d[i_idx, 1])
    cy = p[i_idx, 1] - (sn * d[i_idx, 0] + c * d[i_idx, 1])
    ex = p[None, :, 0] - (c[:, None] * d[None, :, 0] - sn[:, None] * d[None, :, 1]) - cx[:, None]
    ey = p[None, :, 1] - (sn[:, None] * d[None, :, 0] + c[:, None] * d[None, :, 1]) - cy[:, None]
    e = np.hypot(ex, ey)
    inl = e <= thr[None, :]
    score = inl.sum(1) - np.minimum((e / thr[None, :]) ** 2, 1.0).sum(1) / (m + 1)   # count, then closeness
    return phi, cx, cy, inl, int(np.argmax(score)) if score.size else -1


def rigid_fit(d: np.ndarray, p: np.ndarray, w: np.ndarray) -> tuple[float, np.ndarray]:
    """Weighted least-squares rigid map p ~ R(phi) d + c (closed form, 2-D
    Procrustes). w: (M,) weights. Returns (phi, c (2,))."""
    w = w / w.sum()
    md, mp = w @ d, w @ p
    a, b = d - md, p - mp
    phi = float(np.arctan2(np.sum(w * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])),
                           np.sum(w * (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1]))))
    c, s = np.cos(phi), np.sin(phi)
    return phi, mp - np.array([c * md[0] - s * md[1], s * md[0] + c * md[1]])


def _antenna_path(ml, mr, dtw, track, lever, e=(0.0, 0.0, 0.0)):
    """Dead-reckoned poses (K+1, 3) from the first wheel measurement, and a
    function giving the antenna at given times, with relative scale errors
    e = (e_left, e_right, e_track) taken out of the nominal wheel speeds."""
    ul, ur = ml / (1.0 + e[0]), mr / (1.0 + e[1])
    v, w = 0.5 * (ul + ur), (ur - ul) / (track * (1.0 + e[2]))
    return integrate(v, w, dtw)


def _antenna_at(dr, t_dr, ft, lever):
    th = np.interp(ft, t_dr, dr[:, 2])
    return np.stack([np.interp(ft, t_dr, dr[:, 0]) + np.cos(th) * lever[0] - np.sin(th) * lever[1],
                     np.interp(ft, t_dr, dr[:, 1]) + np.sin(th) * lever[0] + np.cos(th) * lever[1]], -1)


def consensus_pose(tw, ml, mr, dtw, track, ft, fp, fs, lever, scale_sigma: float,
                   t_first: float | None = None) -> ConsensusFit:
    """The start pose that best maps the wheels' own path onto the first fixes,
    robust to outliers among them (RANSAC, then least squares).

    The wheels, integrated with the nominal parameters from the first wheel
    measurement (pose 0), give a path d(t) in their own frame; fixes are the
    antenna p_k = R(phi) (d(t_k) + R(theta_d(t_k)) l) + c. Any two fixes far
    enough apart give a hypothesis (phi, c); the one most fixes agree with
    (within 3.4 sigma plus the drift the scale prior allows) wins. It is then
    refined on its inliers together with the three scale errors, under their
    prior: a few percent between the wheels bends a straight run by tenths of
    a radian over two metres, and a fit that ignored it gave a heading 5 sigma
    off. An outlier in the first seconds can neither place nor turn the start,
    and a robot that turns early or moves slowly still gets its heading from
    the whole arc, not "the first straight metre".

    Args:
        tw, ml, mr, dtw: (K,) wheel measurement times [s], nominal left and
            right wheel speeds [m/s] and step lengths [s].
        track: nominal track width [m].
        ft, fp, fs: (M,) fix times, (M, 2) antenna positions, (M,) sigma [m].
        lever: (2,) antenna in the robot frame [m].
        scale_sigma: prior 1-sigma of the scale factors.
        t_first: time of the fixes' sensor's first measurement [s] (the
            first range, before the first multilateration fix); default
            ft[0]. The anchor (ConsensusFit.anchor) is given there, so that
            none of its measurements comes before it.

    Returns the pose at tw[0] with an honest covariance: the fit's (scale
    errors marginalised), scaled by its reduced chi-square when the fixes
    scatter more than their sigma says and by the number of fixes (the
    estimators use them again), plus what dead reckoning between tw[0] and
    the first fix can have drifted.
    """
    lever = np.asarray(lever, float)
    dr = _antenna_path(ml, mr, dtw, track, lever)                 # (K+1, 3), DR pose before step k
    t_dr = np.append(tw - 0.5 * dtw, tw[-1] + 0.5 * dtw[-1])      # nodes at the interval ends
    vw, ww = 0.5 * (ml + mr), (mr - ml) / track
    travel = np.concatenate([[0.0], np.cumsum(np.abs(vw) * dtw)])
    turned = np.concatenate([[0.0], np.cumsum(np.abs(ww) * dtw)])
    ft, fp, fs = np.asarray(ft, float), np.asarray(fp, float), np.asarray(fs, float)
    d = _antenna_at(dr, t_dr, ft, lever)
    s_f = np.interp(ft, t_dr, travel)
    need = max(CONSENSUS_TRAVEL, 20.0 * float(np.median(fs)))

    def window(ft, fs, d, s_f):
        """The window: from the first fix until enough travel (and fixes), at
        most CONSENSUS_WINDOW; its size and the antenna's spread over it."""
        within = ft <= ft[0] + CONSENSUS_WINDOW
        enough = np.flatnonzero(within & (s_f - s_f[0] >= need) & (np.arange(len(ft)) >= 5))
        m = int(enough[0]) + 1 if enough.size else int(within.sum())
        m = max(m, min(len(ft), 8))
        return m, (float(np.max(np.hypot(*(d[:m] - d[:m].mean(0)).T))) if m > 1 else 0.0)

    m, spread = window(ft, fs, d, s_f)
    thr_move = max(3.0 * float(np.median(fs)), 0.05)     # the "hardly moved" test below
    moved = np.flatnonzero(np.hypot(*(d - d[0]).T) >= thr_move)
    if spread < thr_move and moved.size and moved[0] >= m:
        # A robot that stands still first shows its heading only when it
        # moves: the window then starts with the last few fixes before the
        # wheels' antenna first moves, and the pose is carried back over the
        # wait (the wheels say nothing happened in it). Without this a long
        # wait started every estimator at heading 0 +- pi, and isam2 could not
        # recover once the robot drove off 2.5 rad from it.
        i0 = max(int(moved[0]) - 5, 0)
        ft, fp, fs, d, s_f = ft[i0:], fp[i0:], fs[i0:], d[i0:], s_f[i0:]
        m, spread = window(ft, fs, d, s_f)
    W_t, W_p, W_s, W_d, W_sf = ft[:m], fp[:m], fs[:m], d[:m], s_f[:m]
    ds = np.abs(W_sf - W_sf[0])
    # What nominal parameters may have drifted [m]: along track with the
    # common scale, sideways with the wheels' difference (a curve of
    # curvature sqrt(2) sigma / track).
    drift = 2.0 * scale_sigma * ds + 0.5 * (2.0 * np.sqrt(2.0) * scale_sigma / track) * ds**2
    thr = 3.4 * W_s + drift
    t_first_gap = float(ft[0] - tw[0])
    back = 2.0 * scale_sigma * float(np.interp(ft[0], t_dr, travel))
    back_th = scale_sigma * float(np.interp(ft[0], t_dr, turned)) + \
        np.sqrt(2.0) * scale_sigma * float(np.interp(ft[0], t_dr, travel)) / track
    if not spread >= max(3.0 * float(np.median(W_s)), 0.05) or m < 2:
        # The antenna hardly moved: position from the median fix, heading
        # unknown. The start lies on the circle around it whose radius is the
        # wheels' antenna at the first fix, seen from the start: the lever arm
        # standing still, but the whole path driven when the first fix came
        # late (a stream's warm-up with one fix 35 s in took the lever arm's
        # 0.3 m for a start 17 m away, and isam2 bent its scale factors 12
        # sigma to join them).
        med = np.median(W_p, 0)
        s_p = float(np.hypot(np.median(W_s), max(np.hypot(*lever), float(np.hypot(*d[0]))))) + back
        pose = np.array([med[0], med[1], 0.0])
        return ConsensusFit(pose, np.diag([s_p**2, s_p**2, np.pi**2]), m, 0,
                            f"position from the median of {m} fixes; heading not observable from the first motion "
                            "(sigma = pi)", moved=False)
    phi, cx, cy, inl, best = rigid_ransac(W_d, W_p, thr)
    if best < 0:
        s_p = max(1.0, float(np.hypot(*d[0]))) + back          # the circle of the path, as above
        return ConsensusFit(np.array([*np.median(W_p, 0), 0.0]), np.diag([s_p**2, s_p**2, np.pi**2]), m, 0,
                            "position from the median of the first fixes; no pair of them fixes a heading", moved=False)
    keep = inl[best]

    # Least squares on the inliers: (cx, cy, phi) and the scale errors
    # (e_left, e_right, e_track) under their prior, by Gauss-Newton with a
    # numerical Jacobian (each evaluation re-integrates the window's wheels).
    k_end = int(np.searchsorted(t_dr, W_t[-1])) + 2
    sl = slice(0, min(k_end, len(ml)))

    def predict(q, sel):
        path = _antenna_path(ml[sl], mr[sl], dtw[sl], track, lever, q[3:6])
        a = _antenna_at(path, t_dr[:path.shape[0]], W_t[sel], lever)
        cq, sq = np.cos(q[2]), np.sin(q[2])
        return np.stack([cq * a[:, 0] - sq * a[:, 1] + q[0], sq * a[:, 0] + cq * a[:, 1] + q[1]], -1)

    q = np.array([cx[best], cy[best], phi[best], 0.0, 0.0, 0.0])
    prior_w = np.array([0.0, 0.0, 0.0, 1.0, 1.0, 1.0]) / scale_sigma
    for _round in range(2):
        w_sqrt = np.repeat(1.0 / W_s[keep], 2)
        for _ in range(10):
            r = np.concatenate([((W_p[keep] - predict(q, keep)).reshape(-1)) * w_sqrt, -prior_w * q])
            J = np.empty((r.size, 6))
            for j in range(6):
                h = 1e-6 if j < 3 else 1e-7
                dq = q.copy()
                dq[j] += h
                rj = np.concatenate([((W_p[keep] - predict(dq, keep)).reshape(-1)) * w_sqrt, -prior_w * dq])
                J[:, j] = -(rj - r) / h
            J[-6:, :] = np.diag(prior_w)
            J = J[np.r_[np.arange(r.size - 6), r.size - 6 + np.flatnonzero(prior_w)]]
            r = r[np.r_[np.arange(r.size - 6), r.size - 6 + np.flatnonzero(prior_w)]]
            step, *_ = np.linalg.lstsq(J, r, rcond=None)
            q = q + step
            if np.abs(step).max() < 1e-10:
                break
        # Inliers again, against the refined model: residuals within 3.4 sigma.
        res = np.hypot(*(W_p - predict(q, slice(None))).T)
        keep = res <= 3.4 * W_s * max(1.0, float(np.sqrt(np.mean((res[keep] / W_s[keep]) ** 2) / 2.0)))
    n_out = int(m - keep.sum())
    H = J.T @ J
    cov6 = np.linalg.inv(H)
    nfix = 2 * int(keep.sum())
    chi2 = float(np.sum(r[:nfix] ** 2)) / max(1, nfix - 3)
    cov = cov6[:3, :3] * max(1.0, chi2)
    # The estimators see these fixes again as measurements: as a prior the fit
    # may carry about one fix's worth of them, not all (double counting made
    # the start overconfident, and biased ranges then biased everything).
    cov *= max(1.0, float(keep.sum()))
    # Ambiguity: a hypothesis nearly as well supported but turned well away
    # (0.3 rad, and 5 sigma) is a second mode; the heading sigma covers both.
    close = inl.sum(1) >= 0.9 * inl[best].sum()
    dphi = np.abs(np.angle(np.exp(1j * (phi[close] - q[2]))))
    dphi = dphi[dphi > max(0.3, 5.0 * np.sqrt(cov[2, 2]) + 0.1)]
    amb = float(dphi.max()) if dphi.size else 0.0
    warnings = ()
    if amb > 0.0:
        cov[2, 2] = max(cov[2, 2], amb**2)
        warnings = (f"initial heading is ambiguous: fits {np.degrees(amb):.0f} deg apart explain the first fixes "
                    "nearly as well; its sigma says so",)
    floor = 0.5 * float(np.median(W_s))
    anchor = None
    t_a = min(float(W_t[0]), float(ft[0]) if t_first is None else max(float(t_first), float(tw[0])))
    if t_a - float(tw[0]) > 1.0 and float(np.interp(t_a, t_dr, travel)) > 0.0:
        # The pose at the first fix, which the window's fixes pin without any
        # carrying back: the path's pose there mapped by (cx, cy, phi), with
        # the covariance of the map and the scale errors pushed through it
        # (numerically).
        def pose_at_first(q):
            path = _antenna_path(ml[sl], mr[sl], dtw[sl], track, lever, q[3:6])
            tn = t_dr[:path.shape[0]]
            px, py, pt = (np.interp(t_a, tn, path[:, j]) for j in range(3))
            cq, sq = np.cos(q[2]), np.sin(q[2])
            return np.array([cq * px - sq * py + q[0], sq * px + cq * py + q[1], pt + q[2]])

        a0 = pose_at_first(q)
        Jp = np.empty((3, 6))
        for j in range(6):
            dq = q.copy()
            dq[j] += 1e-6
            Jp[:, j] = (pose_at_first(dq) - a0) / 1e-6
        # Not scaled by the number of fixes as the start's is (the filter
        # shares their information, Anchor), but by what their errors' correlation from one
        # fix to the next leaves of them (n (1 - rho) / (1 + rho) independent
        # ones): multilaterated fixes share ranges, and GPS errors persist.
        # Without it the anchor was 3.5 sigma off on a range-only log.
        res = (W_p[keep] - predict(q, keep)) / W_s[keep][:, None]     # (the kept fixes', in time order)
        den = float(np.sum(res[:-1] ** 2))
        rho = min(max(float(np.sum(res[1:] * res[:-1])) / den if den > 0.0 else 0.0, 0.0), 0.9)
        cov_a = Jp @ cov6 @ Jp.T * max(1.0, chi2) * (1.0 + rho) / (1.0 - rho)
        cov_a[2, 2] = max(cov_a[2, 2], amb**2)
        # Carried back from the window to t_a (ranges from too few beacons
        # before the first fix), what that can drift, as for the start.
        s_gap = float(np.interp(W_t[0], t_dr, travel) - np.interp(t_a, t_dr, travel))
        r_gap = float(np.interp(W_t[0], t_dr, turned) - np.interp(t_a, t_dr, turned))
        back_a = 2.0 * scale_sigma * s_gap
        cov_a += np.diag([floor**2 + back_a**2, floor**2 + back_a**2,
                          0.01**2 + (scale_sigma * r_gap + np.sqrt(2.0) * scale_sigma * s_gap / track) ** 2])
        cov_a /= ANCHOR_SHARE
        if cov_a[2, 2] < np.pi**2:
            anchor = Anchor(t_a, np.array([a0[0], a0[1], float(wrap_angle(a0[2]))]), cov_a,
                            float(W_t[-1]), int(keep.sum()))
    # Dead reckoning's own error back to the first wheel measurement, and a
    # floor for what the rigid-path model leaves out (timing, interpolation).
    cov[0, 0] += back**2 + floor**2
    cov[1, 1] += back**2 + floor**2
    cov[2, 2] += back_th**2 + 0.01**2
    if cov[2, 2] > np.pi**2:
        # A heading sigma beyond pi says "unknown"; cap it, scaling its row and
        # column with it so that the covariance stays positive definite.
        f = np.pi / np.sqrt(cov[2, 2])
        cov[2, :] *= f
        cov[:, 2] *= f
    note = (f"start fitted to {int(keep.sum())} of the first {m} fixes ({W_t[-1] - W_t[0]:.1f} s, "
            f"{W_sf[-1] - W_sf[0]:.1f} m of travel)" + (f", {n_out} rejected as outliers" if n_out else ""))
    if t_first_gap > 1.0:
        note += f"; carried back {t_first_gap:.1f} s to the first wheel measurement"
    return ConsensusFit(q[:3].copy(), cov, int(keep.sum()), n_out, note, warnings, anchor=anchor)
