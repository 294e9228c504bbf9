"""Peers that the benchmarks and tests compare odomgraph against.

``FilterPyEKF`` is the paper's EKF built on FilterPy's ExtendedKalmanFilter:
the same models (factors), process noise, schedule and event loop, with
FilterPy doing every predict and update. It only supports the paper's literal
pseudo-update hold and the paper's encoder update (EKFOptions.encoder_scale_gain:
FilterPy has no consider update); the gate is ours, applied before FilterPy's update.
"""
from __future__ import annotations

import numpy as np
from filterpy.kalman import ExtendedKalmanFilter

from odomgraph.factors._math import wrap_angle
from odomgraph.factors.motion import propagate
from odomgraph import state as S
from odomgraph.estimators.ekf import EKF, EKFOptions, add_process_noise
from odomgraph.estimators.schedule import Hold, Schedule


class FilterPyEKF(EKF):
    def __init__(self, log, schedule: Schedule = Schedule(hold=Hold.pseudo), **kw):
        if schedule.hold is not Hold.pseudo:
            raise ValueError("FilterPy has no consider update: use Hold.pseudo")
        kw.setdefault("options", EKFOptions(encoder_scale_gain=True))
        if not kw["options"].encoder_scale_gain:
            raise ValueError("FilterPy has no consider update: use EKFOptions(encoder_scale_gain=True)")
        super().__init__(log, schedule, **kw)
        self.fp = ExtendedKalmanFilter(dim_x=S.N, dim_z=1)
        self.fp.x = self.x
        self.fp.P = self.P

    def predict(self, t: float) -> None:
        dt = t - self.t
        if dt <= 0.0:
            return
        fp = self.fp
        pose, J = propagate(*fp.x[:5], dt)
        F = np.eye(S.N)
        F[0:3, 0:5] = J
        Q = np.zeros((S.N, S.N))
        add_process_noise(Q, J, dt, self._q, self._q_slip)
        fp.F, fp.Q = F, Q

        def predict_x(u=0):
            fp.x[0], fp.x[1], fp.x[2] = pose[0], pose[1], wrap_angle(pose[2])
        fp.predict_x = predict_x
        fp.predict()
        self.x, self.P, self.t = fp.x, fp.P, t

    def update(self, z, h, H, idx, R, gate=None, ref=None, no_gain=None, huber=False) -> float:
        assert not self.holding_scale and no_gain is None
        Hfull = np.zeros((H.shape[0], S.N))
        Hfull[:, idx] = H
        fp = self.fp
        y = np.atleast_1d(z) - h
        self.last_y = y
        if gate is not None:     # the same Mahalanobis gate as ours, before FilterPy's update
            Sm = Hfull @ fp.P @ Hfull.T + R
            nis = float(y @ np.linalg.solve(Sm, y))
            d = y if ref is None else y - ref
            if nis > gate and (ref is None or float(d @ np.linalg.solve(Sm, d)) > gate):
                return -nis
            if nis > gate and huber:      # rescued, at a Huber weight (EKF.update)
                R = R + Sm * (nis / gate - 1.0)
        fp.update(np.atleast_1d(z), lambda x: Hfull, lambda x: h, R=R)
        fp.x[2] = wrap_angle(fp.x[2])
        self.x, self.P = fp.x, fp.P
        y = np.atleast_1d(z) - h
        return float(y @ np.linalg.solve(fp.S, y))


