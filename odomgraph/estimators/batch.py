"""Batch smoother: Levenberg-Marquardt over the whole log, on GTSAM's elimination.

Why not GTSAM's own LevenbergMarquardtOptimizer with CustomFactors: inside
GTSAM's optimisers every Python callback receives a copy of the whole Values,
so one iteration costs O(n^2) (ESTIMATION-NOTES.md; benchmarks/README.md
measures it as the "straightforward" peer). Here every factor is linearised
for all keyframes at once in numpy (graph.py, the EKF's models), the rows of
each keyframe interval become one gtsam.JacobianFactor on (k, k+1), and GTSAM
eliminates the chain in time order (linear in the log length; COLAMD was
1.6x slower on this structure). Marginals come from the eliminated Bayes net
by the backward recursion
    Sigma_k = R_k^-1 R_k^-T + (R_k^-1 S_k) Sigma_{k+1} (R_k^-1 S_k)^T,
also linear, where GTSAM's Marginals would query the Bayes tree key by key.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np

from factors import pose2
from factors._math import wrap_angle
from factors.motion import propagate
from odomgraph import state as S
from odomgraph.checks import bounded, check_fields
from odomgraph.errors import EstimatorDivergedError
from odomgraph.estimators.graph import NB, Linearization, Problem, linearize
from odomgraph.estimators.initial import initial_state
from odomgraph.estimators.keyframes import build_keyframes
from odomgraph.estimators.measurements import from_log, slip_intensity
from odomgraph.estimators.observability import decondition
from odomgraph.estimators.result import Estimate
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import Log


@dataclass(frozen=True)
class SmootherOptions:
    keyframe_hz: float = bounded(5.0, gt=0, le=1000)
    """Keyframe rate [Hz] (at most the encoder rate); slip is resolved at this rate."""
    max_iterations: int = bounded(50, ge=1, integer=True)
    rel_tol: float = bounded(1e-7, gt=0, lt=1)
    """Stop when the cost decreases by less than this fraction."""
    robust: str | None = bounded(None, choices=("huber", "cauchy"), optional=True)
    """Robust loss of GPS fixes and ranges: "huber", "cauchy" or None (Gaussian)."""
    robust_k: float | None = bounded(None, gt=0, optional=True)
    """Its threshold in sigmas (None: the loss's 95 %-efficiency default)."""
    slip_cauchy: float | None = bounded(0.005, gt=0, optional=True)
    """Cauchy scale [m/s] of the sparse zero-slip prior outside the calibration
    window (the whole log with ``calibrate_until=None``). None: no prior there,
    slip is a free random walk after the window as in the EKF."""
    range_bias: bool = False
    """Estimate a constant range bias per beacon (UWB antenna delays, NLOS offsets)."""
    range_bias_sigma: float = bounded(0.5, gt=0)
    """Prior 1-sigma of each range bias [m]."""
    velocity_loss: str | None = bounded(None, choices=("huber", "cauchy"), optional=True)
    """Robust loss of the velocity random walk ("huber", "cauchy"; None: Gaussian).
    For robots whose speed jumps (in-place pivots started and stopped at once)."""
    wheel_speed_units: bool = True
    """With a calibration window, take the v and slip random walks in
    wheel-speed units (graph.linearize): no prior then pays for shrinking the
    speeds into larger scale factors. False: the plain walks (as isam2,
    fixed-lag and the EKF)."""

    def __post_init__(self):
        check_fields(self)


def build_problem(log: Log, schedule: Schedule, options: SmootherOptions, causal: bool = False) -> Problem:
    """The keyframe graph of a log: same initialisation and schedule as the EKF.
    ``causal``: no interval's factors read data after its end (incremental smoothers)."""
    meas = from_log(log)
    init = initial_state(log.robot, meas)
    kf = build_keyframes(log, init.t, options.keyframe_hz, causal)
    if kf.n < 3:
        raise EstimatorDivergedError("the log is too short for the smoother: fewer than 3 keyframes")
    # Move the initial state to the first keyframe (a fraction of an encoder period).
    mean = init.x.copy()
    p, _ = propagate(mean[0], mean[1], mean[2], mean[3], mean[4], kf.t[0] - init.t)
    mean[0:3] = p
    cov = init.P.copy()
    mid = 0.5 * (kf.t[1:] + kf.t[:-1])
    if not init.observability.slip_observable:
        zero = np.ones(kf.n - 1, bool)           # nothing but the wheels sees the motion: no slip
    elif schedule.calibrate_until is None:
        zero = np.zeros(kf.n - 1, bool)
    else:
        zero = mid < meas.t_start + schedule.calibrate_until
    robust = options.slip_cauchy
    if options.range_bias and not (kf.rng_k.size and log.robot.beacons):
        from odomgraph.errors import OdomgraphError
        raise OdomgraphError("--range-bias: the log has no ranges to estimate a bias from")
    return Problem(kf, log.robot, mean, cov, zero, robust, slip_intensity(log.robot.process, meas), options.robust,
                   options.robust_k, options.range_bias_sigma if options.range_bias else None,
                   options.velocity_loss, init=init)


def initial_guess(prob: Problem, ekf: Estimate) -> tuple[np.ndarray, np.ndarray]:
    """Keyframe estimate from a filter run: poses at t_k, interval averages of the rest.

    Starting from dead reckoning with wrong scale factors, batch solves can
    fall into a wrong minimum (ESTIMATION-NOTES.md); the filter starts them
    near the answer.
    """
    t = prob.kf.t
    m = ekf.mean
    pose = np.stack([np.interp(t, ekf.t, m[:, S.X]), np.interp(t, ekf.t, m[:, S.Y]),
                     wrap_angle(np.interp(t, ekf.t, np.unwrap(m[:, S.THETA])))], -1)
    W = np.empty((len(t), 8))
    mid = np.append(0.5 * (t[1:] + t[:-1]), t[-1])
    for j, i in enumerate(range(S.V, S.N)):
        W[:, j] = np.interp(mid, ekf.t, m[:, i])
    W[:, 5:8] = m[-1, S.SCALE]
    return pose, W


def _factor_arrays(prob: Problem, lin: Linearization):
    """Stack each interval's rows: A1 on block k, A2 on block k+1, b."""
    n1 = lin.A_u.shape[0]
    ru = lin.A_u.shape[1]
    rows = ru + 3 + 8
    A1 = np.zeros((n1, rows, NB))
    A2 = np.zeros((n1, rows, NB))
    b = np.empty((n1, rows))
    A1[:, :ru] = lin.A_u
    A1[:, ru:ru + 3] = lin.A_m0
    A2[:, ru:ru + 3, 0:3] = lin.A_m1
    A1[:, ru + 3:, 3:] = lin.A_w0
    A2[:, ru + 3:, 3:] = lin.A_w1
    b[:, :ru] = lin.b_u
    b[:, ru:ru + 3] = lin.b_m
    b[:, ru + 3:] = lin.b_w
    return A1, A2, b


def gaussian_graph(prob: Problem, lin: Linearization) -> gtsam.GaussianFactorGraph:
    """The linearised problem as a GTSAM graph: one JacobianFactor per interval on (k, k+1)."""
    A1, A2, b = _factor_arrays(prob, lin)
    g = gtsam.GaussianFactorGraph()
    g.add(gtsam.JacobianFactor(0, lin.A_p, lin.b_p, gtsam.noiseModel.Unit.Create(NB)))
    unit = gtsam.noiseModel.Unit.Create(A1.shape[1])
    for k in range(prob.kf.n - 1):
        g.add(gtsam.JacobianFactor(k, A1[k], k + 1, A2[k], b[k], unit))
    if prob.n_bias:
        # The bias vector is one more variable, key n, eliminated last: each
        # interval's ranges become one factor on (k, n).
        n, kr = prob.kf.n, prob.kf.rng_k
        g.add(gtsam.JacobianFactor(n, lin.A_bp, lin.b_bp, gtsam.noiseModel.Unit.Create(prob.n_bias)))
        if lin.A_r is not None:
            cuts = np.flatnonzero(np.diff(kr)) + 1
            for sel in np.split(np.arange(kr.size), cuts):
                g.add(gtsam.JacobianFactor(int(kr[sel[0]]), lin.A_r[sel], n, lin.A_rb[sel], lin.b_r[sel],
                                           gtsam.noiseModel.Unit.Create(sel.size)))
    return g


def time_ordering(n: int, n_global: int = 0) -> gtsam.Ordering:
    """Keyframes in time order (the chain eliminates with no fill), then the
    global variables (keys n, n+1, ...) last."""
    o = gtsam.Ordering()
    for k in range(n + n_global):
        o.push_back(k)
    return o


def retract(pose: np.ndarray, W: np.ndarray, d: np.ndarray):
    x, y, th = pose2.retract(pose[:, 0], pose[:, 1], pose[:, 2], d[:, 0:3])
    return np.stack([x, y, wrap_angle(th)], -1), W + d[:, 3:]


def solve(prob: Problem, pose: np.ndarray, W: np.ndarray, options: SmootherOptions, progress=None):
    """Gauss-Newton with a backtracking line search.

    Returns (pose, W, iterations, cost, range_bias); range_bias is None
    unless the problem estimates it.

    Not Levenberg-Marquardt with Marquardt damping: the scale factors are
    per-keyframe copies tied by very tight random-walk factors, so diag(A^T A)
    is ~1e10 on their columns and Marquardt damping freezes exactly the
    direction that calibration has to move (measured: LM stopped 1 sigma short
    in a flat valley). Started near the answer (from the EKF), full
    Gauss-Newton steps with step halving converge in a few iterations.
    """
    n, nb = prob.kf.n, prob.n_bias
    order = time_ordering(n, 1 if nb else 0)
    rb = np.zeros(nb) if nb else None
    lin = linearize(prob, pose, W, range_bias=rb)
    it = 0
    for it in range(1, options.max_iterations + 1):
        if progress is not None:
            progress(it, options.max_iterations)
        vv = gaussian_graph(prob, lin).optimize(order, gtsam.EliminateQR)
        d = np.stack([vv.at(k) for k in range(n)])
        db = vv.at(n) if nb else None
        if not (np.all(np.isfinite(d)) and (db is None or np.all(np.isfinite(db)))):
            raise EstimatorDivergedError(f"batch smoother diverged at iteration {it}: non-finite step")
        alpha = 1.0
        while True:
            pose_n, W_n = retract(pose, W, alpha * d)
            rb_n = rb + alpha * db if nb else None
            lin_n = linearize(prob, pose_n, W_n, range_bias=rb_n)
            if lin_n.cost <= lin.cost or alpha < 1e-3:
                break
            alpha *= 0.5
        if lin_n.cost > lin.cost:
            break  # no descent left along the Gauss-Newton direction: converged
        decrease = (lin.cost - lin_n.cost) / max(lin.cost, 1e-300)
        pose, W, rb, lin = pose_n, W_n, rb_n, lin_n
        if decrease < options.rel_tol:
            break
    return pose, W, it, lin.cost, rb


def marginal_blocks(prob: Problem, pose: np.ndarray, W: np.ndarray, range_bias: np.ndarray | None = None):
    """(N, 11, 11) marginal covariance of each keyframe block (pose part in the body frame).

    With range biases (a global variable g eliminated last) the recursion
    carries the cross-covariance with g: for the conditional
    x_k = R^-1 (d - S [x_{k+1}; g]),
        Sigma_k  = R^-1 R^-T + A Sigma_yy A^T,   Sigma_kg = -A Sigma_yg,   A = R^-1 S,
    with y the conditional's parents. Then returns (blocks, Sigma_gg).
    """
    lin = linearize(prob, pose, W, range_bias=range_bias)
    g = gaussian_graph(prob, lin)
    n, nb = prob.kf.n, prob.n_bias
    bn = g.eliminateSequential(time_ordering(n, 1 if nb else 0), gtsam.EliminateQR)
    Sig = np.empty((n, NB, NB))
    if not nb:
        c = bn.at(n - 1)
        Rinv = np.linalg.inv(c.R())
        Sig[n - 1] = Rinv @ Rinv.T
        for k in range(n - 2, -1, -1):
            c = bn.at(k)
            Rinv = np.linalg.inv(c.R())
            A = Rinv @ c.S()
            Sig[k] = Rinv @ Rinv.T + A @ Sig[k + 1] @ A.T
        return Sig
    Rg = np.linalg.inv(bn.at(n).R())
    Sgg = Rg @ Rg.T
    cross = np.zeros((n, NB, nb))     # Sigma_{k, g}
    for k in range(n - 1, -1, -1):
        c = bn.at(k)
        keys = list(c.keys())[1:]
        Rinv = np.linalg.inv(c.R())
        A = Rinv @ c.S()
        blocks = {n: (Sgg, None)}
        if k + 1 < n:
            blocks[k + 1] = (Sig[k + 1], cross[k + 1])
        # Sigma_yy and Sigma_yg over the parents, in the conditional's key order.
        dims = [NB if key < n else nb for key in keys]
        m = sum(dims)
        Syy = np.zeros((m, m))
        Syg = np.zeros((m, nb))
        off = np.cumsum([0] + dims)
        for a, ka in enumerate(keys):
            sa = slice(off[a], off[a + 1])
            Syg[sa] = Sgg if ka == n else cross[ka]
            for b_, kb in enumerate(keys):
                sb = slice(off[b_], off[b_ + 1])
                if ka == kb:
                    Syy[sa, sb] = Sgg if ka == n else Sig[ka]
                elif ka == n:
                    Syy[sa, sb] = cross[kb].T
                else:
                    Syy[sa, sb] = cross[ka]
        Sig[k] = Rinv @ Rinv.T + A @ Syy @ A.T
        cross[k] = -A @ Syg
    return Sig, Sgg


def honest_blocks(prob: Problem, Sig: np.ndarray) -> np.ndarray:
    """Keyframe block marginals (N, 11, 11) with the prior uncertainty of the
    pinned scale combinations given back (observability.decondition); Sig
    itself when nothing is pinned. Each block holds its keyframe's scale copy,
    so the pose-scale cross-covariance the correction needs is in the block."""
    obs = prob.init.observability if prob.init is not None else None
    if obs is None or not obs.unobservable:
        return Sig
    return decondition(Sig, obs, [8, 9, 10], obs.prior_sigma)


def keyframe_rows(prob: Problem, pose: np.ndarray, W: np.ndarray, Sig: np.ndarray | None, method: str,
                  rows: slice = slice(None)) -> Estimate:
    """States at interval midpoints: the pose flown half an interval from X_k, W_k's averages.

    Row k describes interval k, so its velocity, slip and bias are the averages
    they are estimated as; sigma is propagated through the same arc.
    """
    kf = prob.kf
    k = np.arange(kf.n - 1)[rows]
    half = 0.5 * kf.dt[k]
    t = kf.t[k] + half
    p, Jf = propagate(pose[k, 0], pose[k, 1], pose[k, 2], W[k, 0], W[k, 1], half)
    mean = np.empty((len(k), S.N))
    mean[:, 0:2] = p[:, 0:2]
    mean[:, 2] = wrap_angle(p[:, 2])
    mean[:, 3:] = W[k]
    sigma = np.zeros((len(k), S.N))
    pose_cov = None
    if Sig is not None:
        # d pose_mid / d block: body-frame pose columns and (v, omega).
        J = np.zeros((len(k), 3, NB))
        J[:, :, 0:3] = pose2.to_body(Jf[:, :, 0:3], pose[k, 2])
        J[:, :, 3:5] = Jf[:, :, 3:5]
        pose_cov = J @ Sig[k] @ np.swapaxes(J, 1, 2)
        sigma[:, 0:3] = np.sqrt(np.maximum(np.diagonal(pose_cov, 0, 1, 2), 0))
        sigma[:, 3:] = np.sqrt(np.maximum(np.diagonal(Sig[k], 0, 1, 2)[:, 3:], 0))
    return Estimate(method=method, t=t, mean=mean, sigma=sigma, pose_cov=pose_cov)


def run_batch(log: Log, schedule: Schedule = Schedule(), options: SmootherOptions = SmootherOptions(),
              progress=None, initial: Estimate | None = None) -> Estimate:
    """Smooth the whole log. Starts from ``initial``, an EKF estimate of the same
    log, or runs the EKF for it (same schedule; 20 s when there is none)."""
    from odomgraph.estimators.ekf import run_ekf
    wall0 = time.perf_counter()
    prob = build_problem(log, schedule, options)
    ekf_schedule = schedule if schedule.calibrate_until is not None else Schedule(20.0)
    ekf = initial if initial is not None else run_ekf(log, ekf_schedule)
    pose, W = initial_guess(prob, ekf)
    if options.wheel_speed_units:
        prob.speed_ref = W[0, 5:8].copy()   # the units of the random walks (graph.linearize)
    pose, W, iters, cost, rb = solve(prob, pose, W, options, progress)
    if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(W))):
        raise EstimatorDivergedError("batch smoother diverged: non-finite estimate")
    Sig = marginal_blocks(prob, pose, W, rb)
    if rb is not None:
        Sig, Sgg = Sig
    given = Sig[-1][8:11, 8:11].copy()
    Sig = honest_blocks(prob, Sig)
    est = keyframe_rows(prob, pose, W, Sig, "batch")
    if rb is not None:
        est.range_bias = {b.id: {"value": float(v), "sigma": float(np.sqrt(Sgg[i, i]))}
                          for i, (b, v) in enumerate(zip(log.robot.beacons, rb))}
    est.wall_time_s = time.perf_counter() - wall0
    est.n_updates = _n_measurements(prob)
    t0 = from_log(log).t_start
    est.t_switch = None if schedule.calibrate_until is None else t0 + schedule.calibrate_until
    est.calibration_sigma = np.sqrt(np.diagonal(Sig[-1])[8:11])
    est.calibration_cov = Sig[-1][8:11, 8:11].copy()
    est.calibration_cov_given = given
    est.observability = prob.init.observability
    est.warnings = list(prob.init.warnings)
    est.notes = [f"batch: {prob.kf.n} keyframes at {options.keyframe_hz:g} Hz, {iters} LM iterations, "
                 f"final cost {cost:.1f}"] + list(ekf.notes)
    return est


def _n_measurements(prob: Problem) -> int:
    kf = prob.kf
    return int(kf.n - 1 + np.sum(kf.gyro_n) + np.sum(kf.vel_n) + kf.gps_k.size + kf.rng_k.size)
