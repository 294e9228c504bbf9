"""Batch smoother: Gauss-Newton over the whole log, on GTSAM's elimination.

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

import dataclasses
import math
import time
from dataclasses import dataclass

import gtsam
import numpy as np

from odomgraph.factors import pose2
from odomgraph.factors._math import wrap_angle
from odomgraph.factors.motion import arc_at, propagate, velocity_between
from odomgraph import state as S
from odomgraph.checks import bounded, check_fields
from odomgraph.errors import EstimatorDivergedError
from odomgraph.estimators.graph import NB, SLIP_STEP_K, Linearization, Problem, linearize, robust_counts
from odomgraph.estimators.initial import initial_state
from odomgraph.estimators.keyframes import build_keyframes
from odomgraph.estimators.measurements import clean, from_log, slip_intensity, yaw_rate_sensed
from odomgraph.estimators.priorcheck import (CHECK_K, SLIP_SEEN, Verdict, informed, slip_after_window,
                                              tangent_difference, verdict, widened)
from odomgraph.observability import decondition
from odomgraph.estimators.slipcheck import in_stretches, in_window
from odomgraph.estimators.standstill import still_intervals
from odomgraph.result import Estimate, SlipPriorRows
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import Log


@dataclass(frozen=True)
class GraphOptions:
    """The keyframe graph's options, which batch, isam2 and fixed-lag all
    take (BatchGraphOptions adds batch's own graph options and SmootherOptions
    its solver's; IncrementalOptions the incremental smoothers')."""
    keyframe_hz: float = bounded(5.0, ge=0.01, le=1000)
    """Keyframe rate [Hz] (at most the encoder rate); slip is resolved at this rate."""
    robust: str | None = bounded("cauchy", choices=("huber", "cauchy", "none"), optional=True)
    """Robust loss of GPS fixes and ranges: "cauchy" (default), "huber", or
    "none" (Gaussian). Real logs have outliers, some in the first seconds."""
    robust_k: float | None = bounded(None, gt=0, optional=True)
    """Its threshold in sigmas (None: 5 for Cauchy, 1.345 for Huber; graph.ROBUST_K)."""
    slip_cauchy: float | None = bounded(0.005, gt=0, optional=True)
    """Cauchy scale [m/s] of the sparse zero-slip prior outside the calibration
    window (the whole log with ``calibrate_until=None``). None: no prior there,
    slip is a free random walk after the window as in the EKF."""
    slip_check: bool = True
    """Where slip after the calibration window exceeds priorcheck.SLIP_SEEN,
    solve again without the sparse slip prior there (check_slip_prior).
    batch gives that solution where the two differ by more than
    priorcheck.CHECK_K sigma, and elsewhere widens its covariance to hold
    both means (applied by pipeline.estimate, after the checks of the fixes:
    Estimate.slip_check); isam2 and fixed-lag, whose rows were given as they
    came, are flagged there. False: the prior trusted unchecked."""
    pin: tuple[tuple[str, str], ...] = ()
    """(scale combination, reason) pairs to hold at nominal with their prior
    sigma, as if the log could not determine them (observability)."""
    wheel_speed_units: bool = True
    """With a calibration window, take the v and slip random walks in
    wheel-speed units (graph.walk_rows): no prior then pays for shrinking the
    speeds into larger scale factors. False: the plain walks (as the EKF)."""

    def __post_init__(self):
        check_fields(self)


@dataclass(frozen=True)
class BatchGraphOptions(GraphOptions):
    """The graph as batch builds it: the keyframe graph's options and what
    only batch implements (range-bias states, a robust velocity walk, Huber
    slip steps). isam2 and fixed-lag do not take these (IncrementalOptions
    derives from GraphOptions), so an estimator is never handed an option it
    would ignore (the registry says whose option it is)."""
    range_bias: bool = False
    """Estimate a constant range bias per beacon (UWB antenna delays, NLOS offsets)."""
    range_bias_sigma: float = bounded(0.5, gt=0)
    """Prior 1-sigma of each range bias [m]."""
    velocity_loss: str | None = bounded(None, choices=("huber", "cauchy"), optional=True)
    """Robust loss of the velocity random walk ("huber", "cauchy"; None: Gaussian).
    For robots whose speed jumps (in-place pivots started and stopped at once)."""
    slip_step_k: float | None = bounded(None, gt=0, infinite=True, optional=True)
    """Huber threshold [sigma] of the slips' common-mode random-walk step: a
    wheel that starts or stops spinning (a stall) steps its slip within a
    second, which Gaussian steps spread over several (graph.SLIP_STEP_K).
    inf: Gaussian steps, as the EKF's random walk. None: SLIP_STEP_K where a
    yaw-rate sensor covers the log (measurements.yaw_rate_sensed), Gaussian
    where none does: there a cheap common-mode step let a one-wheel slip be
    read as a spin in place (a yard log without a gyro, GPS at 5 Hz, a 0.8 m/s
    slip of one wheel: both slips +2 m/s, the heading 3 rad off, rows 0.75 m
    off at z 40, status ok; Gaussian steps: flagged)."""


@dataclass(frozen=True)
class SmootherOptions(BatchGraphOptions):
    """The batch smoother's options: its graph's, and its Gauss-Newton solver's."""
    max_iterations: int = bounded(50, ge=1, integer=True)
    rel_tol: float = bounded(1e-7, gt=0, lt=1)
    """Stop when the cost decreases by less than this fraction,"""
    abs_tol: float = bounded(0.01, gt=0)
    """or by less than this much (cost = half the sum of whitened squares): a
    chi-square change of 0.02 moves no estimate by a noticeable part of its
    sigma, and the tight scale-factor chain otherwise crawls on for dozens of
    iterations in its flat valley."""