# --------------------------------------------------------------------------
# The straightforward GTSAM design: the same keyframe graph built from plain
# gtsam.CustomFactors (factors/gtsam_factors.py), solved by GTSAM's own
# LevenbergMarquardtOptimizer or by one ISAM2 update per keyframe.
def straightforward_graph(prob, k0: int = 0, k1: int | None = None):
    """NonlinearFactorGraph of intervals k0..k1-1 (plus the prior when k0 == 0).
    The slips' random walk is Gaussian here (isam2's built-in BetweenFactor),
    where batch weighs its common-mode step by a Huber loss (graph.walk_rows):
    one row an interval reweighted, the same work per iteration."""
    import gtsam
    from gtsam.symbol_shorthand import S as SK, W as WK, X as XK
    from odomgraph.factors import gtsam_factors as gf
    from odomgraph.estimators.incremental import S_IDX, W_IDX
    kf, r = prob.kf, prob.robot
    k1 = kf.n - 1 if k1 is None else k1
    g = gtsam.NonlinearFactorGraph()
    if k0 == 0:
        m, P = prob.prior_mean, prob.prior_cov
        c, s = np.cos(m[2]), np.sin(m[2])
        Rb = np.eye(3)
        Rb[0:2, 0:2] = [[c, s], [-s, c]]
        g.add(gtsam.PriorFactorPose2(XK(0), gtsam.Pose2(*m[0:3]),
                                     gtsam.noiseModel.Gaussian.Covariance(Rb @ P[0:3, 0:3] @ Rb.T)))
        g.add(gtsam.PriorFactorVector(WK(0), m[3:][W_IDX], gtsam.noiseModel.Gaussian.Covariance(
            P[3:, 3:][np.ix_(W_IDX, W_IDX)])))
        g.add(gtsam.PriorFactorVector(SK(0), m[3:][S_IDX], gtsam.noiseModel.Gaussian.Covariance(
            P[3:, 3:][np.ix_(S_IDX, S_IDX)])))
    from odomgraph.estimators.incremental import IncrementalOptions, _Graph
    builtins = _Graph(prob, IncrementalOptions(slip_cauchy=prob.slip_robust))
    for k in range(k0, k1):
        g.add(gf.encoder_factor(WK(k), SK(k), kf.enc_m[k], gtsam.noiseModel.Diagonal.Sigmas(kf.enc_sigma[k]),
                                r.track_width))
        if np.isfinite(kf.gyro_sigma[k]):
            g.add(gf.gyro_factor(WK(k), kf.gyro_z[k], gtsam.noiseModel.Isotropic.Sigma(1, kf.gyro_sigma[k])))
        if np.all(np.isfinite(kf.vel_sigma[k])):
            g.add(gf.velocity_factor(WK(k), kf.vel_z[k], gtsam.noiseModel.Diagonal.Sigmas(kf.vel_sigma[k])))
        for i in range(*np.searchsorted(kf.gps_k, [k, k + 1])):
            g.add(gf.gps_factor(XK(k), WK(k), kf.gps_xy[i], kf.gps_tau_vw[i], r.gps_lever_arm,
                                gtsam.noiseModel.Isotropic.Sigma(2, kf.gps_sigma[i]), q=kf.gps_bend[i]))
        for i in range(*np.searchsorted(kf.rng_k, [k, k + 1])):
            g.add(gf.range_factor(XK(k), WK(k), kf.rng_z[i], kf.rng_tau_vw[i], kf.rng_beacon[i], r.range_lever_arm,
                                  gtsam.noiseModel.Isotropic.Sigma(1, r.range_sigma), q=kf.rng_bend[i]))
        g.add(gf.motion_factor(XK(k), WK(k), XK(k + 1), kf.dt[k],
                               gtsam.noiseModel.Diagonal.Sigmas(1.0 / prob.motion_whiten[k]), q=kf.trans_bend[k]))
        g.push_back(builtins.builtin_factors(k))
    return g


def _values(pose, Wv, ks):
    import gtsam
    from gtsam.symbol_shorthand import S as SK, W as WK, X as XK
    from odomgraph.estimators.incremental import S_IDX, W_IDX
    v = gtsam.Values()
    for k in ks:
        v.insert(XK(k), gtsam.Pose2(*pose[k]))
        v.insert(WK(k), Wv[k, W_IDX].copy())
        v.insert(SK(k), Wv[k, S_IDX].copy())
    return v


def straightforward_lm(log, schedule, options, max_iterations: int = 100):
    """gtsam.LevenbergMarquardtOptimizer over the CustomFactor graph, from the EKF. Returns (seconds, iterations)."""
    import time
    import gtsam
    from odomgraph.estimators import batch as B
    from odomgraph.estimators.ekf import run_ekf
    prob = B.build_problem(log, schedule, options)
    pose, Wv = B.initial_guess(prob, run_ekf(log, schedule))
    g = straightforward_graph(prob)
    v = _values(pose, Wv, range(prob.kf.n))
    params = gtsam.LevenbergMarquardtParams()
    params.setMaxIterations(max_iterations)
    t0 = time.perf_counter()
    opt = gtsam.LevenbergMarquardtOptimizer(g, v, params)
    opt.optimize()
    return time.perf_counter() - t0, opt.iterations()


def straightforward_isam2(log, schedule, options, time_limit: float = 600.0):
    """One ISAM2 update per keyframe with CustomFactors. Returns (seconds, per-update times, completed)."""
    import time
    import gtsam
    from odomgraph.factors.motion import propagate
    from odomgraph.estimators import batch as B
    prob = B.build_problem(log, schedule, options)
    n = prob.kf.n
    pose = np.zeros((n, 3))
    Wv = np.zeros((n, 8))
    pose[0], Wv[0] = prob.prior_mean[0:3], prob.prior_mean[3:]
    isam = gtsam.ISAM2(gtsam.ISAM2Params())
    isam.update(straightforward_graph(prob, 0, 0), _values(pose, Wv, [0]))
    times = []
    t_start = time.perf_counter()
    for k in range(1, n):
        t0 = time.perf_counter()
        p, _ = propagate(*pose[k - 1], Wv[k - 1, 0], Wv[k - 1, 1], prob.kf.dt[k - 1])
        pose[k], Wv[k] = p, Wv[k - 1]
        isam.update(straightforward_graph(prob, k - 1, k), _values(pose, Wv, [k]))
        est = isam.calculateEstimatePose2(gtsam.symbol_shorthand.X(k))
        pose[k] = [est.x(), est.y(), est.theta()]
        times.append(time.perf_counter() - t0)
        if time.perf_counter() - t_start > time_limit:
            return time.perf_counter() - t_start, np.array(times), False
    return time.perf_counter() - t_start, np.array(times), True
