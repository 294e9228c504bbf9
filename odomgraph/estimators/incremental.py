"""Incremental smoothers: gtsam.ISAM2 and gtsam.IncrementalFixedLagSmoother.

Each keyframe k+1 triggers one true incremental update with what arrived in
(t_k, t_{k+1}]: the new variables X_{k+1} (Pose2), W_{k+1} (Vector6: v, omega,
gyro_bias, scale_left, scale_right, scale_track) and S_{k+1} (Vector2:
slip_left, slip_right), and the factors of interval k. No factor calls back
into Python, because GTSAM copies the whole Values for every Python callback
inside an update, which costs O(n) per factor (ESTIMATION-NOTES.md):

* the measurement and motion factors of interval k are linearised in numpy
  (graph.linearize, the EKF's models) at the current estimate and enter as
  gtsam.LinearContainerFactor, which GTSAM moves with the estimate to first
  order;
* random walks are gtsam.BetweenFactorVector, and the slip priors are
  gtsam.PriorFactorVector: zero-slip (the schedule) inside the calibration
  window, robust Cauchy (sparse slip) outside it, as in the batch solver.
  With a calibration window the walks are in wheel-speed units instead
  (GraphOptions.wheel_speed_units, graph.walk_rows: the v and slip steps
  are scale x speed, which no prior can cheapen by shrinking the speeds);
  those rows are bilinear and enter as linear factors like the
  measurements'. On 0.5 m GPS at 2 Hz the plain walks put ticks/m 6 % high
  at 6 sigma (benchmarks/weak_gps.py).

Slip has its own key so that its robust prior can be a built-in factor.
There are no global keys: the scale factors are per-keyframe copies tied by a
tight random walk (see graph.SCALE_FLOOR).
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import gtsam
import numpy as np
from gtsam.symbol_shorthand import S as S_KEY
from gtsam.symbol_shorthand import W as W_KEY
from gtsam.symbol_shorthand import X as X_KEY

from odomgraph.factors import gps as gps_model
from odomgraph.factors import pose2, ranging
from odomgraph.factors._math import wrap_angle
from odomgraph.factors.motion import arc_at, bend, propagate
from odomgraph import state as St
from odomgraph.checks import bounded
from odomgraph.errors import EstimatorDivergedError
from odomgraph.estimators.batch import (HELD_SIGMA, GraphOptions, build_problem, check_slip_prior, factor_arrays,
                                        marginal_blocks, retract, smoother_estimate, solve_window)
from odomgraph.estimators.graph import NB, Problem, linearize, slip_prior_rows, walk_rows
from odomgraph.estimators.heading import circle_variance
from odomgraph.estimators.measurements import PAUSE_S
from odomgraph.result import Estimate
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import Log

# Block columns (state.NAMES order) of each incremental variable.
X_COLS = [0, 1, 2]
W_COLS = [3, 4, 5, 8, 9, 10]
S_COLS = [6, 7]
W_IDX = [0, 1, 2, 5, 6, 7]   # rows of the 8-vector W (graph.py) in W_KEY
S_IDX = [3, 4]


@dataclass(frozen=True)
class IncrementalOptions(GraphOptions):
    """isam2's and fixed-lag's options: the keyframe graph's, and the
    incremental solvers'. Not batch's own graph options (BatchGraphOptions:
    range biases, a robust velocity walk, Huber slip steps); the registry
    refuses them here by name. Huber slip steps were measured here (joint
    step, thirteenth session): isam2's slips 20-50 % closer to the truth on
    the paper and yard logs, but 3 of 16 range-only 6 s stalls ended 0.6-1.5 m
    off (flagged; 0.24 m Gaussian): the smoothed v held at the wheels' speed
    into the stall while ranges were gated at their first linearisation."""
    lag: float = bounded(5.0, gt=0)
    """Fixed-lag window [s] (fixed-lag only)."""
    relinearize_threshold: float = bounded(0.05, gt=0)
    """ISAM2 relinearisation threshold of pose [m, rad] and velocity [m/s, rad/s]
    (built-in factors); bias, scale and slip thresholds are scaled from it."""
    segment: float = bounded(300.0, ge=0)
    """isam2: length [s] of one ISAM2 instance's history (0: one ISAM2 for the
    whole log). GTSAM 4.3's Bayes-tree destructor walks the whole tree on every
    update (benchmarks/README.md), so one long-lived ISAM2 costs O(n) per
    update. Each segment hands over to a fresh ISAM2 seeded with the joint
    marginal of the boundary keyframe; at the end, every earlier segment
    receives what the later data says about its boundary, which recovers the
    full smoothed estimate. The online estimate is unchanged by this."""
    relinearize_after: float = bounded(2.0, ge=0)
    """Age [s] at which an interval's linear factors are linearised again, at
    the by then nearly final estimate (they were first linearised at a
    prediction). 0 disables."""
    recovery_window: float = bounded(20.0, gt=0)
    """Seconds of history re-solved when the divergence watch trips (at most
    back to the current segment's start; fixed-lag: its window)."""
    max_recoveries: int = bounded(50, ge=0, integer=True)
    """Recoveries allowed in one run before the estimator gives up and says so."""
    max_mean_residual: float = bounded(50.0, gt=0, infinite=True)
    """Diverged when the running mean (about the last 50) of the whitened squared
    post-fit residuals of GPS fixes or ranges exceeds this many times their
    dimension: the estimate no longer explains the data (as EKFOptions.max_mean_nis)."""


def _params(options: IncrementalOptions, reuse_slots: bool = False) -> gtsam.ISAM2Params:
    p = gtsam.ISAM2Params()
    # Marginalisation and relinearisation remove factors; without reusing their
    # slots the factor list, and every update with it, grows with the log.
    p.findUnusedFactorSlots = reuse_slots
    # QR: the scale random walk is very tight, Cholesky loses it (measured:
    # IndeterminateSystemException at sigma 1e-5).
    p.setFactorization("QR")
    # Per-variable relinearisation thresholds, in each variable's own units.
    # Slip needs a small one: its robust (Cauchy) prior is re-weighted only when
    # slip is relinearised, and the weight changes a lot within a few c.
    th = gtsam.ISAM2ThresholdMap()
    r = options.relinearize_threshold
    th.insert(("x", np.full(3, r)))
    th.insert(("w", np.array([r, r, r / 10, 4e-3 * r, 4e-3 * r, 4e-3 * r])))
    c = options.slip_cauchy if options.slip_cauchy is not None else 0.05
    th.insert(("s", np.full(2, 0.2 * c)))
    p.setRelinearizeThreshold(th)
    p.relinearizeSkip = 1
    p.enablePartialRelinearizationCheck = True
    p.evaluateNonlinearError = False
    return p


class _Graph:
    """Builds the per-interval GTSAM factors of a Problem."""

    def __init__(self, prob: Problem, options: IncrementalOptions):
        self.prob, self.options = prob, options
        pn = prob.robot.process
        self.zero_model = gtsam.noiseModel.Isotropic.Sigma(2, pn.pseudo_slip_sigma)
        c = options.slip_cauchy
        self.robust_model = None if c is None else gtsam.noiseModel.Robust.Create(
            gtsam.noiseModel.mEstimator.Cauchy.Create(1.0), gtsam.noiseModel.Isotropic.Sigma(2, c))
        # The numpy linearisation must not add the slip priors: built-ins carry them.
        self.lin_prob = Problem(prob.kf, prob.robot, prob.prior_mean, prob.prior_cov,
                                np.zeros_like(prob.zero_slip), None, prob.q_slip, prob.robust, prob.robust_k)
        # A new interval is first linearised at a prediction. A robust loss
        # there would weigh good fixes by how far the *prediction* is off, and
        # a prediction gone wrong would then never be corrected; so the first
        # linearisation is Gaussian behind a gate (first_gate), and the robust
        # loss comes in when the interval is linearised again, near its answer.
        self.lin_first = Problem(prob.kf, prob.robot, prob.prior_mean, prob.prior_cov,
                                 np.zeros_like(prob.zero_slip), None, prob.q_slip, None, None)
        self.history: dict[tuple, list] = {}      # (sensor, beacon) -> recent prediction residuals
        self.jump: dict[tuple, tuple] = {}        # (sensor, beacon) -> (t, residual before, burst indices) of a jump held out
        self.rearm: set[tuple] = set()            # hold expired: no new jump until one is accepted
        self.last_t: dict[tuple, float] = {}      # (sensor, beacon) -> time of its previous measurement
        self.gated: dict[str, int] = {}
        # interval -> its slip in wheel-speed units where its slip prior was last linearised
        self.slip_at: dict[int, np.ndarray] = {}
        # The runner's start is unsettled (its _settle_start, both runners): no gate. Its
        # prediction is as unsure as the start's heading, and a gate that reads
        # only the fix's own sigma refused the fixes that settle it (a first fix
        # 35 s in: 15 gated, causal rows 6 m off at sigma 0.3 m).
        self.gate_open = False
        self.gated_rows: set[tuple[str, int]] = set()   # ("gps" | "ranges", index) gated at first linearisation
        self.held_rows: set[tuple[str, int]] = set()    # those of them held out as a jump: never used

    def values(self, k: int, pose, W) -> gtsam.Values:
        v = gtsam.Values()
        v.insert(X_KEY(k), gtsam.Pose2(*pose[k]))
        v.insert(W_KEY(k), W[k, W_IDX].copy())
        v.insert(S_KEY(k), W[k, S_IDX].copy())
        return v

    def prior_factors(self, pose, W) -> gtsam.NonlinearFactorGraph:
        lin = linearize(self.lin_prob, pose, W, 0, 1)
        g = gtsam.NonlinearFactorGraph()
        lp = self.values(0, pose, W)
        jf = gtsam.JacobianFactor(X_KEY(0), lin.A_p[:, X_COLS], W_KEY(0), lin.A_p[:, W_COLS], S_KEY(0),
                                  lin.A_p[:, S_COLS], lin.b_p, gtsam.noiseModel.Unit.Create(NB))
        g.add(gtsam.LinearContainerFactor(jf, lp))
        return g

    def first_gate(self, k: int, lin) -> None:
        """Reject, in interval k's first linearisation, the fixes and ranges far
        from the prediction *and* from what the same sensor said lately (the
        EKF's gate, ekf.gate_reference): whitened residual and its distance
        from the median of the last GATE_HISTORY both beyond FIRST_GATE. Zeroed
        rows are dropped from the factor; the count is kept in self.gated."""
        kf, prob = self.prob.kf, self.lin_first
        t = float(kf.t[k])
        g0, g1 = np.searchsorted(kf.gps_k, [k, k + 1])
        for i in range(g0, g1):
            rows = prob.gps_rows(prob.gps_slot[i]) + np.arange(2)
            # the fix's own time (a stamp within the interval without gps_t)
            tf = float(kf.gps_t[i]) if kf.gps_t is not None else t + kf.dt[k] * (i - g0 + 1) / (g1 - g0)
            self._gate(("gps", 0), lin, rows, i, tf, float(kf.gps_sigma[i]))
        q0, q1 = np.searchsorted(kf.rng_k, [k, k + 1])
        for i in range(q0, q1):
            rows = np.array([prob.range_rows(prob.rng_slot[i])])
            # ranges carry no time of their own here: the interval's end, so a
            # step within one interval is judged over the whole interval
            self._gate(("ranges", int(kf.rng_id[i])), lin, rows, i, t + kf.dt[k], self.prob.robot.range_sigma)

    def _gate(self, key, lin, rows, i: int, t: float, sigma: float) -> None:
        """Gate one fix or range (index i, at time t [s], 1-sigma ``sigma``).
        A residual that steps from the sensor's previous one faster than
        JUMP_SPEED over the real time between them (an outage in between
        lets the prediction drift far, and that is no jump) is a jump of the
        sensor (a multipath burst), held out as the EKF holds it
        (ekf.EKFOptions.jump_speed): no rescue from the recent residuals,
        until it comes back, or JUMP_HOLD has passed; then, as in the EKF,
        the jump is the sensor's new level."""
        from odomgraph.estimators.ekf import GATE_HISTORY, JUMP_HOLD, JUMP_SPEED, gate_reference, jumped
        u = -lin.b_u[0, rows]                          # whitened residual at the prediction
        hist = self.history.setdefault(key, [])
        held = key in self.jump
        ref = None if held else gate_reference(hist)
        limit = FIRST_GATE**2 * len(rows)
        far = float(u @ u) > limit
        reject = far and (ref is None or float((u - ref) @ (u - ref)) > limit)
        t_prev, self.last_t[key] = self.last_t.get(key), t
        if (reject and not held and key not in self.rearm and hist and t_prev is not None
                and jumped(u, hist[-1], np.eye(len(rows)), max(t - t_prev, 1e-3), JUMP_SPEED / sigma, limit)):
            self.jump[key], held = (t, hist[-1].copy(), []), True
        if held and reject and t - self.jump[key][0] > JUMP_HOLD:
            # Held out long enough: the jump is the sensor's new level (its
            # history becomes that level; no new jump until one is accepted).
            del self.jump[key]
            held = False
            hist[:] = [u.copy() for _ in hist]
            self.rearm.add(key)
            ref = gate_reference(hist)
            reject = far and (ref is None or float((u - ref) @ (u - ref)) > limit)
        if not reject:
            self.rearm.discard(key)
        hist.append(self.jump[key][1].copy() if held and reject else u.copy())
        if len(hist) > GATE_HISTORY:
            del hist[0]
        if reject:
            lin.A_u[0, rows] = 0.0
            lin.b_u[0, rows] = 0.0
            self.gated[key[0]] = self.gated.get(key[0], 0) + 1
            self.gated_rows.add((key[0], i))
            if held:
                # A burst (two or more held in a row) is held out of every
                # later solve too; a single spike is left to the robust loss
                # when its interval is linearised again, as any outlier.
                burst = self.jump[key][2]
                burst.append(i)
                if len(burst) >= 2:
                    for j in burst[-2:]:          # (_hold is idempotent: the earlier ones are held already)
                        self._hold(key[0], j)
        if held and not reject:
            del self.jump[key]                         # it came back: the jump is over

    def _hold(self, sensor: str, i: int) -> None:
        """Fix or range i is held out of later linearisations (_drop_held). A
        fix also gets no weight in any later solve (recovery, the final
        segment solve, the marginals); a range, which has no sigma of its
        own in the problem, still counts in those (a known gap)."""
        self.held_rows.add((sensor, i))
        if sensor == "gps":
            self.prob.kf.gps_sigma[i] = HELD_SIGMA     # no weight

    def _drop_held(self, k: int, lin) -> None:
        """Interval k linearised again (robust loss, near its answer) keeps out
        the fixes and ranges held out as a jump: a multipath burst of 200
        consistent fixes would otherwise come back in, and a robust loss
        cannot refuse so many that agree (a 3.6 m burst: 1.2 m RMS, status ok)."""
        if not self.held_rows:
            return
        kf, prob = self.prob.kf, self.lin_first
        g0, g1 = np.searchsorted(kf.gps_k, [k, k + 1])
        for i in range(g0, g1):
            if ("gps", i) in self.held_rows:
                rows = prob.gps_rows(prob.gps_slot[i]) + np.arange(2)
                lin.A_u[0, rows] = 0.0
                lin.b_u[0, rows] = 0.0
        q0, q1 = np.searchsorted(kf.rng_k, [k, k + 1])
        for i in range(q0, q1):
            if ("ranges", i) in self.held_rows:
                rows = np.array([prob.range_rows(prob.rng_slot[i])])
                lin.A_u[0, rows] = 0.0
                lin.b_u[0, rows] = 0.0

    def linear_factors(self, k: int, pose, W, first: bool = False) -> gtsam.NonlinearFactorGraph:
        """The measurement and motion factors of interval k, linearised at (pose, W):
        with ``first``, at a prediction (Gaussian, gated: first_gate); else with
        the robust loss."""
        if first:
            lin = linearize(self.lin_first, pose, W, k, k + 1)
            if not self.gate_open:
                self.first_gate(k, lin)
        else:
            lin = linearize(self.lin_prob, pose, W, k, k + 1)
            self._drop_held(k, lin)
        g = gtsam.NonlinearFactorGraph()
        lp = self.values(k, pose, W)
        lp.insert(X_KEY(k + 1), gtsam.Pose2(*pose[k + 1]))
        A, b = lin.A_u[0], lin.b_u[0]
        rows = np.any(A != 0, 1)            # drop the padding of sensors without data
        if rows.any():
            A, b = A[rows], b[rows]
            jf = gtsam.JacobianFactor(X_KEY(k), A[:, X_COLS], W_KEY(k), A[:, W_COLS], S_KEY(k), A[:, S_COLS], b,
                                      gtsam.noiseModel.Unit.Create(len(b)))
            g.add(gtsam.LinearContainerFactor(jf, lp))
        Am = lin.A_m0[0]
        jf = gtsam.JacobianFactor(X_KEY(k), Am[:, X_COLS], W_KEY(k), Am[:, W_COLS], X_KEY(k + 1), lin.A_m1[0],
                                  lin.b_m[0], gtsam.noiseModel.Unit.Create(3))
        g.add(gtsam.LinearContainerFactor(jf, lp))
        if self.prob.wheel_speed_units:
            g.push_back(self.walk_factors(k, pose, W, lp))
        if self.linear_slip_prior(k):
            g.add(self.slip_factor(k, W))      # last: refresh_slip_priors replaces it alone
        return g

    def linear_slip_prior(self, k: int) -> bool:
        """Interval k's sparse (Cauchy) slip prior is a linear factor
        (slip_factor), not a built-in: in wheel-speed units it is on scale x
        slip, which no built-in factor can say (graph.slip_prior_rows).

        The window's zero-slip pseudo-prior stays a built-in on the slip: it
        holds the slip at zero, where the two forms agree and there is nothing
        to pull the scale with. Frozen as a linear factor at a slip far from
        zero (a start or a restart far off), its tight rows would tie the
        scale factors to that slip for good (measured: a restarted stream's
        track scale 9 % off at 25 sigma)."""
        return self.prob.wheel_speed_units and not self.prob.zero_slip[k] and self.prob.slip_robust is not None

    def slip_factor(self, k: int, W) -> gtsam.LinearContainerFactor:
        """Interval k's slip prior, linearised at W[k] (graph.slip_prior_rows):
        a LinearContainerFactor on (S_k, W_k). Its Cauchy weight is that of
        the slip it was linearised at, so the runners re-linearise it while the
        slip moves (refresh_slip_priors), as ISAM2 re-linearises a built-in."""
        b, A, _ = slip_prior_rows(self.prob, W[k:k + 1], self.prob.zero_slip[k:k + 1])
        Aw = np.zeros((2, len(W_IDX)))
        Aw[:, [W_IDX.index(5), W_IDX.index(6)]] = A[0][:, 2:4]
        jf = gtsam.JacobianFactor(S_KEY(k), A[0][:, 0:2], W_KEY(k), Aw, b[0], gtsam.noiseModel.Unit.Create(2))
        lp = gtsam.Values()
        lp.insert(W_KEY(k), W[k, W_IDX].copy())
        lp.insert(S_KEY(k), W[k, S_IDX].copy())
        self.slip_at[k] = self.wheel_slip(W[k])
        return gtsam.LinearContainerFactor(jf, lp)

    def wheel_slip(self, w: np.ndarray) -> np.ndarray:
        """(2,) the slips of W row w (8,) in wheel-speed units [m/s]: (k_i / ref_i) s_i."""
        return w[St.W_WHEEL_SCALE] / np.asarray(self.prob.speed_ref, float)[0:2] * w[St.W_SLIP]

    def refresh_slip_priors(self, lo: int, hi: int, W, linear_index: dict, factors, remove: list) -> list[int]:
        """Re-linearise the slip priors of intervals lo <= j < hi whose slip, in
        wheel-speed units, moved by more than the relinearisation threshold
        ISAM2 gives slip (_params: 0.2 c) since they were linearised: the replacement goes into
        ``factors``, the old factor's index into ``remove``. Returns the
        intervals refreshed, in the order their factors were added. Older
        intervals are forgotten (their values are no longer read back)."""
        kf = self.prob.kf
        if hi > 0:      # at most REFRESH_BACK s back: with relinearize_after 0, lo stays at the segment start
            lo = max(lo, int(np.searchsorted(kf.t, kf.t[hi] - REFRESH_BACK)))
        for j in [j for j in self.slip_at if j < lo]:
            del self.slip_at[j]
        c = self.options.slip_cauchy if self.options.slip_cauchy is not None else 0.05
        done = []
        for j in range(lo, hi):
            if j not in self.slip_at or j not in linear_index:
                continue
            if np.max(np.abs(self.wheel_slip(W[j]) - self.slip_at[j])) > 0.2 * c:
                remove.append(linear_index[j][-1])
                factors.add(self.slip_factor(j, W))
                done.append(j)
        return done

    def walk_factors(self, k: int, pose, W, lp: gtsam.Values) -> gtsam.NonlinearFactorGraph:
        """The random walks of W and S from keyframe k to k+1 in wheel-speed
        units (graph.walk_rows), linearised at (pose, W) ``lp`` holding the
        keyframe k values. GTSAM's Python JacobianFactor takes three keys at
        most, and a slip row touches four (both slips, both scale copies):
        its small derivative on scale copy k+1 is put on copy k, which a
        scale walk at graph.SCALE_FLOOR holds equal to it."""
        A0, A1, bw, _ = walk_rows(self.prob, W, k, k + 1)      # Gaussian steps (Problem.slip_step_k inf)
        A0, A1, bw = A0[0], A1[0], bw[0]
        lp = gtsam.Values(lp)
        lp.insert(W_KEY(k + 1), W[k + 1, W_IDX].copy())
        lp.insert(S_KEY(k + 1), W[k + 1, S_IDX].copy())
        g = gtsam.NonlinearFactorGraph()
        w = np.array(W_IDX)
        jw = gtsam.JacobianFactor(W_KEY(k), A0[np.ix_(w, w)], W_KEY(k + 1), A1[np.ix_(w, w)], bw[w],
                                  gtsam.noiseModel.Unit.Create(len(w)))
        g.add(gtsam.LinearContainerFactor(jw, lp))
        sl = np.array(S_IDX)
        js = gtsam.JacobianFactor(S_KEY(k), A0[np.ix_(sl, sl)], S_KEY(k + 1), A1[np.ix_(sl, sl)], W_KEY(k),
                                  A0[np.ix_(sl, w)] + A1[np.ix_(sl, w)], bw[sl], gtsam.noiseModel.Unit.Create(len(sl)))
        g.add(gtsam.LinearContainerFactor(js, lp))
        return g

    def interval_factors(self, k: int, pose, W, first: bool = False) -> gtsam.NonlinearFactorGraph:
        """All factors of interval k: linear ones first (see linear_factors), then built-ins."""
        g = self.linear_factors(k, pose, W, first)
        g.push_back(self.builtin_factors(k))
        return g

    def builtin_factors(self, k: int) -> gtsam.NonlinearFactorGraph:
        """Random walks of W and S from keyframe k to k+1, and the slip prior of interval k."""
        prob = self.prob
        g = gtsam.NonlinearFactorGraph()
        if not prob.wheel_speed_units:         # else: linear factors (walk_factors)
            Q = prob.rw.cov(k)
            g.add(gtsam.BetweenFactorVector(W_KEY(k), W_KEY(k + 1), np.zeros(6),
                                            gtsam.noiseModel.Gaussian.Covariance(Q[np.ix_(W_IDX, W_IDX)])))
            g.add(gtsam.BetweenFactorVector(S_KEY(k), S_KEY(k + 1), np.zeros(2),
                                            gtsam.noiseModel.Gaussian.Covariance(Q[np.ix_(S_IDX, S_IDX)])))
        if prob.zero_slip[k]:
            g.add(gtsam.PriorFactorVector(S_KEY(k), np.zeros(2), self.zero_model))
        elif self.robust_model is not None and not self.linear_slip_prior(k):    # else: slip_factor
            g.add(gtsam.PriorFactorVector(S_KEY(k), np.zeros(2), self.robust_model))
        return g


class _Runner:
    """The shared loop; subclasses hold the GTSAM engine."""

    method = ""
    #: The start's heading is known well enough (ISAM2Runner / FixedLagRunner._settle_start).
    _settled = True
    #: Arrays with one row per keyframe (``_grow`` makes room as a stream adds keyframes).
    per_keyframe = ("pose", "W", "update_times")

    def __init__(self, log: Log, schedule: Schedule, options: IncrementalOptions, prob: Problem | None = None):
        self.log, self.schedule, self.options = log, schedule, options
        self.heading_watch = None    # set by a stream (online.py): its HeadingWatch (when the motion showed the heading)
        # _watch: per sensor [slow running mean, count, dof, the last few values]
        self._ema = {"GPS fixes": [2.0, 0, 2, []], "ranges": [1.0, 0, 1, []]}
        self._path = [0, 0.0, 0, 0.0]   # _overshot: keyframe, wheels' path to it [m], fixes seen, largest sigma [m]
        # causal: the online row of interval k is produced at t_{k+1} from data up to t_{k+1}.
        # A stream (estimators.growing) passes the problem it grows.
        self.prob = prob if prob is not None else build_problem(log, schedule, options, causal=True)
        if options.wheel_speed_units:
            self.prob.speed_ref = self.prob.prior_mean[St.SCALE_S].copy()   # the prior's scale factors
        self.graph = _Graph(self.prob, options)
        n = self.prob.kf.n
        self.pose = np.zeros((n, 3))
        self.W = np.zeros((n, 8))
        self.pose[0] = self.prob.prior_mean[0:3]
        self.W[0] = self.prob.prior_mean[3:]
        self.update_times = np.zeros(n)
        self.recoveries: list[str] = []
        self._recovered_at: list[float] = []
        self._recovered_spans: list[tuple[int, int]] = []    # (j0, k) of each re-solve
        # The last keyframe: no segment hands over there. A stream does not know it until it ends.
        self.last_k = n - 1

    def _grow(self, n: int) -> None:
        """Room for n keyframes in every per-keyframe array (doubling: a stream adds one at a time)."""
        for name in self.per_keyframe:
            a = getattr(self, name)
            if len(a) < n:
                b = np.zeros((max(n, 2 * len(a)),) + a.shape[1:], a.dtype)
                b[:len(a)] = a
                setattr(self, name, b)

    def trim(self) -> None:
        """Per-keyframe arrays cut to the problem's keyframes (before finish)."""
        n = self.prob.kf.n
        for name in self.per_keyframe:
            setattr(self, name, getattr(self, name)[:n])

    def _new_keyframe(self, k: int) -> None:
        """Predict keyframe k from k-1 (its initial value). Across an interval
        longer than a pause in the log (measurements.PAUSE_S) the velocity
        before it says nothing of the average over it: that comes from the
        interval's wheels (no slip, the current scale factors), else the
        first linearisation puts keyframe k an hour's drive away (a probe's
        pause of a day: a row 466 m off at a sigma of 2.8 m)."""
        kf = self.prob.kf
        if kf.dt[k - 1] > PAUSE_S:
            self._wheel_velocity(self.W[k - 1], k - 1)
        x, y, th = self.pose[k - 1]
        p, _ = bend(*propagate(x, y, th, self.W[k - 1, 0], self.W[k - 1, 1], kf.dt[k - 1]), x, y, th,
                    None if kf.trans_bend is None else kf.trans_bend[k - 1], self.W[k - 1, 1])
        self.pose[k] = [p[0], p[1], wrap_angle(p[2])]
        self.W[k] = self.W[k - 1]

    def _wheel_velocity(self, w: np.ndarray, j: int) -> None:
        """W row w (8,), in place: interval j's velocities from its wheels at
        w's scale factors, no slip."""
        kl, kr, kb = w[St.W_SCALE]
        ul, ur = self.prob.kf.enc_m[j, 0] / kl, self.prob.kf.enc_m[j, 1] / kr
        w[St.W_VEL] = 0.5 * (ul + ur), (ur - ul) / (kb * self.prob.robot.track_width)
        w[St.W_SLIP] = 0.0

    def _store(self, k: int, values) -> None:
        p = values.atPose2(X_KEY(k))
        self.pose[k] = [p.x(), p.y(), p.theta()]
        self.W[k, W_IDX] = values.atVector(W_KEY(k))
        self.W[k, S_IDX] = values.atVector(S_KEY(k))

    def run(self, progress=None) -> Estimate:
        wall0 = time.perf_counter()
        n = self.prob.kf.n
        self.begin()
        stride = max(1, n // 200)
        for k in range(1, n):
            self.advance(k)
            if progress is not None and k % stride == 0:
                progress(k, n)
        return self.finish(wall0)

    def begin(self) -> None:
        """The engine, with the prior on keyframe 0."""
        self.start(self.graph.prior_factors(self.pose, self.W), self.graph.values(0, self.pose, self.W))

    def advance(self, k: int) -> None:
        """Keyframe k: one incremental update with interval k-1's factors,
        then the divergence watch, and a recovery if it trips. The problem
        must hold interval k-1 (a stream appends it first)."""
        t0 = time.perf_counter()
        self._grow(k + 1)
        self._new_keyframe(k)
        pred = self.pose[k, :2].copy()
        self.graph.gate_open = not self._settled
        factors = self.graph.interval_factors(k - 1, self.pose, self.W, first=True)
        self.step(k, factors, self.graph.values(k, self.pose, self.W))
        self.update_times[k] = time.perf_counter() - t0
        if not (np.all(np.isfinite(self.pose[k])) and np.all(np.isfinite(self.W[k]))):
            raise EstimatorDivergedError(f"{self.method} diverged at t={self.prob.kf.t[k]:.3f} s: non-finite estimate")
        reason = self._overshot(k, pred) or self._watch(k - 1)
        if reason is not None:
            self._trip(k, reason)

    def _wheels_path(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(pose, W) with keyframes 0..k dead-reckoned from the prior's mean:
        each interval's velocities from its wheels at the prior's scale
        factors, no slip (as _new_keyframe across a pause)."""
        kf, prior = self.prob.kf, self.prob.prior_mean
        pose, W = self.pose.copy(), self.W.copy()
        pose[0], W[0] = prior[0:3], prior[3:]
        for j in range(k):
            w = prior[3:].copy()
            self._wheel_velocity(w, j)
            W[j] = w
            x, y, th = pose[j]
            p, _ = bend(*propagate(x, y, th, w[0], w[1], kf.dt[j]), x, y, th,
                        None if kf.trans_bend is None else kf.trans_bend[j], w[1])
            pose[j + 1] = [p[0], p[1], wrap_angle(p[2])]
            W[j + 1] = w
        return pose, W

    def _absolute_age(self, k: int) -> float:
        """Time [s] from the first keyframe whose graph holds a fix or range
        to keyframe k (-inf before it): the settles' clock, since nothing
        before it can pin the heading. A fix in interval g enters the graph
        with keyframe g + 1 (advance)."""
        kf = self.prob.kf
        first = [int(a[0]) + 1 for a in (kf.gps_k, kf.rng_k) if len(a) and int(a[0]) < k]
        return float(kf.t[k] - kf.t[min(first)]) if first else -np.inf

    def _solve_start(self, k: int) -> None:
        """Keyframes 0..k re-solved from the problem's prior (batch.solve_window)
        from two starts, the lower cost kept: the estimate as it stands, and
        the wheels' path from the prior's start (_wheels_path). A start held
        at a heading that was a guess leaves linear factors that can put the
        estimate in a basin Gauss-Newton does not leave (a probe: first fix
        35 s after the start, 2 Hz keyframes, fixed-lag 24 m off), where
        batch, started near the fixes, is right; the wheels' path from the
        start the first fixes fitted (initial.consensus_pose) ends on them."""
        best = None
        for p0, w0 in ((self.pose, self.W), self._wheels_path(k)):
            try:
                pose, W, _ = solve_window(self.prob, p0, w0, 0, k, None)
            except EstimatorDivergedError:
                continue                  # the other start may still do
            cost = float(linearize(self.prob, pose, W, 0, k).cost)
            if np.isfinite(cost) and (best is None or cost < best[0]):
                best = (cost, pose, W)
        if best is None:
            raise EstimatorDivergedError(f"{self.method}: re-solving the start gave a non-finite cost")
        self.pose[:k + 1], self.W[:k + 1] = best[1][:k + 1], best[2][:k + 1]

    def _overshot(self, k: int, pred: np.ndarray) -> str | None:
        """The update moved keyframe k from its prediction ``pred`` (x, y) further
        than any fix could: OVERSHOOT sigmas of the absolute sensor, plus 5
        sigmas of the start's position, plus twice the wheels' path so far (a
        heading flipped about the start). One
        Gauss-Newton step from linearisations at a heading the fixes had not
        pinned did that, and the next ones doubled it each keyframe (measured:
        10 m fixes at 0.2 Hz, a settle at 16 s, 18 km off at sigma 5 m by 18 s,
        between two fixes, which the watch on fixes cannot see)."""
        kf = self.prob.kf
        j, d, g, sig = self._path
        g1 = int(np.searchsorted(kf.gps_k, k))
        s_new = kf.gps_sigma[g:g1]
        s_new = s_new[s_new < HELD_SIGMA]               # (a fix held out has no weight: HELD_SIGMA)
        sig = max(sig, float(s_new.max()) if s_new.size else 0.0,
                  self.prob.robot.range_sigma if np.searchsorted(kf.rng_k, k) else 0.0)
        self._path = [k, d + float(np.sum(np.abs(kf.enc_m[j:k].mean(1)) * kf.dt[j:k])), g1, sig]
        if sig <= 0.0:
            return None                       # no absolute sensor yet: nothing can move it far
        jump = float(np.hypot(*(self.pose[k, :2] - pred)))
        # the start's own uncertainty too (a restart widens it to metres)
        start = 5.0 * float(np.sqrt(max(self.prob.prior_cov[0, 0], self.prob.prior_cov[1, 1])))
        limit = OVERSHOOT * sig + start + 2.0 * self._path[1]
        if jump > limit:
            return (f"one update moved the estimate {jump:.0f} m from its prediction, more than any fix could "
                    f"({limit:.0f} m): it overshot")
        return None

    def _estimate(self, Sig: np.ndarray, wall0: float, notes: list[str], **extra) -> Estimate:
        """The run's Estimate from its keyframe marginals Sig (N, 11, 11) (batch.smoother_estimate),
        with what every incremental run adds: update times, recoveries, the first-linearisation gate."""
        if self.graph.gated:
            notes = notes + ["gated at first linearisation (online): " + ", ".join(
                f"{k} {v}" for k, v in sorted(self.graph.gated.items()))]
        held: dict[str, int] = {}
        for sensor, _ in self.graph.held_rows:      # a fix held out has no weight: the robust loss cannot count it
            if sensor == "gps":
                held[sensor] = held.get(sensor, 0) + 1
        gi = sorted(i for s_, i in self.graph.held_rows if s_ == "gps")
        if gi and self.prob.kf.gps_t is not None:
            extra["held_out"] = {"gps": self.prob.kf.gps_t[gi]}
        # The sparse slip prior, checked as batch checks it (batch.check_slip_prior).
        # The rows were given as they came (fixed-lag's, isam2's online.csv), so a
        # prior the data contradict is flagged, and nothing is replaced or widened
        # (a yard log, 0.5 m fixes at 2 Hz and one-wheel slips: 48 % of isam2's
        # rows outside 3 sigma, status ok).
        chk = check_slip_prior(self.prob, self.pose, self.W, None, self.options)
        if chk is not None:
            notes = notes + [f"{self.method}: {chk.note}"]
            if chk.verdict is None:
                extra["warnings"] = list(extra.get("warnings", ())) + [f"{self.method}: {chk.note}"]
            else:
                if chk.verdict.prior_free:
                    line = (f"{self.method}: the slips after the calibration window contradict the sparse "
                            f"zero-slip prior its rows rest on (the solution without it is {chk.verdict.p95:.1f} "
                            "sigma away, 95th percentile near the fixes): not trustworthy; --method batch gives "
                            "the prior-free solution")
                    extra["flags"] = list(extra.get("flags", ())) + [line]
                    extra["warnings"] = list(extra.get("warnings", ())) + [line]
        left = self._left_off()
        if left:
            extra["flags"] = list(extra.get("flags", ())) + left
            extra["warnings"] = list(extra.get("warnings", ())) + left
        return smoother_estimate(self.prob, self.schedule, self.pose, self.W, Sig, self.method, wall0, notes,
                                 held=held, update_times=self.update_times[1:], recoveries=list(self.recoveries),
                                 heading_watch=self.heading_watch, **extra)

    def _left_off(self) -> list[str]:
        """A line for each re-solve whose stretch (its window and RECOVERY_AFTER
        seconds on) the final estimate still leaves off its fixes or ranges:
        RECOVERY_RUN of them in a row whose median post-fit distance exceeds
        RECOVERY_LEFT sigma. A re-solve that did not bring the estimate back
        is a wrong answer at a small sigma (a probe: fixed-lag's rows 0.55 m
        off at z 50 after a re-solve inside a stuck-wheels slip, 35 s after
        a 2 h pause, status ``recovered``). The fixes the first-linearisation
        gate or the robust loss refused count: refused because the estimate
        was off, they are the ones that show it; those held out as a jump
        (graph.held_rows, a burst no estimate follows) do not."""
        kf, out = self.prob.kf, []
        n = len(self.pose)
        held = set(self.graph.held_rows)
        for j0, k in self._recovered_spans:
            k = min(k, n - 1)
            # RECOVERY_AFTER s past the re-solve, and at least RECOVERY_RUN
            # fixes or ranges past it (1 Hz fixes: 3 s hold too few)
            g_k, q_k = np.searchsorted(kf.gps_k, k), np.searchsorted(kf.rng_k, k)
            ends = [kf.t[k] + RECOVERY_AFTER]
            for ks, i in ((kf.gps_k, g_k), (kf.rng_k, q_k)):
                if i + RECOVERY_RUN - 1 < len(ks):
                    ends.append(kf.t[min(ks[i + RECOVERY_RUN - 1] + 1, n - 1)])
            k1 = min(int(np.searchsorted(kf.t, max(ends))), n - 1)
            g0, g1 = np.searchsorted(kf.gps_k, [j0, k1])
            q0, q1 = np.searchsorted(kf.rng_k, [j0, k1])
            gi = np.array([i for i in range(g0, g1) if ("gps", i) not in held], int)
            qi = np.array([i for i in range(q0, q1) if ("ranges", i) not in held], int)
            worst = 0.0
            for _, u2 in self._post_fit(gi, qi):
                if len(u2) >= RECOVERY_RUN:
                    runs = np.lib.stride_tricks.sliding_window_view(u2, RECOVERY_RUN)
                    worst = max(worst, float(np.sqrt(np.median(runs, axis=1).max())))
            if worst > RECOVERY_LEFT:
                out.append(f"{self.method}: the re-solve at t={kf.t[k]:.1f} s did not bring the estimate back: "
                           f"between t={kf.t[j0]:.1f} and {kf.t[k1]:.1f} s its fixes or ranges sit up to "
                           f"{worst:.0f} sigma from it ({RECOVERY_RUN} in a row, median); rows there are not "
                           "trustworthy")
        return out

    def _watch(self, j: int) -> str | None:
        """Divergence watch on interval j's GPS fixes and ranges, at the estimate just
        updated with them. A linear factor keeps the linearisation it was given;
        if that was far off (nominal parameters wrong by 2x, say), the estimate
        can walk away from the data while every update looks normal. Post-fit
        residuals of a healthy smoother are at the noise level."""
        kf = self.prob.kf
        # Fixes and ranges the first-linearisation gate rejected say nothing about the estimate.
        gated = self.graph.gated_rows
        g0, g1 = np.searchsorted(kf.gps_k, [j, j + 1])
        gi = np.array([i for i in range(g0, g1) if ("gps", i) not in gated], int)
        q0, q1 = np.searchsorted(kf.rng_k, [j, j + 1])
        qi = np.array([i for i in range(q0, q1) if ("ranges", i) not in gated], int)
        checks = self._post_fit(gi, qi)
        limit = self.options.max_mean_residual
        for name, values in checks:
            e = self._ema[name]
            before = e[0]
            for u in values:
                # slow: about the last 50; one gross outlier is clipped so it cannot trip it
                e[0] = 0.98 * e[0] + 0.02 * min(u, 10.0 * limit * e[2])
                e[3].append(u)
                e[1] += 1
            del e[3][:-3]
            if e[1] > 100 and e[0] > limit * e[2]:
                return f"the running mean of whitened squared {name} residuals is {e[0]:.0f} (expected about {e[2]})"
            # fast: the median of the last three, so one outlier cannot trip it;
            # against the long-run level (at most 5x its expected value), so a
            # sensor whose sigma is set too small, and sits a few sigma off all
            # the time, is not taken for a divergence. It catches a stall's onset.
            fast = float(np.median(e[3]))
            if e[1] > 5 and fast > FAST_WATCH * max(e[2], min(before, 5.0 * e[2])):
                return (f"the last few {name} sit {np.sqrt(fast / e[2]):.1f} sigma from the estimate "
                        "(expected about 1)")
        return None

    def _post_fit(self, gi: np.ndarray, qi: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """Whitened squared residuals of GPS fixes gi and ranges qi (indices into
        the keyframes' arrays) at the current estimate of their keyframes."""
        kf, r = self.prob.kf, self.prob.robot
        checks = []
        for name, idx in (("GPS fixes", gi.astype(int)), ("ranges", qi.astype(int))):
            if not idx.size:
                continue
            ks = (kf.gps_k if name == "GPS fixes" else kf.rng_k)[idx]
            tvw = (kf.gps_tau_vw if name == "GPS fixes" else kf.rng_tau_vw)[idx]
            q = kf.gps_bend if name == "GPS fixes" else kf.rng_bend
            x, y, th = self.pose[ks].T
            p, _ = arc_at(x, y, th, self.W[ks, 0], self.W[ks, 1], tvw[:, 0], tvw[:, 1], None if q is None else q[idx])
            if name == "GPS fixes":
                h, _ = gps_model.antenna_position(p[:, 0], p[:, 1], p[:, 2], r.gps_lever_arm)
                checks.append((name, np.sum(((h - kf.gps_xy[idx]) / kf.gps_sigma[idx, None]) ** 2, 1)))
            else:
                h, _ = ranging.beacon_range(p[:, 0], p[:, 1], p[:, 2], kf.rng_beacon[idx], r.range_lever_arm)
                checks.append((name, ((h[:, 0] - kf.rng_z[idx]) / r.range_sigma) ** 2))
        return checks

    def _trip(self, k: int, reason: str) -> None:
        """The watch tripped at keyframe k: re-solve the recent past and carry on,
        or, when recovering keeps failing, say so."""
        t = float(self.prob.kf.t[k])
        recent = [r for r in self._recovered_at if t - r < 5.0]
        if len(self._recovered_at) >= self.options.max_recoveries or len(recent) >= 2:
            raise EstimatorDivergedError(
                f"{self.method} diverged at t={t:.3f} s: {reason}, and re-solving the last "
                f"{self.options.recovery_window * 3:g} s did not bring it back ({len(self._recovered_at)} "
                "recoveries). The batch smoother (--method batch) relinearises everything and may still work")
        window = self.options.recovery_window * (3.0 if recent else 1.0)
        kf = self.prob.kf
        j0 = self._recovery_start(k, int(np.searchsorted(kf.t, t - window)))
        if j0 >= k:       # a segment just began: nothing of its own to re-solve yet
            for e in self._ema.values():
                e[0], e[1], e[3] = float(e[2]), 0, []
            return
        self.recover(k, j0)
        for e in self._ema.values():
            e[0], e[1], e[3] = float(e[2]), 0, []
        self._recovered_at.append(t)
        self._recovered_spans.append((j0, k))
        self.recoveries.append(f"t={t:.2f} s: {reason}; re-solved the {t - kf.t[j0]:.0f} s since t={kf.t[j0]:.2f} s "
                               "and carried on from there")


def _joint_marginal(isam, k: int) -> np.ndarray:
    """(11, 11) joint marginal covariance of (X_k, W_k, S_k) in an ISAM2, tangent order X, W, S."""
    keys = [X_KEY(k), W_KEY(k), S_KEY(k)]
    jm = isam.jointMarginalCovariance(keys)
    off = np.cumsum((0, 3, 6, 2))
    C = np.zeros((11, 11))
    for a, ka in enumerate(keys):
        for c, kc in enumerate(keys):
            C[off[a]:off[a + 1], off[c]:off[c + 1]] = jm.at(ka, kc)
    return 0.5 * (C + C.T)


#: The first linearisation of a fix or range rejects it beyond this many sigma
#: from the prediction and from the sensor's recent residuals (_Graph.first_gate).
FIRST_GATE = 10.0
#: Look-back [s] of the slip priors' refresh (_Graph.refresh_slip_priors); fixed-lag: its window.
REFRESH_BACK = 5.0
#: An update that moves the newest keyframe from its prediction by more than this
#: many sigmas of the absolute sensor (plus twice the path so far) overshot (_overshot).
OVERSHOOT = 2.0 * FIRST_GATE

#: A re-solve's stretch runs this far past it [s] (_left_off)...
RECOVERY_AFTER = 3.0
#: ...and the final estimate still off its fixes there by more than this
#: many sigmas (the median of RECOVERY_RUN in a row; one outlier cannot
#: do it) is said (clean logs' post-fit distances sit near 1).
RECOVERY_LEFT = 4.0
RECOVERY_RUN = 5
#: The fast watch trips when the recent post-fit residuals average this many
#: times their expected whitened square (about 3.9 sigma per axis).
FAST_WATCH = 15.0
#: A prior heading sigma [rad] above which isam2 settles its start (ISAM2Runner._settle_start) ...
SETTLE_HEADING = 0.2
#: ... until a re-solve leaves the heading this sure [rad].
SETTLE_HEADING_DONE = 0.05
#: The settles' ages after the first fix or range [s]: at it, then doubling from twice this.
SETTLE_FIRST = 0.125
#: The first segment is kept open up to this many --segment lengths while its
#: heading is unsettled (memory grows by as much, once).
FIRST_SEGMENT_CAP = 4.0
#: fixed-lag holds an unsettled start in its window for at most this long [s]
#: after the first fix or range (FixedLagRunner._settle_start; memory grows by
#: as much, once, plus the stretch before the first fix).
HOLD_CAP = 300.0

#: ISAM2 boundary tangent order (X 3, W_KEY 6, S_KEY 2) -> keyframe block order (graph.py).
_PERM = np.array([0, 1, 2] + [3 + i for i in W_IDX] + [3 + i for i in S_IDX])


def _to_block(C: np.ndarray) -> np.ndarray:
    """A covariance in ISAM2 boundary order, reordered to block order."""
    out = np.empty_like(C)
    out[np.ix_(_PERM, _PERM)] = C
    return out


def _block_values(vals) -> tuple[np.ndarray, np.ndarray]:
    """(pose (3,) world, W (8,)) of the single keyframe in boundary ``vals``."""
    keys = {chr(gtsam.Symbol(k).chr()): k for k in vals.keys()}
    p = vals.atPose2(keys["x"])
    W = np.empty(8)
    W[W_IDX] = vals.atVector(keys["w"])
    W[S_IDX] = vals.atVector(keys["s"])
    return np.array([p.x(), p.y(), p.theta()]), W


def _block_local(vals, pose: np.ndarray, W: np.ndarray) -> np.ndarray:
    """(11,) tangent, block order, from the boundary ``vals`` to (pose, W)."""
    p0, W0 = _block_values(vals)
    d = np.empty(NB)
    d[0:3] = gtsam.Pose2(*p0).localCoordinates(gtsam.Pose2(*pose))
    d[3:] = W - W0
    return d


def _whitener(Lam: np.ndarray) -> np.ndarray:
    """(n, n) A with A^T A = Lam, a symmetric information matrix, by its
    eigenvectors. Directions it barely informs are floored, not dropped: a
    variable left with no information at all stops a fresh ISAM2
    (IndeterminateSystemException; measured: the slips after an hour's
    pause in the log, whose random walk left them 1e-12 of the scale
    factors' information). The floor is a prior far wider than the data."""
    d, V = np.linalg.eigh(0.5 * (Lam + Lam.T))
    return _floored(d, V)


def _floored(d: np.ndarray, V: np.ndarray) -> np.ndarray:
    d = np.maximum(d, 1e-9 * max(d.max(), 1e-300))
    return np.sqrt(d)[:, None] * V.T


def _cov_whitener(cov: np.ndarray) -> np.ndarray:
    """(n, n) L with L^T L = cov^-1 (a hand-over marginal's whitener), from
    the covariance's eigenvectors, its eigenvalues kept positive and its
    information floored as _whitener's. A Cholesky factor of the inverse
    failed on a hand-over across a 2 h pause of a wheel-speed log (not
    positive definite to rounding; tests/test_pauses.py); the inverse's
    eigenvalues, floored, would turn a covariance eigenvalue rounded below
    zero into the least informed direction (a second read)."""
    w, V = np.linalg.eigh(0.5 * (cov + cov.T))
    w = np.maximum(w, 1e-15 * max(w.max(), 1e-300))
    return _floored(1.0 / w, V)


class ISAM2Runner(_Runner):
    method = "isam2"
    per_keyframe = _Runner.per_keyframe + ("online", "online_sigma", "heading_held")

    def start(self, factors, values):
        self.isam = gtsam.ISAM2(_params(self.options, reuse_slots=True))
        self.isam.update(factors, values)
        self.linear_index: dict[int, list[int]] = {}
        self._relin_next = 0
        self.seg_start = 0
        self.segments: list[dict] = []
        self.online = np.zeros((self.prob.kf.n, St.N))
        self.online_sigma = np.zeros((self.prob.kf.n, St.N))
        # the causal heading sigma with pinned scale combinations held, as the
        # solver has it: what the start's settling reads (online_sigma gives the
        # pins' prior back, which no data shrink: a settle on it never ends)
        self.heading_held = np.zeros(self.prob.kf.n)
        self._settled = float(np.sqrt(self.prob.prior_cov[2, 2])) <= SETTLE_HEADING
        self._settle_next, self.settles, self._settled_at = 0.0, 0, -1
        self.settle_warnings: list[str] = []

    def step(self, k, factors, values):
        isam, kf = self.isam, self.prob.kf
        n_lin = sum(1 for i in range(factors.size()) if isinstance(factors.at(i), gtsam.LinearContainerFactor))
        remove = []
        # Re-linearise the interval that just became `relinearize_after` old.
        j = self._relin_next
        age = self.options.relinearize_after
        if age > 0 and j < k - 1 and kf.t[k] - kf.t[j + 1] >= age:
            extra = self.graph.linear_factors(j, self.pose, self.W)
            remove = self.linear_index.pop(j)
            for i in range(extra.size()):
                factors.add(extra.at(i))
            self._relin_next = j + 1
        else:
            extra = None
        n_before = factors.size()
        fresh = self.graph.refresh_slip_priors(self._relin_next, k - 1, self.W, self.linear_index, factors, remove)
        res = isam.update(factors, values, remove)
        idx = list(res.getNewFactorsIndices())
        self.linear_index[k - 1] = idx[:n_lin]
        if extra is not None:
            self.linear_index[j] = idx[n_before - extra.size():n_before]
        for pos, i in enumerate(fresh):
            self.linear_index[i][-1] = idx[n_before + pos]
        # Read back what the relinearisation window needs (and the newest keyframe).
        lo = max(0, min(self._relin_next, k - 1))
        for i in range(lo, k + 1):
            p = isam.calculateEstimatePose2(X_KEY(i))
            self.pose[i] = [p.x(), p.y(), p.theta()]
            self.W[i, W_IDX] = isam.calculateEstimateVector(W_KEY(i))
            self.W[i, S_IDX] = isam.calculateEstimateVector(S_KEY(i))
        self._online_row(k)
        self._settle_start(k)
        seg = self.options.segment
        if seg > 0 and kf.t[k] - kf.t[self.seg_start] >= seg and k < self.last_k:
            # The first segment stays open while its start heading is unsettled
            # (up to FIRST_SEGMENT_CAP segments): its hand-over marginal is what
            # every later segment starts from, and only an open segment can be
            # re-solved.
            if self._settled or self.segments or kf.t[k] - kf.t[0] >= FIRST_SEGMENT_CAP * seg:
                self._settle_start(k, closing=True)
                self._hand_over(k)

    def _settle_start(self, k: int, closing: bool = False) -> None:
        """A start whose heading the prior barely knows (sigma above
        SETTLE_HEADING: a consensus fit on few or weak fixes, or none): the
        linear factors of every interval so far were linearised at headings
        that were guesses, and a linear factor keeps its linearisation. Until
        the heading is known, the first segment is re-solved from its prior
        (Gauss-Newton over keyframes 0..k, as a recovery) at doubling ages
        (0, 0.25, 0.5, 1, 2, ... s after the first fix or range is in the
        graph: _absolute_age), and the ISAM2 restarted there: O(n) work in
        all. A divergence watch that trips meanwhile re-solves from the
        prior too.

        ``closing``: the first segment is about to be handed over at keyframe
        k (kept open until settled, at most FIRST_SEGMENT_CAP segment
        lengths); it is re-solved once more whatever its age, because its
        hand-over marginal is what every later segment starts from. If the
        heading is still not known to SETTLE_HEADING_DONE then, that is said
        (``settle_warnings``): no later settle can reach those linear factors."""
        if self.segments or self.seg_start != 0 or self._settled:
            return
        kf = self.prob.kf
        age = self._absolute_age(k)
        if age < self._settle_next and not closing:
            return
        if not (closing and self._settled_at == k):       # not re-solved at this keyframe already
            self._settle_next = 2.0 * max(age, SETTLE_FIRST)
            self.recover(k, 0)
            self._settled_at = k
            self.settles += 1
        if self.heading_held[k] < SETTLE_HEADING_DONE:
            self._settled = True
        elif closing:
            self._settled = True                          # nothing left to settle
            self.settle_warnings.append(
                f"isam2: the start's heading was still uncertain (sigma {np.degrees(self.online_sigma[k, 2]):.1f} "
                f"deg, settled at {np.degrees(SETTLE_HEADING_DONE):.1f}) when the first segment closed at "
                f"t={kf.t[k]:.1f} s ({FIRST_SEGMENT_CAP:g} x --segment): the causal estimates (online.csv) and the segments after it rest on "
                "linearisations at a heading the fixes had not pinned; the smoothed states were re-solved "
                "(a longer --segment, or an [initial] pose in robot.toml, avoids this)")

    def _online_row(self, k):
        """The causal estimate at t_k, of the state at the midpoint of the
        interval just completed (its averages are what the smoother knows)."""
        isam, kf = self.isam, self.prob.kf
        tau = kf.mid_tau_vw[k - 1]          # as far as the wheels got by the midpoint (batch.keyframe_rows)
        p, Jf = arc_at(*self.pose[k - 1], self.W[k - 1, 0], self.W[k - 1, 1], tau[0], tau[1],
                       None if kf.mid_bend is None else kf.mid_bend[k - 1])
        row = np.empty(St.N)
        row[0:2], row[2] = p[0:2], wrap_angle(p[2])
        row[3:] = self.W[k - 1]
        self.online[k] = row
        # pose at the midpoint: arc Jacobian on X (body) and (v, omega)
        Jx = pose2.to_body(Jf[:, 0:3], self.pose[k - 1, 2])
        Jv = Jf[:, St.VEL_S]
        obs = self.prob.init.observability
        if obs is not None and obs.unobservable:
            # Pinned scale combinations: the prior uncertainty given back
            # (batch.honest_blocks), which needs the joint block. The per-variable
            # marginals gave the pin's own 1e-4 as the track scale's sigma (a
            # probe's stream of a slow snowplow whose warm-up drove straight:
            # z -248 on every row, silent).
            from odomgraph.estimators.batch import honest_blocks
            C = honest_blocks(self.prob, _to_block(_joint_marginal(isam, k - 1))[None])[0]
            J = np.zeros((3, St.N))
            J[:, 0:3], J[:, St.VEL_S] = Jx, Jv
            self.online_sigma[k, 0:3] = np.sqrt(np.maximum(np.diag(J @ C @ J.T), 0))
            self.online_sigma[k, 3:] = np.sqrt(np.maximum(np.diag(C)[3:], 0))
            Px, Pw = isam.marginalCovariance(X_KEY(k - 1)), isam.marginalCovariance(W_KEY(k - 1))
            self.heading_held[k] = float(np.sqrt(max((Jx @ Px @ Jx.T + Jv @ Pw[0:2, 0:2] @ Jv.T)[2, 2], 0.0)))
        else:
            Px = isam.marginalCovariance(X_KEY(k - 1))
            Pw = isam.marginalCovariance(W_KEY(k - 1))
            Ps = isam.marginalCovariance(S_KEY(k - 1))
            # (cross terms ignored)
            Pp = Jx @ Px @ Jx.T + Jv @ Pw[0:2, 0:2] @ Jv.T
            self.online_sigma[k, 0:3] = np.sqrt(np.maximum(np.diag(Pp), 0))
            self.online_sigma[k, [3, 4, 5, 8, 9, 10]] = np.sqrt(np.maximum(np.diag(Pw), 0))
            self.online_sigma[k, [6, 7]] = np.sqrt(np.maximum(np.diag(Ps), 0))
            self.heading_held[k] = self.online_sigma[k, 2]
        if not self._settled and self.heading_held[k] > SETTLE_HEADING:
            # A heading this unsure is past what a linearisation carries: the
            # row lies on a circle about the fix-pinned antenna, of the lever
            # arm plus the interval's travel (the first row after a first fix
            # 35 s in: 0.4 m off at sigma 0.05 m, z 8).
            r = self.prob.robot
            lever = r.gps_lever_arm if len(kf.gps_k) else r.range_lever_arm
            radius = float(np.hypot(*lever)) + abs(float(self.W[k - 1, 0])) * float(kf.dt[k - 1])
            self.online_sigma[k, 0:2] = np.sqrt(self.online_sigma[k, 0:2] ** 2 + circle_variance(radius))

    # ------------------------------------------------------------ recovery
    def _recovery_start(self, k: int, j: int) -> int:
        if not self._settled and not self.segments and self.seg_start == 0:
            return 0              # an unsettled start is re-solved whole, from its prior (_settle_start)
        return max(self.seg_start, min(j, k - 1))

    def _seed(self):
        """(factors, values, solve_window prior) that start an ISAM2 at keyframe
        seg_start: the previous segment's hand-over marginal, or the problem's
        prior at keyframe 0."""
        if not self.segments:
            return (self.graph.prior_factors(self.pose, self.W), self.graph.values(0, self.pose, self.W), None)
        seg = self.segments[-1]
        cov_block = seg["cov"]
        cov = cov_block[np.ix_(_PERM, _PERM)]              # back to ISAM2 order X, W, S
        p0, w0 = _block_values(seg["vals"])
        L = _cov_whitener(cov_block)
        return (self._information_factor(seg["vals"], np.linalg.inv(cov), np.zeros(11)), gtsam.Values(seg["vals"]),
                (p0, w0, L))

    def recover(self, k: int, j0: int) -> None:
        """Re-solve keyframes j0..k (many Gauss-Newton iterations, robust
        weights renewed each time) and restart the ISAM2 at j0 with every
        factor since linearised at that solution. A closed segment ends at j0,
        so the backward pass and the memory bound are those of a hand-over."""
        kf = self.prob.kf
        vals = self.isam.calculateEstimate()
        for i in range(self.seg_start, k + 1):
            self._store(i, vals)
        if j0 > self.seg_start:
            bvals, cov = self._boundary(self.isam, j0)
            self.segments.append({"k0": self.seg_start, "b": j0, "vals": bvals, "cov": _to_block(cov),
                                  "pose": self.pose[self.seg_start:j0 + 1].copy(),
                                  "W": self.W[self.seg_start:j0 + 1].copy()})
            self.seg_start = j0
        seed_factors, seed_values, prior = self._seed()
        if prior is None and j0 == 0:
            self._solve_start(k)
        else:
            pose, W, _ = solve_window(self.prob, self.pose, self.W, j0, k, prior)
            self.pose[j0:k + 1], self.W[j0:k + 1] = pose[j0:k + 1], W[j0:k + 1]
        graph = gtsam.NonlinearFactorGraph()
        graph.push_back(seed_factors)
        values = gtsam.Values()
        for i in range(j0, k + 1):
            values.insert(self.graph.values(i, self.pose, self.W))
        owner = [None] * graph.size()
        for j in range(j0, k):
            lin = self.graph.linear_factors(j, self.pose, self.W)
            owner += [j] * lin.size()
            graph.push_back(lin)
            built = self.graph.builtin_factors(j)
            owner += [None] * built.size()
            graph.push_back(built)
        self.isam = gtsam.ISAM2(_params(self.options, reuse_slots=True))
        res = self.isam.update(graph, values)
        self.linear_index = {}
        for pos, fi in enumerate(res.getNewFactorsIndices()):
            if owner[pos] is not None:
                self.linear_index.setdefault(owner[pos], []).append(fi)
        # Linearised at the re-solved estimate already: only the youngest
        # intervals are relinearised again when they come of age.
        age = self.options.relinearize_after
        young = [j for j in range(j0, k) if kf.t[k] - kf.t[j + 1] < age]
        self._relin_next = young[0] if young else k - 1
        for i in range(j0, k + 1):
            p = self.isam.calculateEstimatePose2(X_KEY(i))
            self.pose[i] = [p.x(), p.y(), p.theta()]
            self.W[i, W_IDX] = self.isam.calculateEstimateVector(W_KEY(i))
            self.W[i, S_IDX] = self.isam.calculateEstimateVector(S_KEY(i))
        self._online_row(k)

    # -------------------------------------------------------- segmentation
    def _boundary(self, isam, b):
        """(values of X_b, W_b, S_b; their joint covariance (11, 11), tangent order X, W, S)."""
        vals = gtsam.Values()
        vals.insert(X_KEY(b), isam.calculateEstimatePose2(X_KEY(b)))
        vals.insert(W_KEY(b), isam.calculateEstimateVector(W_KEY(b)))
        vals.insert(S_KEY(b), isam.calculateEstimateVector(S_KEY(b)))
        return vals, _joint_marginal(isam, b)

    @staticmethod
    def _information_factor(vals, Lam, eta):
        """LinearContainerFactor of 0.5 d^T Lam d - eta^T d on (X_b, W_b, S_b) at ``vals``."""
        keys = list(vals.keys())
        keys = [k for c in ("x", "w", "s") for k in keys if chr(gtsam.Symbol(k).chr()) == c]
        A = _whitener(Lam)
        b = np.linalg.solve(A.T, eta)
        jf = gtsam.JacobianFactor(keys[0], A[:, 0:3], keys[1], A[:, 3:9], keys[2], A[:, 9:11], b,
                                  gtsam.noiseModel.Unit.Create(len(b)))
        g = gtsam.NonlinearFactorGraph()
        g.add(gtsam.LinearContainerFactor(jf, vals))
        return g

    def _hand_over(self, b):
        """Close the current ISAM2 at keyframe b and continue in a fresh one seeded at b.

        The closed segment keeps only its estimate (keyframes k0..b) and the
        hand-over marginal, not the ISAM2: the backward pass relinearises it
        from those (``_smooth_segment``), so memory stays O(keyframes)."""
        # Settle the pending relinearisations while their factors are still here.
        remove, extra = [], gtsam.NonlinearFactorGraph()
        for j in range(self._relin_next, b):
            fs = self.graph.linear_factors(j, self.pose, self.W)
            remove += self.linear_index.pop(j, [])
            for i in range(fs.size()):
                extra.add(fs.at(i))
        if extra.size():
            self.isam.update(extra, gtsam.Values(), remove)
        vals, cov = self._boundary(self.isam, b)
        # Full back-substitution of the closed segment (as in finish).
        values = self.isam.calculateBestEstimate()
        for k in range(self.seg_start, b + 1):
            self._store(k, values)
        self.segments.append({"k0": self.seg_start, "b": b, "vals": vals, "cov": _to_block(cov),
                              "pose": self.pose[self.seg_start:b + 1].copy(),
                              "W": self.W[self.seg_start:b + 1].copy()})
        new = gtsam.ISAM2(_params(self.options, reuse_slots=True))
        new.update(self._information_factor(vals, np.linalg.inv(cov), np.zeros(11)), gtsam.Values(vals))
        self.isam = new
        self.linear_index = {}
        self._relin_next = b
        self.seg_start = b

    def _smooth_segment(self, i: int, Lam_later: np.ndarray, eta_later: np.ndarray, max_iterations: int = 10,
                        final: bool = False):
        """Gauss-Newton over closed segment i, from the estimate it closed with,
        given the later data's information about its last keyframe b
        (0.5 d'Lam d - eta'd, block order, tangent at the hand-over values).
        After a plain hand-over one step is the whole answer (the later data
        move the boundary by well under a sigma); after a recovery the boundary
        can move far, so it iterates, with a line search, until the cost stops
        falling. Writes keyframes k0..b-1 (and b with ``final``: the open
        segment, which no later one owns); returns (block k0's new value as
        (pose, W), its marginal covariance (11, 11), block order).""" 
        seg = self.segments[i]
        k0, b = seg["k0"], seg["b"]
        pose, W = self.pose.copy(), self.W.copy()
        pose[k0:b + 1], W[k0:b + 1] = seg["pose"], seg["W"]
        pose[b], W[b] = _block_values(seg["vals"])        # linearise the boundary where it was handed over
        ev, V = np.linalg.eigh(0.5 * (Lam_later + Lam_later.T))
        keep = ev > 1e-9 * max(ev.max(), 1e-300)
        A_t = np.sqrt(ev[keep])[:, None] * V[:, keep].T
        b_t = (V[:, keep].T @ eta_later) / np.sqrt(ev[keep])
        if k0 > 0:
            prev = self.segments[i - 1]
            L0 = _cov_whitener(prev["cov"])

        def build(pose, W):
            lin = linearize(self.prob, pose, W, k0, b)
            A1, A2, rhs = factor_arrays(self.prob, lin)
            g = gtsam.GaussianFactorGraph()
            unit = gtsam.noiseModel.Unit.Create(A1.shape[1])
            for j in range(b - k0):
                g.add(gtsam.JacobianFactor(j, A1[j], j + 1, A2[j], rhs[j], unit))
            cost = lin.cost
            if k0 == 0:
                g.add(gtsam.JacobianFactor(0, lin.A_p, lin.b_p, gtsam.noiseModel.Unit.Create(NB)))
            else:
                # The hand-over prior this segment started from, at its current estimate of k0.
                r0 = L0 @ _block_local(prev["vals"], pose[k0], W[k0])
                g.add(gtsam.JacobianFactor(0, L0, -r0, gtsam.noiseModel.Unit.Create(NB)))
                cost += 0.5 * float(r0 @ r0)
            if keep.any():
                d_b = _block_local(seg["vals"], pose[b], W[b])
                r_t = A_t @ d_b - b_t
                g.add(gtsam.JacobianFactor(b - k0, A_t, -r_t, gtsam.noiseModel.Unit.Create(int(keep.sum()))))
                cost += 0.5 * float(r_t @ r_t)
            return g, cost

        order = gtsam.Ordering()
        for j in range(b - k0, -1, -1):       # reverse time: no fill, and k0 is eliminated last
            order.push_back(j)
        g, cost = build(pose, W)
        for _ in range(max_iterations):
            bn = g.eliminateSequential(order, gtsam.EliminateQR)
            sol = bn.optimize()
            step = np.stack([sol.at(j) for j in range(b - k0 + 1)])
            alpha = 1.0
            while True:
                p_n, W_n = pose.copy(), W.copy()
                p_n[k0:b + 1], W_n[k0:b + 1] = retract(pose[k0:b + 1], W[k0:b + 1], alpha * step)
                g_n, cost_n = build(p_n, W_n)
                if cost_n <= cost or alpha < 1e-3:
                    break
                alpha *= 0.5
            if cost_n > cost:
                break
            done = (cost - cost_n) <= 1e-9 * max(cost, 1e-300)
            pose, W, g, cost = p_n, W_n, g_n, cost_n
            if done or np.abs(alpha * step).max() < 1e-10:
                break
        bn = g.eliminateSequential(order, gtsam.EliminateQR)
        end = b + 1 if final else b      # the open segment's last keyframe has no later owner
        self.pose[k0:end], self.W[k0:end] = pose[k0:end], W[k0:end]
        Rinv = np.linalg.inv(bn.at(bn.size() - 1).R())
        return (pose[k0].copy(), W[k0].copy()), Rinv @ Rinv.T

    def finish(self, wall0: float) -> Estimate:
        # Full back-substitution: the wildfire threshold (1e-3) would leave older
        # keyframes with scale-factor copies that are stale by up to 1e-3.
        values = self.isam.calculateBestEstimate()
        n = self.prob.kf.n
        for k in range(self.seg_start, n):
            self._store(k, values)
        # The open segment's factors were linearised near where each keyframe
        # first stood (a prediction, then once more 2 s later). Where the start
        # was uncertain (heading unknown at first) that is not where the answer
        # is: Gauss-Newton over the segment, from the ISAM2's estimate, settles
        # it, and gives its first keyframe's marginal for the backward pass.
        last = gtsam.Values()
        last.insert(X_KEY(n - 1), gtsam.Pose2(*self.pose[n - 1]))
        last.insert(W_KEY(n - 1), self.W[n - 1, W_IDX].copy())
        last.insert(S_KEY(n - 1), self.W[n - 1, S_IDX].copy())
        self.segments.append({"k0": self.seg_start, "b": n - 1, "vals": last, "cov": None,
                              "pose": self.pose[self.seg_start:].copy(), "W": self.W[self.seg_start:].copy()})
        fin, cov_f = self._smooth_segment(len(self.segments) - 1, np.zeros((NB, NB)), np.zeros(NB), final=True)
        self.segments.pop()
        # Backward pass over the segments: the later data's information about
        # each boundary, Sigma_final^-1 - Sigma_handoff^-1 (at the handoff
        # point), is exactly what the earlier segment has not seen.
        for i in range(len(self.segments) - 1, -1, -1):
            seg = self.segments[i]
            delta = _block_local(seg["vals"], *fin)
            inf_f = np.linalg.inv(cov_f)
            fin, cov_f = self._smooth_segment(i, inf_f - np.linalg.inv(seg["cov"]), inf_f @ delta)
        Sig = marginal_blocks(self.prob, self.pose, self.W)
        kf = self.prob.kf
        online = Estimate("isam2-online", kf.t[:-1] + 0.5 * kf.dt, self.online[1:], self.online_sigma[1:])
        notes = [f"isam2: {kf.n} keyframes at {self.options.keyframe_hz:g} Hz, one ISAM2 update each, "
                 f"{len(self.segments) + 1} segment(s)"]
        if self.settles:
            notes.append(f"isam2: the start's heading was uncertain; the first segment was re-solved from its prior "
                         f"{self.settles} time(s) as the heading firmed up")
        # Flagged, not only said: a probe's 1-2 s segments on weak fixes ended 4-7 sigma off with status ok.
        flags = (["isam2: the first segment closed with the start heading still uncertain (warnings)"]
                 if self.settle_warnings else [])
        return self._estimate(Sig, wall0, notes, online=online, warnings=self.settle_warnings, flags=flags)


class FixedLagRunner(_Runner):
    method = "fixed-lag"
    per_keyframe = _Runner.per_keyframe + ("done", "Sig")

    def start(self, factors, values):
        self.smoother = gtsam.IncrementalFixedLagSmoother(self.options.lag, _params(self.options, reuse_slots=True))
        self.done = np.zeros(self.prob.kf.n, bool)
        self.filed_late: dict[int, float] = {}   # keyframe -> the later time [s] the smoother files it under
        self.Sig = np.zeros((self.prob.kf.n, NB, NB))
        self.linear_index: dict[int, list[int]] = {}
        self._relin_next = 0
        # A start whose heading the prior barely knows: held in the window until settled (_settle_start).
        self._settled = float(np.sqrt(self.prob.prior_cov[2, 2])) <= SETTLE_HEADING
        self._settle_next, self.settles = 0.0, 0
        self.settle_notes: list[str] = []
        self.settle_warnings: list[str] = []     # the hold ended at HOLD_CAP unsettled (a stream alerts them)
        self._update(factors, values, [0])

    def _update(self, factors, values, keyframes, remove=(), stamp: dict[int, float] | None = None):
        """``stamp``: keyframe -> the time [s] the smoother files it under, where not its own."""
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        for k in keyframes:
            t = float(self.prob.kf.t[k]) if stamp is None or k not in stamp else stamp[k]
            for key in (X_KEY(k), W_KEY(k), S_KEY(k)):
                stamps.insert((key, t))
        try:
            self.smoother.update(factors, values, stamps, list(remove))
        except ValueError as exc:
            # gtsam's Python wrapper raises its std::invalid_argument as
            # ValueError ("Asking to remove variables from the variable index
            # that are not unused"): a solver failure, said as one
            raise EstimatorDivergedError(f"fixed-lag: the solver failed ({exc})") from exc

    def _harvest(self, k, est):
        """Record keyframe k's fixed-lag estimate (from ``est``) and marginals before it leaves the window."""
        self._store(k, est)
        if self.prob.init.observability.unobservable:
            # Pinned scale combinations: their correction (batch.honest_blocks)
            # needs the pose-scale cross-covariance, which per-variable
            # marginals leave out.
            self.Sig[k] = _to_block(_joint_marginal(self.smoother.getISAM2(), k))
        else:
            Sig = np.zeros((NB, NB))
            Sig[np.ix_(X_COLS, X_COLS)] = self.smoother.marginalCovariance(X_KEY(k))
            Sig[np.ix_(W_COLS, W_COLS)] = self.smoother.marginalCovariance(W_KEY(k))
            Sig[np.ix_(S_COLS, S_COLS)] = self.smoother.marginalCovariance(S_KEY(k))
            self.Sig[k] = Sig
        self.done[k] = True
        self.filed_late.pop(k, None)
        # Its factors leave with it: no index of them may be removed later (their slots are reused),
        # and an unbounded stream keeps nothing per keyframe it no longer needs.
        self.linear_index.pop(k, None)
        self.graph.slip_at.pop(k, None)

    def _recovery_start(self, k: int, j: int) -> int:
        first = int(np.argmin(self.done[:k])) if not self.done[:k].all() else k
        if not self._settled:
            return first          # a held start is re-solved whole, from its prior (_settle_start)
        return max(first, min(j, k - 1))

    def recover(self, k: int, j0: int) -> None:
        """Re-solve keyframes j0..k, the part of the window the watch looks
        back on (as ISAM2Runner.recover), and restart the smoother at j0 with
        its marginal there (j0 = 0: the problem's prior, _solve_start) and
        every factor since linearised at the solution. Older keyframes still
        in the window are harvested first."""
        est = self.smoother.calculateEstimate()
        for j in np.flatnonzero(~self.done[:k + 1]):
            if j < j0:
                self._harvest(int(j), est)
            else:
                self._store(int(j), est)
        if j0 == 0:
            # Nothing has left the window: the problem's own prior (the window's
            # marginal at keyframe 0 would count every factor since twice).
            self._solve_start(k)
            graph = self.graph.prior_factors(self.pose, self.W)
        else:
            isam = self.smoother.getISAM2()
            cov = _joint_marginal(isam, j0)
            vals = gtsam.Values()
            vals.insert(X_KEY(j0), est.atPose2(X_KEY(j0)))
            vals.insert(W_KEY(j0), est.atVector(W_KEY(j0)))
            vals.insert(S_KEY(j0), est.atVector(S_KEY(j0)))
            p0, w0 = _block_values(vals)
            L = _cov_whitener(_to_block(cov))
            pose, W, _ = solve_window(self.prob, self.pose, self.W, j0, k, (p0, w0, L))
            self.pose[j0:k + 1], self.W[j0:k + 1] = pose[j0:k + 1], W[j0:k + 1]
            graph = ISAM2Runner._information_factor(vals, np.linalg.inv(cov), np.zeros(11))
        values = gtsam.Values()
        for i in range(j0, k + 1):
            values.insert(self.graph.values(i, self.pose, self.W))
        for j in range(j0, k):
            graph.push_back(self.graph.interval_factors(j, self.pose, self.W))
        self.smoother = gtsam.IncrementalFixedLagSmoother(self.options.lag, _params(self.options, reuse_slots=True))
        self._update(graph, values, range(j0, k + 1), stamp=self.filed_late)
        # The new smoother's factors were all linearised at the solution: none to redo.
        self.linear_index, self._relin_next = {}, k
        est = self.smoother.calculateEstimate()
        for i in range(j0, k + 1):
            self._store(i, est)

    def step(self, k, factors, values):
        kf = self.prob.kf
        # Keyframes that the coming update marginalises: take their estimate
        # now. Not keyframe k-1, whose interval's factors (its wheels, its W)
        # come with this update: after an interval longer than the lag (an
        # encoder dropout, a pause in the log) it would leave with W_{k-1}
        # never measured (a probe's hour-long pause: a row 2 m off at a
        # sigma of 2.7 km and 18708 rad). It is filed just inside the
        # window instead, and leaves at the next update.
        keep = {}
        edge = kf.t[k] - self.options.lag
        if kf.t[k - 1] < edge:
            keep[k - 1] = float(kf.t[k]) - self.options.lag + 1e-6 * self.options.lag
        if not self._settled:
            # The start is held: every keyframe about to leave is filed at t_k (_settle_start).
            for j in np.nonzero(~self.done[:k] & (kf.t[:k] < edge + 1e-6 * self.options.lag))[0]:
                if self.filed_late.get(int(j), -np.inf) < edge + 1e-6 * self.options.lag:
                    keep[int(j)] = float(kf.t[k])
        leaving = [j for j in np.nonzero(~self.done[:k - 1] & (kf.t[:k - 1] < edge))[0]
                   if int(j) not in keep and self.filed_late.get(int(j), -np.inf) < edge]
        if leaving:
            est = self.smoother.calculateEstimate()
            for j in leaving:
                self._harvest(int(j), est)
                self.filed_late.pop(int(j), None)
        n_lin = sum(1 for i in range(factors.size()) if isinstance(factors.at(i), gtsam.LinearContainerFactor))
        # Re-linearise the interval that just became `relinearize_after` old,
        # as ISAM2Runner.step does, while both its keyframes are still inside
        # the window (a factor on a marginalised key is gone). The wheel-speed
        # unit walks need it: at the prediction the speed step is zero, and
        # the linearised walk cannot see what shrinking the speeds costs.
        j, age, remove, extra = self._relin_next, self.options.relinearize_after, [], None
        while j < k - 1 and (self.done[j] or j not in self.linear_index):
            j += 1
        self._relin_next = j
        if (age > 0 and j < k - 1 and kf.t[k] - kf.t[j + 1] >= age
                and kf.t[j] >= kf.t[k] - self.options.lag + kf.dt[k - 1]):
            extra = self.graph.linear_factors(j, self.pose, self.W)
            remove = self.linear_index.pop(j)
            for i in range(extra.size()):
                factors.add(extra.at(i))
            self._relin_next = j + 1
        # Slip priors of intervals still in the window whose slip moved (not
        # one this update marginalises: a factor on a marginalised key is gone).
        n_before = factors.size()
        # The whole window, as ISAM2 re-weighs a built-in at any age: a slip that
        # later fixes reveal must not keep the weight of zero slip (the output is final).
        lo = int(np.searchsorted(kf.t, kf.t[k] - self.options.lag + kf.dt[k - 1] - 1e-12))
        while lo < k - 1 and self.done[lo]:
            lo += 1
        fresh = self.graph.refresh_slip_priors(lo, k - 1, self.W, self.linear_index, factors, remove)
        self._update(factors, values, [k, *keep], remove, keep)
        self.filed_late.update(keep)
        idx = list(self.smoother.getISAM2Result().getNewFactorsIndices())
        self.linear_index[k - 1] = idx[:n_lin]
        if extra is not None:
            self.linear_index[j] = idx[n_before - extra.size():n_before]
        for pos, i in enumerate(fresh):
            self.linear_index[i][-1] = idx[n_before + pos]
        est = self.smoother.calculateEstimate()
        # Read back the window: what the next re-linearisations (and slip prior refreshes) need.
        for i in range(min(self._relin_next, lo, k - 1), k + 1):
            if not self.done[i]:
                self._store(i, est)
        if not self._settled:
            self._settle_start(k)

    def _settle_start(self, k: int, closing: bool = False) -> None:
        """A start whose heading the prior barely knows (sigma above
        SETTLE_HEADING: a consensus fit on few or weak fixes, or a first fix
        long after the start), as ISAM2Runner._settle_start: a window that
        marginalises keyframes linearised at a heading that was a guess
        freezes that guess, and every row after it inherits it (a probe: the
        first fix 35 s after the start, rows 2.8 rad and 5 m off at sigma
        0.2 rad and 0.5 m, status ok). So until the heading is known, no
        keyframe leaves the window (step files it at t_k); the held window is
        re-solved from the prior (Gauss-Newton, as a recovery) at doubling
        ages (0, 0.25, 0.5, 1, ... s after the first fix or range is in the
        graph: _absolute_age) and the smoother restarted there (a divergence
        watch that trips meanwhile does the same), until the newest
        keyframe's heading sigma is below SETTLE_HEADING_DONE. The
        hold ends at HOLD_CAP seconds whatever the heading (memory), and that
        is said. ``closing``: the log ends at keyframe k, re-solved once more
        whatever its age."""
        kf = self.prob.kf
        age = self._absolute_age(k)
        # (before the first fix or range nothing is capped: a prior this unsure
        # comes only from a fit to fixes that are yet to come)
        capped = age >= HOLD_CAP
        if age < self._settle_next and not (capped or closing):
            return
        self._settle_next = 2.0 * max(age, SETTLE_FIRST)
        self.recover(k, int(np.argmin(self.done[:k + 1])) if not self.done[:k + 1].all() else k)
        self.settles += 1
        sig = float(np.sqrt(max(self.smoother.marginalCovariance(X_KEY(k))[2, 2], 0.0)))
        if sig < SETTLE_HEADING_DONE:
            self._settled = True
            self._release_hold(k)
            self.settle_notes.append(
                f"fixed-lag: the start's heading was uncertain (prior sigma "
                f"{np.degrees(np.sqrt(self.prob.prior_cov[2, 2])):.0f} deg): the window held every keyframe until "
                f"t={kf.t[k]:.1f} s, when {self.settles} re-solve(s) from the start had pinned it "
                f"(sigma {np.degrees(sig):.1f} deg)")
        elif closing:
            self._settled = True
            self.settle_notes.append(
                f"fixed-lag: the start's heading was never pinned (sigma {np.degrees(sig):.1f} deg at the end): "
                f"the window held every keyframe to the end, and the rows are a re-solve of the whole log")
        elif capped:
            self._settled = True
            self._release_hold(k)
            self.settle_warnings.append(
                f"fixed-lag: the start's heading was still uncertain (sigma {np.degrees(sig):.1f} deg; it counts as "
                f"pinned below {np.degrees(SETTLE_HEADING_DONE):.1f} deg) when the window stopped holding at t={kf.t[k]:.1f} s "
                f"({HOLD_CAP:g} s after the first fix or range): the rows after it rest on linearisations at a heading the data had not pinned "
                "(an [initial] pose in robot.toml, or --method batch, avoids this)")

    def _release_hold(self, k: int) -> None:
        """The hold ended (pinned, or at HOLD_CAP): every held keyframe older
        than the lag leaves now, from the estimate the settle just re-solved,
        and the smoother restarts at k (recover). Left to leave by
        their filing times, they left in groups of every lag-th keyframe
        (filed together at each lag), and gtsam's marginalisation of such
        scattered keys failed ("Asking to remove variables from the variable
        index that are not unused": a probe's 2.5-4 m consumer GPS held the
        start 250-300 s, then fixed-lag stopped with a traceback). A hold
        shorter than the lag has nothing to release."""
        kf = self.prob.kf
        j0 = int(np.searchsorted(kf.t, kf.t[k] - self.options.lag))
        if j0 < 1 or j0 > k or self.done[:j0].all():
            return
        # Restarted at k itself, whose marginal already holds every factor so
        # far: a restart at j0 < k would push the factors j0..k on top of a
        # marginal that counts them. The keyframes of the last lag leave with
        # the rest, smoothed as far as the data up to k go.
        self.recover(k, k)
        self.filed_late = {}

    def end_hold(self) -> None:
        """The log ends: a start still held is re-solved once more, and its rows are that re-solve's."""
        if not self._settled:
            self._settle_start(self.prob.kf.n - 1, closing=True)

    def finish(self, wall0: float) -> Estimate:
        self.end_hold()
        est = self.smoother.calculateEstimate()
        for j in np.nonzero(~self.done)[0]:
            self._harvest(int(j), est)
        # Window marginals are per variable: the cross-covariance of X, W and S
        # of one keyframe is not available, so pose sigma at the row time
        # ignores it (it is second order for the pose).
        notes = [f"fixed-lag: {self.prob.kf.n} keyframes at {self.options.keyframe_hz:g} Hz, lag "
                 f"{self.options.lag:g} s"] + self.settle_notes
        flags = (["fixed-lag: the window stopped holding with the start heading still uncertain (warnings)"]
                 if self.settle_warnings else [])
        return self._estimate(self.Sig, wall0, notes, causal_lag=self.options.lag, warnings=self.settle_warnings,
                              flags=flags)


def run_isam2(log: Log, schedule: Schedule = Schedule(), options: IncrementalOptions = IncrementalOptions(),
              progress=None) -> Estimate:
    """One gtsam.ISAM2 update per keyframe; final smoothed states plus the online (causal) estimate."""
    return ISAM2Runner(log, schedule, options).run(progress)


def run_fixed_lag(log: Log, schedule: Schedule = Schedule(), options: IncrementalOptions = IncrementalOptions(),
                  progress=None) -> Estimate:
    """gtsam.IncrementalFixedLagSmoother with ``options.lag`` seconds."""
    return FixedLagRunner(log, schedule, options).run(progress)