def build_problem(log: Log, schedule: Schedule, options: GraphOptions, causal: bool = False) -> Problem:
    """The keyframe graph of a log: same initialisation and schedule as the EKF.
    ``causal``: no interval's factors read data after its end (incremental smoothers)."""
    meas = from_log(log)
    init = initial_state(log.robot, meas, dict(options.pin))
    kf = build_keyframes(clean(log)[0], init.t, options.keyframe_hz, causal)
    if kf.n < 3:
        raise EstimatorDivergedError("the log is too short for the smoother: fewer than 3 keyframes")
    # Move the initial state to the first keyframe (a fraction of an encoder period).
    mean = init.x.copy()
    p, _ = propagate(mean[0], mean[1], mean[2], mean[3], mean[4], kf.t[0] - init.t)
    mean[0:3] = p
    cov = init.P.copy()
    # The standstills (estimators.standstill) as batch sees them, whole; the
    # causal smoothers' graph reads no data after an interval's end, and a
    # stretch is known still only with hindsight (the EKF's StillWatch is causal).
    still = still_intervals(kf.t, init.still) if not causal else np.zeros(len(kf.t) - 1, bool)
    window = zero_slip_intervals(kf.t, init, meas.t_start, schedule)
    zero = window | still
    robust = options.slip_cauchy
    # batch's own graph options; isam2's and fixed-lag's graph has none of them
    own = options if isinstance(options, BatchGraphOptions) else BatchGraphOptions(slip_step_k=math.inf)
    if own.range_bias and not (kf.rng_k.size and log.robot.beacons):
        from odomgraph.errors import OdomgraphError
        raise OdomgraphError("--range-bias: the log has no ranges to estimate a bias from")
    loss = None if options.robust in (None, "none") else options.robust
    sensed = yaw_rate_sensed(meas)
    step_k = own.slip_step_k
    if step_k is None:
        step_k = SLIP_STEP_K if sensed else math.inf
    return Problem(kf, log.robot, mean, cov, zero, robust, slip_intensity(log.robot.process, meas, sensed), loss,
                   options.robust_k, own.range_bias_sigma if own.range_bias else None,
                   own.velocity_loss, slip_step_k=step_k, init=init,
                   spikes=dict(meas.spikes), meas=meas, window=window if still.any() else None)


def zero_slip_intervals(t: np.ndarray, init, t_start: float, schedule: Schedule) -> np.ndarray:
    """(N-1,) the keyframe intervals (keyframe times t (N,) [s]) forced to zero
    slip: the schedule's calibration window from the log's t_start, less
    where the wheels slipped (init.slipping), or all of them when slip is not
    observable."""
    mid = 0.5 * (t[1:] + t[:-1])
    if not init.observability.slip_observable:
        return np.ones(len(mid), bool)            # nothing but the wheels sees the motion: no slip
    if schedule.calibrate_until is None:
        return np.zeros(len(mid), bool)
    zero = mid < t_start + schedule.calibrate_until
    slipping, _ = in_window(schedule.slip_stretches(init.slipping), t_start, t_start + schedule.calibrate_until)
    return zero & ~in_stretches(mid, slipping)


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
    W[:, S.W_SCALE] = m[-1, S.SCALE]
    # v and omega of each interval from its two poses, so that the start obeys
    # the motion model: the motion rows are 1e-4 rad / 1 mm tight, and the
    # filter's rates at interval midpoints miss its own poses by enough for a
    # start cost of ~1e8 (the libRSF cut), whose first Gauss-Newton step then
    # lands in the slip model's mirror solution.
    # Only where the interval turns less than MAX_GUESS_TURN (the filter's
    # unwrapped heading says): a wrapped half turn is ambiguous, and the arc's
    # speed diverges as the turn nears it.
    th_u = np.interp(t, ekf.t, np.unwrap(m[:, S.THETA]))
    ok = np.abs(np.diff(th_u)) < MAX_GUESS_TURN
    # The motion model bends the arc's chord to the path's shape
    # (Keyframes.trans_bend): the arc whose bent chord meets the next pose
    # is the one whose plain chord meets it unbent, less the offset and the
    # turn-rate term (omega from the headings alone, as velocity_between's).
    nxt = pose[1:, 0:2]
    q = prob.kf.trans_bend
    if q is not None:
        c0 = pose[:-1, 0] + 1j * pose[:-1, 1]
        rot = np.exp(1j * pose[:-1, 2])
        om = wrap_angle(pose[1:, 2] - pose[:-1, 2]) / prob.kf.dt
        body = ((nxt[:, 0] + 1j * nxt[:, 1] - c0) / rot - (q[:, 2] + 1j * q[:, 3])
                - (q[:, 5] + 1j * q[:, 6]) * (om - q[:, 7]))
        plain = c0 + rot * body / (q[:, 0] + 1j * q[:, 1])
        nxt = np.column_stack([plain.real, plain.imag])
    v, om = velocity_between(pose[:-1, 0], pose[:-1, 1], pose[:-1, 2], nxt[:, 0], nxt[:, 1], pose[1:, 2],
                             prob.kf.dt)
    W[:-1, 0] = np.where(ok, v, W[:-1, 0])
    W[:-1, 1] = np.where(ok, om, W[:-1, 1])
    return pose, W


#: The largest turn [rad] in one keyframe interval whose start velocity is
#: read off its two poses (initial_guess).
MAX_GUESS_TURN = 2.5


