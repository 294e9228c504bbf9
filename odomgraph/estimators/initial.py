"""The first state and its covariance, from the data when robot.toml has no [initial].

LOG_FORMAT forbids assuming a start at the origin. Position comes from the
first absolute fixes (GPS, or multilateration of the first ranges); heading
from the first motion: the direction between two fixes far enough apart,
corrected for the turn the wheels report in between and for reversing. The
estimator starts at the second fix's time, so this stays causal: nothing after
the start time is used.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from factors import encoder
from factors._math import rot2, wrap_angle
from odomgraph import state as S
from odomgraph.errors import NotEnoughDataError
from odomgraph.estimators.measurements import Measurements
from odomgraph.estimators.observability import Observability, prior_scale_cov, structure
from odomgraph.io.robot import RobotConfig

#: Most heading change between the two fixes for the chord to give a heading [rad].
_MAX_TURN = 0.35
#: Longest multilateration window: ranges older than this are not combined [s].
_RANGE_WINDOW = 0.6


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


def _wheel_rates(robot: RobotConfig, meas: Measurements):
    v, w = encoder.body_velocity(meas.wheel.m[:, 0], meas.wheel.m[:, 1], 0.0, 0.0, 1.0, 1.0, 1.0,
                                 robot.track_width)
    return meas.wheel.t, v, w


def _integral(t, rate, t0, t1):
    """Integral of a sampled rate over [t0, t1] (trapezoid on a fine grid)."""
    if t1 <= t0:
        return 0.0
    grid = np.linspace(t0, t1, max(3, int((t1 - t0) * 50)))
    return float(np.trapezoid(np.interp(grid, t, rate), grid))


def _range_fixes(meas: Measurements, robot: RobotConfig, limit: int = 400):
    """Multilateration fixes (t, xy, sigma) from the first ranges (Gauss-Newton)."""
    t, bxy, rr = meas.ranges
    out_t, out_p, out_s = [], [], []
    latest: dict[tuple, tuple[float, float]] = {}
    sig_r = robot.range_sigma + float(np.hypot(*robot.range_lever_arm))
    for k in range(min(len(t), limit)):
        latest[tuple(bxy[k])] = (t[k], rr[k])
        pts = [(np.array(b), r) for b, (tb, r) in latest.items() if t[k] - tb <= _RANGE_WINDOW]
        if len(pts) < 3:
            continue
        B = np.array([p for p, _ in pts])
        R = np.array([r for _, r in pts])
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
        cov = np.linalg.inv(JtJ) * sig_r**2
        out_t.append(t[k]); out_p.append(p); out_s.append(float(np.sqrt(np.max(np.linalg.eigvalsh(cov)))))
    if not out_t:
        return None
    return np.array(out_t), np.array(out_p), np.array(out_s), (0.0, 0.0)


def initial_state(robot: RobotConfig, meas: Measurements) -> InitialState:
    x = S.NOMINAL.copy()
    P = np.zeros((S.N, S.N))
    pn = robot.process
    P[S.BIAS, S.BIAS] = pn.initial_bias_sigma**2
    P[S.SLIP_L, S.SLIP_L] = P[S.SLIP_R, S.SLIP_R] = pn.initial_slip_sigma**2
    obs = structure(robot, meas)
    extra = () if obs.slip_observable else (
        "slip is not observable: nothing but the wheels sees the motion (no gyro, velocity sensor or absolute "
        "fixes), so it is taken as zero throughout (plain dead reckoning)",)
    P[np.ix_(S.SCALE, S.SCALE)] = prior_scale_cov(obs, pn.initial_scale_sigma)
    tw, vw, ww = _wheel_rates(robot, meas)

    def finish(t0, pose, pose_cov, note, warnings=()):
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
        return InitialState(float(t0), x, P, note, obs, tuple(warnings) + extra)

    if robot.initial is not None:
        i = robot.initial
        t0 = min([tw[0], *(s[0][0] for s in (meas.gyro, meas.gps, meas.ranges, meas.velocity) if s is not None)])
        return finish(t0, np.array([i.x, i.y, i.theta]), np.diag(np.square(i.sigma)),
                      "initial pose from robot.toml [initial]")

    fixes, source = None, ""
    if meas.gps is not None:
        fixes, source = (*meas.gps, robot.gps_lever_arm), "GPS"
    elif meas.ranges is not None:
        fixes, source = _range_fixes(meas, robot), "multilateration of the first ranges"
    if fixes is None:
        t0 = tw[0]
        msg = ("no absolute sensor and no [initial] pose in robot.toml: the start pose is taken as the origin, "
               "heading 0 (positions are relative to it)")
        return finish(t0, np.zeros(3), np.diag([1e-6, 1e-6, 1e-6]), msg, (msg,))

    ft, fp, fs, lever = fixes
    lever = np.asarray(lever, float)
    lev = float(np.hypot(*lever))
    for i in range(len(ft)):
        for k in range(i + 1, len(ft)):
            d = fp[k] - fp[i]
            dist = float(np.hypot(*d))
            # Far enough for the chord to give a good heading (the heading sigma
            # below says how good). GPS is used outdoors with room to drive:
            # wait for 1 m and 20 fix sigmas. Ranges are used indoors, where a
            # labyrinth rarely offers a straight metre: 0.5 m and 5 sigmas.
            d_min, n_sig = (1.0, 20.0) if source == "GPS" else (0.5, 5.0)
            if dist < max(d_min, n_sig * max(fs[i], fs[k])):
                continue
            turn = _integral(tw, ww, ft[i], ft[k])
            if abs(turn) > _MAX_TURN:
                break  # the robot turned in between: try a later first fix
            travelled = _integral(tw, vw, ft[i], ft[k])
            chord = np.arctan2(d[1], d[0]) + (np.pi if travelled < 0 else 0.0)
            theta = chord + 0.5 * turn
            # chord noise, lever arm swept by the turn, arc-vs-chord, scale error of the turn
            s_th = np.sqrt(2 * (fs[i] ** 2 + fs[k] ** 2) / dist**2 + (lev * abs(turn) / dist) ** 2
                           + (0.25 * turn) ** 2 + 0.03**2)
            pos = fp[k] - rot2(theta) @ lever
            s_p = np.sqrt(fs[k] ** 2 + (lev * s_th) ** 2)
            return finish(ft[k], np.array([pos[0], pos[1], theta]), np.diag([s_p**2, s_p**2, s_th**2]),
                          f"initial pose from {source}: position at t={ft[k]:.2f} s, heading from "
                          f"{dist:.2f} m of motion")
    # Never moved far enough in a straight line: position only, heading unknown.
    s_p = float(np.sqrt(fs[0] ** 2 + lev**2))
    return finish(ft[0], np.array([fp[0][0], fp[0][1], 0.0]), np.diag([s_p**2, s_p**2, np.pi**2]),
                  f"initial position from {source}; heading not observable from the first motion (sigma = pi)")