#: Length of the pieces of dead reckoning aligned one by one to the fixes [s].
GUESS_CHUNK = 15.0
#: GNC: the robust threshold starts at 2^GNC_STEPS times its target and halves each iteration.
GNC_STEPS = 5


def robust_initial_guess(prob: Problem, meas) -> tuple[np.ndarray, np.ndarray]:
    """Keyframe estimate of the batch's own, needing no filter to survive.

    Dead reckoning with the nominal parameters from the initial pose (the
    consensus start, initial.consensus_pose), cut into GUESS_CHUNK pieces,
    each moved by the rigid map most of its fixes agree with (RANSAC, then
    weighted least squares; initial.rigid_ransac), so that the guess stays
    near the truth however the nominal scale factors drift. Velocities are the
    wheels' (nominal), slip and bias zero, scale factors at the prior. A piece
    with too few fixes keeps the previous piece's map (an outage), and a log
    without fixes is plain dead reckoning.
    """
    from odomgraph.factors.motion import integrate
    from odomgraph.estimators.initial import range_fixes, rigid_fit, rigid_ransac
    kf, r = prob.kf, prob.robot
    v = kf.enc_m.mean(1)
    w = (kf.enc_m[:, 1] - kf.enc_m[:, 0]) / r.track_width
    dr = integrate(v, w, kf.dt, start=tuple(prob.prior_mean[0:3]))
    W = np.zeros((kf.n, 8))
    W[:-1, 0], W[:-1, 1] = v, w
    W[-1] = W[-2]
    W[:, S.W_SCALE] = prob.prior_mean[S.SCALE]
    W[:, 2] = prob.prior_mean[S.BIAS]
    fixes = None
    if meas.gps is not None:
        fixes = (*meas.gps, np.asarray(r.gps_lever_arm, float))
    elif meas.ranges is not None:
        rf = range_fixes(meas, r, limit=None)
        if rf is not None:
            fixes = (rf[0], rf[1], rf[2], np.asarray(r.range_lever_arm, float))
    pose = dr.copy()
    if fixes is None:
        pose[:, 2] = wrap_angle(pose[:, 2])
        return pose, W
    ft, fp, fs, lever = fixes
    th_f = np.interp(ft, kf.t, dr[:, 2])
    d = np.stack([np.interp(ft, kf.t, dr[:, 0]) + np.cos(th_f) * lever[0] - np.sin(th_f) * lever[1],
                  np.interp(ft, kf.t, dr[:, 1]) + np.sin(th_f) * lever[0] + np.cos(th_f) * lever[1]], -1)
    edges = np.arange(kf.t[0], kf.t[-1] + GUESS_CHUNK, GUESS_CHUNK)
    phi, c = 0.0, np.zeros(2)
    for a, b in zip(edges[:-1], edges[1:]):
        sel = (ft >= a) & (ft < b)
        if sel.sum() >= 6:
            travel = float(np.sum(np.abs(v[(kf.t[:-1] >= a) & (kf.t[:-1] < b)]) * GUESS_CHUNK / max(1, sel.sum())))
            thr = 3.4 * fs[sel] + 0.1 * max(travel, 1.0)
            ph, cx, cy, inl, best = rigid_ransac(d[sel], fp[sel], thr)
            keep = inl[best] if best >= 0 else np.zeros(int(sel.sum()), bool)
            if keep.sum() >= 5 and np.ptp(d[sel][keep], 0).max() > 3.0 * float(np.median(fs[sel])):
                phi, c = rigid_fit(d[sel][keep], fp[sel][keep], 1.0 / fs[sel][keep] ** 2)
        k = (kf.t >= a) & (kf.t < b + (1e-9 if b >= edges[-1] else 0.0))
        cp, sp = np.cos(phi), np.sin(phi)
        pose[k, 0] = cp * dr[k, 0] - sp * dr[k, 1] + c[0]
        pose[k, 1] = sp * dr[k, 0] + cp * dr[k, 1] + c[1]
        pose[k, 2] = dr[k, 2] + phi
    pose[:, 2] = wrap_angle(pose[:, 2])
    return pose, W


#: Growing-window start: each solve covers this much history [s], advancing by GROW_STEP.
GROW_WINDOW = 30.0
GROW_STEP = 10.0
#: Prior 1-sigma on the first keyframe of each later window, block order (a
#: soft hand-over: the full solve afterwards does the exact job).
_GROW_SIGMA = np.array([0.05, 0.05, 0.02, 0.1, 0.1, 0.01, 0.1, 0.1, 0.01, 0.01, 0.01])


def growing_window_guess(prob: Problem, meas) -> tuple[np.ndarray, np.ndarray]:
    """Keyframe estimate by solving a window that grows through the log.

    Starts from robust_initial_guess; then solves the first GROW_STEP
    seconds, extends by GROW_STEP at a time, filling the new keyframes by
    dead reckoning from the last solved one with its scale factors and slip,
    and solves the last GROW_WINDOW seconds again (Gauss-Newton with GNC,
    solve_window) with a soft prior where each window starts. Every solve
    starts near its answer, so no part of the log can drag the rest into a
    wrong minimum (ESTIMATION-NOTES.md: started from dead reckoning with wrong
    scale factors, a whole-log solve converged to scale factors x5).
    """
    from odomgraph.factors.encoder import body_velocity
    pose, W = robust_initial_guess(prob, meas)
    kf, r = prob.kf, prob.robot
    L = np.diag(1.0 / _GROW_SIGMA)
    done = 0
    while done < kf.n - 1:
        k1 = int(min(kf.n - 1, max(done + 2, np.searchsorted(kf.t, kf.t[done] + GROW_STEP))))
        if done > 0:
            # New keyframes: dead reckoning from the last solved one, with its parameters.
            w = W[done]
            v, om = body_velocity(kf.enc_m[done:k1, 0], kf.enc_m[done:k1, 1], w[3], w[4], w[5], w[6], w[7],
                                  r.track_width)
            from odomgraph.factors.motion import integrate
            pose[done:k1 + 1] = integrate(v, om, kf.dt[done:k1], start=tuple(pose[done]))
            pose[done:k1 + 1, 2] = wrap_angle(pose[done:k1 + 1, 2])
            W[done + 1:k1 + 1] = w
            W[done:k1, 0], W[done:k1, 1] = v, om
        k0 = int(np.searchsorted(kf.t, kf.t[k1] - GROW_WINDOW))
        k0 = min(k0, done)
        prior = None if k0 == 0 else (pose[k0].copy(), W[k0].copy(), L)
        pose, W, _ = solve_window(prob, pose, W, k0, k1, prior, max_iterations=15)
        done = k1
    return pose, W


def factor_arrays(prob: Problem, lin: Linearization, part: slice = slice(None)):
    """Stack each interval's rows: A1 on block k, A2 on block k+1, b; for
    the intervals ``part`` (all by default)."""
    ru = lin.A_u.shape[1]
    n1 = len(range(lin.A_u.shape[0])[part])
    rows = ru + 3 + 8
    A1 = np.zeros((n1, rows, NB))
    A2 = np.zeros((n1, rows, NB))
    b = np.empty((n1, rows))
    A1[:, :ru] = lin.A_u[part]
    A1[:, ru:ru + 3] = lin.A_m0[part]
    A2[:, ru:ru + 3, 0:3] = lin.A_m1[part]
    A1[:, ru + 3:, 3:] = lin.A_w0[part]
    A2[:, ru + 3:, 3:] = lin.A_w1[part]
    b[:, :ru] = lin.b_u[part]
    b[:, ru:ru + 3] = lin.b_m[part]
    b[:, ru + 3:] = lin.b_w[part]
    return A1, A2, b


#: Intervals stacked at a time when the graph is built: the stacked rows
#: are a copy of what GTSAM copies again, so whole-log arrays doubled the
#: graph's memory (80 MB on a one-hour log) for nothing.
GRAPH_CHUNK = 2048


def gaussian_graph(prob: Problem, lin: Linearization) -> gtsam.GaussianFactorGraph:
    """The linearised problem as a GTSAM graph: one JacobianFactor per interval on (k, k+1)."""
    g = gtsam.GaussianFactorGraph()
    g.add(gtsam.JacobianFactor(0, lin.A_p, lin.b_p, gtsam.noiseModel.Unit.Create(NB)))
    unit = gtsam.noiseModel.Unit.Create(lin.A_u.shape[1] + 3 + 8)
    for k0 in range(0, prob.kf.n - 1, GRAPH_CHUNK):
        A1, A2, b = factor_arrays(prob, lin, slice(k0, min(k0 + GRAPH_CHUNK, prob.kf.n - 1)))
        for j in range(A1.shape[0]):
            g.add(gtsam.JacobianFactor(k0 + j, A1[j], k0 + j + 1, A2[j], b[j], unit))
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


def solve(prob: Problem, pose: np.ndarray, W: np.ndarray, options: SmootherOptions, progress=None,
          range_bias: np.ndarray | None = None, graduate: bool = True):
    """Gauss-Newton with a backtracking line search.

    Returns (pose, W, iterations, cost, range_bias, converged); range_bias
    is None unless the problem estimates it (``range_bias``: its start,
    zeros by default); converged is False when the iteration cap stopped it.
    ``graduate=False``: no graduated non-convexity, for a start already at
    the answer of a neighbouring problem (priorcheck).

    With a robust loss the threshold is graduated (GNC): it starts at
    2^GNC_STEPS times its target, so that every residual sits in the loss's
    nearly quadratic part and a start far from the answer cannot mistake good
    fixes for outliers, and halves each iteration to its target.

    Not Levenberg-Marquardt with Marquardt damping: the scale factors are
    per-keyframe copies tied by very tight random-walk factors, so diag(A^T A)
    is ~1e10 on their columns and Marquardt damping freezes exactly the
    direction that calibration has to move (measured: LM stopped 1 sigma short
    in a flat valley). Started near the answer (from the EKF), full
    Gauss-Newton steps with step halving converge in a few iterations.
    """
    n, nb = prob.kf.n, prob.n_bias
    order = time_ordering(n, 1 if nb else 0)
    rb = (np.zeros(nb) if range_bias is None else np.array(range_bias, float)) if nb else None
    gnc = prob.robust is not None and graduate
    prob.gnc_scale = 2.0**GNC_STEPS if gnc else 1.0
    lin = linearize(prob, pose, W, range_bias=rb)
    it = 0
    converged = False
    for it in range(1, options.max_iterations + 1):
        if progress is not None:
            progress(it, options.max_iterations)
        if gnc and prob.gnc_scale > 1.0 and it > 1:
            # Graduated non-convexity: tighten the loss, then linearise again at the same point.
            prob.gnc_scale = max(1.0, 0.5 * prob.gnc_scale)
            lin = linearize(prob, pose, W, range_bias=rb)
        cost = lin.cost
        graph = gaussian_graph(prob, lin)
        # Only its cost is needed from here on (a rejected step relinearises
        # under GNC, or stops): freeing it before the elimination takes one
        # linearisation (~45 MB on a one-hour log) off the peak.
        lin = lin_n = None    # (after an accepted step both names hold it)
        vv = graph.optimize(order, gtsam.EliminateQR)
        del graph
        d = np.stack([vv.at(k) for k in range(n)])
        db = vv.at(n) if nb else None
        if not (np.all(np.isfinite(d)) and (db is None or np.all(np.isfinite(db)))):
            raise EstimatorDivergedError(f"batch smoother diverged at iteration {it}: non-finite step")
        alpha = 1.0
        while True:
            pose_n, W_n = retract(pose, W, alpha * d)
            rb_n = rb + alpha * db if nb else None
            lin_n = linearize(prob, pose_n, W_n, range_bias=rb_n)
            if lin_n.cost <= cost or alpha < 1e-3:
                break
            alpha *= 0.5
        if lin_n.cost > cost:
            if prob.gnc_scale <= 1.0:
                converged = True
                break  # no descent left along the Gauss-Newton direction: converged
            continue
        drop = cost - lin_n.cost
        decrease = drop / max(cost, 1e-300)
        pose, W, rb, lin, cost = pose_n, W_n, rb_n, lin_n, lin_n.cost
        if (decrease < options.rel_tol or drop < options.abs_tol) and prob.gnc_scale <= 1.0:
            converged = True
            break
    prob.gnc_scale = 1.0
    return pose, W, it, cost, rb, converged


def block_local(pose0: np.ndarray, W0: np.ndarray, pose: np.ndarray, W: np.ndarray) -> np.ndarray:
    """(11,) tangent from (pose0, W0) to (pose, W), block order: the pose part in
    pose0's body frame (Pose2 local coordinates), the rest as differences."""
    d = np.empty(NB)
    d[0:3] = gtsam.Pose2(*pose0).localCoordinates(gtsam.Pose2(*pose))
    d[3:] = W - W0
    return d


def solve_window(prob: Problem, pose: np.ndarray, W: np.ndarray, k0: int, k1: int, prior=None,
                 max_iterations: int = 30, rel_tol: float = 1e-9):
    """Gauss-Newton with a line search over keyframes k0..k1 only (the intervals
    between them), as ``solve`` does for the whole log. The incremental
    smoothers use it to recover: their factors, linearised once at a
    prediction, can leave the estimate in a basin that many iterations with
    the robust losses re-weighted each time get out of.

    ``prior`` = (pose0 (3,), W0 (8,), L (11, 11)): a Gaussian on keyframe k0
    with whitener L in block order, e.g. an ISAM2 marginal; None with k0 = 0
    uses the problem's own prior. Returns (pose, W) with keyframes k0..k1
    updated, and the iterations used.
    """
    n_w = k1 - k0 + 1
    order = time_ordering(n_w)
    pose, W = pose.copy(), W.copy()
    gnc = prob.robust is not None
    prob.gnc_scale = 2.0**GNC_STEPS if gnc else 1.0       # graduated non-convexity, as in solve

    def lin_at(pose, W):
        lin = linearize(prob, pose, W, k0, k1)
        extra = 0.0
        Ap = bp = None
        if prior is not None:
            p0, w0, L = prior
            r = L @ block_local(p0, w0, pose[k0], W[k0])
            Ap, bp = L, -r
            extra = 0.5 * float(r @ r) - (0.5 * float(lin.b_p @ lin.b_p) if k0 == 0 else 0.0)
        elif k0 == 0:
            Ap, bp = lin.A_p, lin.b_p
        return lin, Ap, bp, lin.cost + extra

    lin, Ap, bp, cost = lin_at(pose, W)
    it = 0
    for it in range(1, max_iterations + 1):
        if gnc and prob.gnc_scale > 1.0 and it > 1:
            prob.gnc_scale = max(1.0, 0.5 * prob.gnc_scale)
            lin, Ap, bp, cost = lin_at(pose, W)
        A1, A2, b = factor_arrays(prob, lin)
        g = gtsam.GaussianFactorGraph()
        unit = gtsam.noiseModel.Unit.Create(A1.shape[1])
        for j in range(n_w - 1):
            g.add(gtsam.JacobianFactor(j, A1[j], j + 1, A2[j], b[j], unit))
        if Ap is not None:
            g.add(gtsam.JacobianFactor(0, Ap, bp, gtsam.noiseModel.Unit.Create(len(bp))))
        vv = g.optimize(order, gtsam.EliminateQR)
        d = np.stack([vv.at(j) for j in range(n_w)])
        if not np.all(np.isfinite(d)):
            raise EstimatorDivergedError("window re-solve: non-finite step")
        alpha = 1.0
        while True:
            p_n, W_n = pose.copy(), W.copy()
            p_n[k0:k1 + 1], W_n[k0:k1 + 1] = retract(pose[k0:k1 + 1], W[k0:k1 + 1], alpha * d)
            lin_n, Ap_n, bp_n, cost_n = lin_at(p_n, W_n)
            if cost_n <= cost or alpha < 1e-3:
                break
            alpha *= 0.5
        if cost_n > cost:
            if prob.gnc_scale <= 1.0:
                break
            continue
        decrease = (cost - cost_n) / max(cost, 1e-300)
        drop = cost - cost_n
        pose, W, lin, Ap, bp, cost = p_n, W_n, lin_n, Ap_n, bp_n, cost_n
        if (decrease < rel_tol or drop < 0.01) and prob.gnc_scale <= 1.0:
            break
    prob.gnc_scale = 1.0
    return pose, W, it


def marginal_blocks(prob: Problem, pose: np.ndarray, W: np.ndarray, range_bias: np.ndarray | None = None):
    """(N, 11, 11) marginal covariance of each keyframe block (pose part in the body frame).

    With range biases (a global variable g eliminated last) the recursion
    carries the cross-covariance with g: for the conditional
    x_k = R^-1 (d - S [x_{k+1}; g]),
        Sigma_k  = R^-1 R^-T + A Sigma_yy A^T,   Sigma_kg = -A Sigma_yg,   A = R^-1 S,
    with y the conditional's parents. Then returns (blocks, Sigma_gg).
    """
    lin = linearize(prob, pose, W, range_bias=range_bias, laplace=True)
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
    """States at interval midpoints: the pose flown from X_k along W_k's arc
    as far as the wheels got by then, turned as far as the gyro turned
    (Keyframes.mid_tau_vw, motion.arc_at), bent to the path's shape
    (Keyframes.mid_bend).

    Row k describes interval k, so its velocity, slip and bias are the averages
    they are estimated as; sigma is propagated through the same arc.
    """
    kf = prob.kf
    k = np.arange(kf.n - 1)[rows]
    t = kf.t[k] + 0.5 * kf.dt[k]
    tau = kf.mid_tau_vw[k]
    p, Jf = arc_at(pose[k, 0], pose[k, 1], pose[k, 2], W[k, 0], W[k, 1], tau[:, 0], tau[:, 1],
                   None if kf.mid_bend is None else kf.mid_bend[k])
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
        J[:, :, S.VEL_S] = Jf[:, :, S.VEL_S]          # the step's columns are the state's first five
        pose_cov = J @ Sig[k] @ np.swapaxes(J, 1, 2)
        sigma[:, 0:3] = np.sqrt(np.maximum(np.diagonal(pose_cov, 0, 1, 2), 0))
        sigma[:, 3:] = np.sqrt(np.maximum(np.diagonal(Sig[k], 0, 1, 2)[:, 3:], 0))
    return Estimate(method=method, t=t, mean=mean, sigma=sigma, pose_cov=pose_cov)


#: The sigma [m] of a fix held out as a jump: no weight in any solve.
HELD_SIGMA = 1e6


def run_batch(log: Log, schedule: Schedule = Schedule(), options: SmootherOptions = SmootherOptions(),
              progress=None, initial: Estimate | None = None) -> Estimate:
    """Smooth the whole log, from its own robust start (robust_initial_guess),
    or from ``initial``, an estimate of the same log (the Monte-Carlo study
    passes the EKF's, which it has anyway).

    The rows are the sparse slip prior's, unchecked: where the check ran
    (GraphOptions.slip_check), its outcome waits in ``Estimate.slip_check``
    until priorcheck.applied gives it (pipeline.estimate does, last; so does
    the Monte-Carlo study). A caller of run_batch alone applies it itself."""
    wall0 = time.perf_counter()
    prob = build_problem(log, schedule, options)
    if initial is None:
        # The EKF is one candidate start: robust itself (a consensus start, a
        # gate that re-acquires), and cheap. If it fails, the batch does not.
        from odomgraph.errors import OdomgraphError
        from odomgraph.estimators.ekf import run_ekf
        try:
            from odomgraph.estimators.ekf import EKFOptions
            initial = run_ekf(log, schedule if schedule.calibrate_until is not None else Schedule(20.0),
                              EKFOptions(pin=options.pin))
        except (OdomgraphError, ArithmeticError, np.linalg.LinAlgError):
            initial = None
    # The fixes the EKF held out as a jump (a multipath burst) get no weight
    # here either: a robust loss cannot refuse 200 fixes that agree with each
    # other (a probe's 3.6 m burst: 1.2 m RMS at a few cm sigma, status ok).
    held, held_out = {}, {}
    ht = initial.held_out.get("gps") if initial is not None else None
    if ht is not None and ht.size and prob.kf.gps_t is not None:
        on = np.isin(prob.kf.gps_t, ht)
        # Bursts only (two or more in a row): a single spike is the robust loss's, as any outlier.
        nxt, prv = np.concatenate([on[1:], [False]]), np.concatenate([[False], on[:-1]])
        on &= nxt | prv
        prob.kf.gps_sigma[on] = HELD_SIGMA
        if on.any():
            held, held_out = {"gps": int(on.sum())}, {"gps": prob.kf.gps_t[on].copy()}
    if initial is not None and initial.recoveries:
        # The filter went through a rough patch: do not start there. A
        # departure (Estimate.departures) is not one: the filter followed a stall; counted as one,
        # the fixes after a 17 s silence sent batch to a growing-window start
        # that left 2 % of its rows after the silence inside 3 sigma.
        initial = None
    if initial is not None:
        pose, W = initial_guess(prob, initial)
        start = f"started from the {initial.method} estimate"
        initial = None          # its rows (the filter's rate: 20-30 MB an hour) are not needed again
    else:
        pose, W = growing_window_guess(prob, prob.meas)
        start = "started from a growing-window solve (the EKF failed or had to recover)"
    if options.wheel_speed_units:
        prob.speed_ref = W[0, S.W_SCALE].copy()   # the units of the random walks (graph.linearize)
    pose, W, iters, cost, rb, converged = solve(prob, pose, W, options, progress)
    if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(W))):
        raise EstimatorDivergedError("batch smoother diverged: non-finite estimate")
    Sig = marginal_blocks(prob, pose, W, rb)
    warnings = []
    chk = check_slip_prior(prob, pose, W, rb, options)
    if chk is not None:
        iters += chk.iterations
    if rb is not None:
        Sig, Sgg = Sig
    if not converged:
        warnings.append(f"batch: stopped at its iteration cap ({options.max_iterations} Gauss-Newton "
                        "iterations) before converging; the estimate may not be the optimum")
    notes = [f"batch: {prob.kf.n} keyframes at {options.keyframe_hz:g} Hz, {iters} Gauss-Newton iterations, "
             f"final cost {cost:.1f}; {start}", prob.init.note]
    est = smoother_estimate(prob, schedule, pose, W, Sig, "batch", wall0, notes, warnings, held=held,
                            range_bias=_range_bias(log, rb, Sgg if rb is not None else None), held_out=held_out,
                            cost=float(cost))
    if chk is not None and chk.verdict is None:
        est.warnings.append(f"batch: {chk.note}")
    elif chk is not None:
        # The rows the check gives, built as these were; the pipeline applies them (Estimate.slip_check).
        if chk.verdict.prior_free:
            a_prob, a_pose, a_W, a_rb, a_Sig = chk.prob, chk.pose, chk.W, chk.rb, chk.Sig
        else:
            a_prob, a_pose, a_W, a_rb, a_Sig = prob, pose, W, rb, chk.widened
        a_Sig, a_Sgg = a_Sig if a_rb is not None else (a_Sig, None)
        alt = smoother_estimate(a_prob, schedule, a_pose, a_W, a_Sig, "batch", wall0, [], [], held=held,
                                range_bias=_range_bias(log, a_rb, a_Sgg), held_out=held_out)
        if alt.t.shape == est.t.shape:
            est.slip_check = SlipPriorRows(chk.verdict.p95, chk.verdict.prior_free, {
                k: getattr(alt, k) for k in ("mean", "sigma", "pose_cov", "calibration_sigma", "calibration_cov",
                                             "range_bias")}, f"batch: {chk.note}")
    return est


def _range_bias(log: Log, rb: np.ndarray | None, Sgg: np.ndarray | None) -> dict | None:
    """{beacon id: {value, sigma}} of the range biases rb (B,) with covariance Sgg (B, B); None without."""
    if rb is None:
        return None
    return {b.id: {"value": float(v), "sigma": float(np.sqrt(Sgg[i, i]))} for i, (b, v) in enumerate(zip(log.robot.beacons, rb))}


@dataclass(frozen=True)
class SlipPriorCheck:
    """check_slip_prior's outcome: the prior-free problem and its solution
    (pose (N, 3), W (N, 8), rb, Sig: marginal_blocks' return), its cost,
    convergence and iterations; ``widened``: the joint solution's keyframe
    covariance widened to hold the prior-free mean (marginal_blocks' form);
    ``verdict`` (priorcheck.Verdict; None: the prior-free solve diverged);
    ``note``: one line for the run's notes."""
    prob: Problem
    pose: np.ndarray
    W: np.ndarray
    rb: np.ndarray | None
    Sig: object
    cost: float
    converged: bool
    iterations: int
    widened: object
    verdict: Verdict | None
    note: str


def check_slip_prior(prob: Problem, pose: np.ndarray, W: np.ndarray, rb: np.ndarray | None,
                     options: GraphOptions) -> SlipPriorCheck | None:
    """Solve again without the sparse slip prior after the window, from the
    joint solution (pose (N, 3), W (N, 8), rb) of ``prob``, and compare the
    two (estimators.priorcheck). None: not checked (option off, no window,
    no prior, or no slip after the window above priorcheck.SLIP_SEEN)."""
    if not (options.slip_check and prob.slip_robust is not None and prob.window_mask.any()
            and slip_after_window(prob.zero_slip, W) > SLIP_SEEN):
        return None
    free = dataclasses.replace(prob, slip_robust=None)
    solver = options if isinstance(options, SmootherOptions) else SmootherOptions()
    pose_f, W_f, it, cost_f, rb_f, conv_f = solve(free, pose, W, solver, None, range_bias=rb, graduate=False)
    if not (np.all(np.isfinite(pose_f)) and np.all(np.isfinite(W_f))):
        return SlipPriorCheck(free, pose_f, W_f, rb_f, None, float(cost_f), False, it, None, None,
                              "the check of the sparse slip prior diverged; the prior's solution is given unchecked")
    Sig_f = marginal_blocks(free, pose_f, W_f, rb_f)
    blocks_f = Sig_f[0] if rb is not None else Sig_f
    d = tangent_difference(pose, W, pose_f, W_f)
    kf = prob.kf
    t_abs = np.sort(np.concatenate([kf.t[kf.gps_k[kf.gps_sigma < HELD_SIGMA]], kf.t[kf.rng_k]]))
    v = verdict(d, blocks_f, informed(kf.t, t_abs))
    wide = widened(blocks_f, d) if rb is None else (widened(blocks_f, d), Sig_f[1] + np.outer(rb - rb_f, rb - rb_f))
    return SlipPriorCheck(free, pose_f, W_f, rb_f, Sig_f, float(cost_f), conv_f, it, wide, v,
                          f"slip prior checked ({v.p95:.1f} sigma at the 95th percentile, threshold {CHECK_K:g})")


def smoother_estimate(prob: Problem, schedule: Schedule, pose: np.ndarray, W: np.ndarray, Sig: np.ndarray,
                      method: str, wall0: float, notes: list[str], warnings=(), held: dict | None = None,
                      causal_lag: float | None = None, heading_watch=None,
                      **extra) -> Estimate:
    """A smoother's Estimate, built in one go from its keyframe solution.

    pose (N, 3), W (N, 8): the keyframe states; Sig (N, 11, 11): their block
    marginals as solved (the pinned scale combinations at nominal). Rows sit
    at interval midpoints (``keyframe_rows``); the calibration block is the
    last keyframe's, honest (``honest_blocks``) and as solved ("given"). Every
    smoother reports the same counts (measurements used; rejected = the robust
    loss's plus despike's) and the same warnings (the start's, the window's),
    then its own ``warnings``. ``extra``: fields only some smoothers fill
    (online, update_times, recoveries, range_bias). wall0: perf_counter at the
    run's start. held: measurements per sensor held out as a jump before or
    during the solve (given no weight, so the robust loss cannot count them),
    rejected too. A start with no heading (estimators.heading): the rows the
    motion cannot have given a heading yet are widened: every row when it
    never does; with ``causal_lag`` [s] (a row has seen that far ahead:
    fixed-lag's window), the rows before the motion less that lag; an
    ``online`` (causal) estimate's, the rows before the motion.
    ``heading_watch``: the HeadingWatch a stream fed (online.py), with that
    motion's time and the circle at each row's time; else the log's."""
    from dataclasses import replace
    given = Sig[-1][np.ix_(S.SCALE, S.SCALE)].copy()
    Sig = honest_blocks(prob, Sig)
    rows = keyframe_rows(prob, pose, W, Sig, method)
    if prob.init is not None and prob.init.heading_unknown and prob.meas is not None:
        from odomgraph.estimators import heading
        watch = heading_watch               # a stream's, from all its data (online.py); else the log's
        if watch is None:
            watch = heading.watch_log(prob.meas, prob.robot)
        until = watch.t_known
        if causal_lag is None:      # a smoother of the whole log: the heading from motion at any time
            mine = np.inf if until == np.inf else -np.inf
        else:
            mine = until - causal_lag
        n = heading.widen_rows(rows.t, rows.sigma, rows.pose_cov, mine, watch, rows.mean)
        if extra.get("online") is not None:
            o = extra["online"]
            n += heading.widen_rows(o.t, o.sigma, o.pose_cov, until, watch, o.mean)
        if n:
            warnings = list(warnings) + [heading.warning(until, watch)]
    from odomgraph.estimators import gaps
    # A silence of every sensor: the rows there are drawn between the states
    # either side, which say nothing of the path's shape (a probe's 30 s
    # silence: batch 4.1 m and 1.7 rad off at sigma 1-3 cm mid-silence, status ok).
    pauses = gaps.pause_paths(prob.meas, prob.kf.t, pose, prob.robot.track_width) if prob.meas is not None else []
    if pauses:
        n = gaps.widen_pauses(rows.t, rows.sigma, rows.pose_cov, pauses)
        if extra.get("online") is not None:
            o = extra["online"]
            n += gaps.widen_pauses(o.t, o.sigma, o.pose_cov, pauses)
        if n:
            notes = list(notes) + gaps.pause_note(method, pauses)
    if causal_lag is None:
        # a whole-log smoother: where in a gap the wheels slipped is not known (estimators.gaps)
        found = gaps.widen_gaps(rows.t, rows.mean, rows.sigma, rows.pose_cov, gaps.fix_times(prob.kf),
                                gaps.min_distance(prob.kf.gps_sigma, prob.robot))
        warnings = list(warnings) + gaps.warning(found)
    rejected, downweighted = robust_counts(prob, pose, W)
    for k, v in list((prob.spikes or {}).items()) + list((held or {}).items()):   # added to the robust loss's
        rejected[k] = rejected.get(k, 0) + v
    return replace(rows, wall_time_s=time.perf_counter() - wall0, n_updates=n_measurements(prob),
                   t_switch=schedule.switch_time(prob.meas.t_start),
                   calibration_sigma=np.sqrt(np.diagonal(Sig[-1])[S.SCALE]),
                   calibration_cov=Sig[-1][np.ix_(S.SCALE, S.SCALE)].copy(), calibration_cov_given=given,
                   observability=prob.init.observability,
                   warnings=list(prob.init.warnings) + window_warnings(prob, schedule) + list(warnings),
                   notes=list(notes), rejected=rejected, downweighted=downweighted,
                   used=measurement_counts(prob), pauses=pauses, **extra)


def window_warnings(prob: Problem, schedule: Schedule) -> list[str]:
    """The warning about slip inside the calibration window (slipcheck), if any."""
    if schedule.calibrate_until is None:
        return []
    t0 = float(prob.kf.t[0]) if prob.init is None else None
    start = prob.init.t if prob.init is not None else t0
    # (the schedule's own stretches are the pipeline's, which says why: analysis.windowfit)
    return in_window(prob.init.slipping, start, start + schedule.calibrate_until)[1] if prob.init else []


def measurement_counts(prob: Problem) -> dict[str, int]:
    """Measurements per sensor the smoother used, as the log's rows (the
    wheel rows and gyro/velocity samples in the keyframes' intervals, though
    the graph takes them as interval means): the units of ``rejected``, whose
    wheel rejections are single-row spikes (measurements.despike). Counted
    in keyframe intervals they read "831 of 92 measurements rejected" and
    made a run degraded (a probe's bag with a noisy wheel driver). From the
    keyframes, so that a stream (estimators.growing) counts as its replay."""
    kf = prob.kf
    out = {"encoders": int(np.sum(kf.enc_n)), "gyro": int(np.sum(kf.gyro_n)), "velocity": int(np.sum(kf.vel_n)),
           "gps": int(kf.gps_k.size), "ranges": int(kf.rng_k.size)}
    return {k: v for k, v in out.items() if v}


def n_measurements(prob: Problem) -> int:
    kf = prob.kf
    return int(kf.n - 1 + np.sum(kf.gyro_n) + np.sum(kf.vel_n) + kf.gps_k.size + kf.rng_k.size)
