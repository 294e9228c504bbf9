"""The smoother's factor graph, linearised for all keyframes at once.

Variables per keyframe k (see keyframes.py): the pose X_k (Pose2, body-frame
tangent) and W_k (8 averages). Their 11-dim tangent block is ordered like
``state.NAMES``: [dX (body), dv, domega, dbias, dslip_l, dslip_r, dscale_l, dscale_r, dscale_track].

Factors, all built on the models in ``factors/`` (the EKF's models):

* motion (X_k, W_k, X_{k+1}): X_{k+1} against the arc flown with W_k's average
  velocity, its chord bent to the path dead-reckoned inside the interval
  (factors.motion.transition_residual, Keyframes.trans_bend);
* random walk (W_k, W_{k+1}): of v, omega (white acceleration), gyro bias,
  common-mode and differential slip (as in the EKF) and the scale factors (a
  floor of 1e-5/sqrt(s) keeps the chain free of global variables). With a
  calibration window the batch smoother takes the v and slip steps in
  wheel-speed units (Problem.wheel_speed_units);
* unary on (X_k, W_k): encoder (eq. 29), gyro (eq. 10), velocity sensor,
  GPS (eq. 8) and range (eq. 12) part-way along the arc (motion.arc_at, at the
  share of the interval's wheel travel done by their time, bent likewise:
  Keyframes.gps_bend, rng_bend), and the
  schedule's zero-slip prior (eq. 35);
* a prior on keyframe 0 from the initialisation.

``linearize`` returns whitened Jacobians (A) and right-hand sides (b = -r),
so that the Gauss-Newton step minimises ||A d - b||^2.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from odomgraph import state as S
from odomgraph.factors import encoder, gps as gps_model, gyro, pose2, ranging
from odomgraph.factors.motion import arc_at, transition_residual
from odomgraph.estimators.initial import InitialState
from odomgraph.estimators.measurements import PAUSE_PATH_SHARE, PAUSE_S, PAUSE_TURN_SHARE, Measurements
from odomgraph.estimators.keyframes import Keyframes
from odomgraph.io.robot import RobotConfig

NB = 11  # tangent dimension of a keyframe block
# W's columns inside a block [pose, W]: the state's indices (state.W_OFFSET)
V, OM, B, SL, SR, KL, KR, KB = S.V, S.OMEGA, S.BIAS, S.SLIP_L, S.SLIP_R, S.SCALE_L, S.SCALE_R, S.SCALE_B
WSL, WSC, WWS = S.W_SLIP, S.W_SCALE, S.W_WHEEL_SCALE
#: The rows of one interval's unary factor, in order: the wheels (2), the
#: gyro (1), the velocity sensor (2), the slip prior (2), then two per GPS
#: fix (Problem.g_max of them) and one per range (Problem.r_max).
ROW_ENC, ROW_GYRO, ROW_VEL, ROW_SLIP = slice(0, 2), 2, slice(3, 5), slice(5, 7)
ROW_FIXES = 7


def unary_rows(g_max: int, r_max: int) -> int:
    """How many rows an interval's unary factor has."""
    return ROW_FIXES + 2 * g_max + r_max
_ENC_COLS = [V, OM, SL, SR, KL, KR, KB]
SCALE_FLOOR = 1e-5  # scale-factor random walk floor [1/sqrt(s)]


@dataclass
class Problem:
    """Everything fixed while the estimate changes."""
    kf: Keyframes
    robot: RobotConfig
    prior_mean: np.ndarray
    """(11,) world-frame state of keyframe 0 (state.NAMES order)."""
    prior_cov: np.ndarray
    """(11, 11) its covariance (pose block in the world frame)."""
    zero_slip: np.ndarray
    """(N-1,) intervals forced to zero slip (eq. 35-36): the schedule's
    calibration window, and where the robot stood still (``still``)."""
    slip_robust: float | None = None
    """Cauchy scale [m/s] of a sparse zero-slip prior on the other intervals (None: none)."""
    q_slip: np.ndarray | None = None
    """(2, 2) slip intensity matrix (common-mode / differential), as in the EKF."""
    robust: str | None = None
    """Robust loss of GPS fixes and ranges: None, "huber" or "cauchy" (real data has outliers)."""
    robust_k: float | None = None
    """Its threshold in sigmas (default: 1.345 for Huber, 2.385 for Cauchy: 95 % efficiency)."""
    range_bias_sigma: float | None = None
    """Prior 1-sigma [m] of a constant range bias per beacon, estimated as one
    global variable (a vector, one entry per robot.beacons); None: no bias."""
    velocity_loss: str | None = None
    """Robust loss ("huber" or "cauchy") of the v and omega random-walk steps; None: Gaussian."""
    slip_step_k: float = math.inf
    """Huber threshold [sigma] of the slips' common-mode random-walk step
    (walk_rows, SLIP_STEP_K); inf: Gaussian, as the EKF's random walk."""
    speed_ref: np.ndarray | None = None
    """(3,) scale factors that define wheel-speed units for the random walks
    (see linearize; batch: the initial guess). None: plain walks."""
    gnc_scale: float = 1.0
    """Graduated non-convexity: the robust threshold is robust_k times this.
    Solvers start it large (every loss nearly quadratic, so a start far from
    the answer does not mistake good fixes for outliers) and lower it to 1."""
    init: "InitialState | None" = None
    meas: "Measurements | None" = None
    """The log's measurements the problem was built from (estimators.measurements)."""
    """The initialisation the prior came from (its observability and warnings)."""
    spikes: dict = None
    """Single-sample spikes the log's cleaning took out, per sensor (measurements.despike)."""
    window: np.ndarray | None = None
    """(N-1,) the schedule's calibration window alone, where zero_slip also
    holds standstills (estimators.standstill); None: zero_slip is the window."""

    @property
    def wheel_speed_units(self) -> bool:
        """Random walks in wheel-speed units: only with a speed_ref and a
        calibration window. The window pins slip to zero and so anchors the
        scale factors; without one a scale factor can shrink towards zero to
        escape the priors (a slip-only schedule on the real libRSF log, as
        first imported, took the track scale to 0). A standstill's zero slip
        is no anchor: with the wheels still it says nothing of a scale."""
        return self.speed_ref is not None and bool(self.window_mask.any())

    @property
    def window_mask(self) -> np.ndarray:
        """(N-1,) the schedule's calibration window (zero_slip less standstills)."""
        return self.zero_slip if self.window is None else self.window

    def loss_k(self) -> float:
        """The robust threshold in sigmas now in force (robust_k, scaled by gnc_scale)."""
        return (self.robust_k or ROBUST_K[self.robust]) * self.gnc_scale

    @property
    def n_bias(self) -> int:
        return len(self.robot.beacons) if self.range_bias_sigma is not None else 0

    def gps_rows(self, slot):
        """The first of the two unary rows of the GPS fixes in slots ``slot``."""
        return ROW_FIXES + 2 * slot

    def range_rows(self, slot):
        """The unary row of the ranges in slots ``slot`` (without range biases)."""
        return ROW_FIXES + 2 * self.g_max + slot

    def __post_init__(self):
        kf = self.kf
        # Fixed row layout of the unary factor of each interval. With range
        # biases, ranges leave it: their rows also touch the global bias.
        self.g_max = int(np.bincount(kf.gps_k, minlength=kf.n - 1).max()) if kf.gps_k.size else 0
        self.r_max = int(np.bincount(kf.rng_k, minlength=kf.n - 1).max()) if kf.rng_k.size else 0
        if self.range_bias_sigma is not None:
            self.r_max = 0
        self.rows_unary = unary_rows(self.g_max, self.r_max)
        self.gps_slot = _slots(kf.gps_k)
        self.rng_slot = _slots(kf.rng_k)
        dt = kf.dt
        # the last interval has no next one and counts its own dt twice
        self.rw = RandomWalkSteps.of(self.robot.process, self.q_slip, walk_span(dt, np.append(dt[1:], dt[-1])))
        self.motion_whiten = 1.0 / motion_sigma(kf, self.robot.process.yaw_accel**2, self.robot.track_width)


def walk_span(dt: np.ndarray, dt_next: np.ndarray) -> np.ndarray:
    """(K,) [s] what the W random walk from interval k to k+1 spans: the
    difference of two adjacent interval averages of a random walk of
    intensity q has variance q (dt_k + dt_{k+1}) / 3."""
    return (dt + dt_next) / 3.0


@dataclass(frozen=True)
class RandomWalkSteps:
    """The W random-walk step covariance of every interval: one unit
    covariance (the intensities of ProcessNoise and the slip's (2, 2) block
    per second, 8 x 8) times each interval's span [s] (walk_span). An
    interval costs one float, not two 8 x 8 matrices: a stream's problem
    grows for hours (estimators.growing)."""
    unit: np.ndarray
    """(8, 8) covariance per second of span."""
    unit_whiten: np.ndarray
    """(8, 8) inverse Cholesky factor of ``unit``."""
    span: np.ndarray
    """(N-1,) [s]."""

    @staticmethod
    def unit_cov(pn, q_slip: np.ndarray) -> np.ndarray:
        """(8, 8): ProcessNoise ``pn``'s intensities squared, q_slip (2, 2) [(m/s)^2/s] on the slips."""
        Q = np.zeros((8, 8))
        Q[0, 0], Q[1, 1], Q[2, 2] = pn.accel**2, pn.yaw_accel**2, pn.gyro_bias**2
        Q[WSL, WSL] = q_slip
        Q[5, 5] = Q[6, 6] = Q[7, 7] = max(pn.scale, SCALE_FLOOR) ** 2
        return Q

    @classmethod
    def of(cls, pn, q_slip: np.ndarray, span: np.ndarray) -> "RandomWalkSteps":
        Q = cls.unit_cov(pn, q_slip)
        return cls(Q, np.linalg.inv(np.linalg.cholesky(Q)), span)

    @property
    def slip_split(self) -> np.ndarray:
        """(2, 2) orthogonal R: R times unit_whiten's slip rows gives the row
        of the common-mode step c = (sL + sR) / 2 whitened alone (first) and
        the differential step d = sR - sL whitened alone (second). The slip
        block is p^2 11^T + q_d^2 / 4 [[1, -1], [-1, 1]]
        (measurements.slip_intensity), so c and d are independent with
        variances p^2 and q_d^2 per second, and the pair of rows costs what
        the joint whitened step costs."""
        Q = self.unit[WSL, WSL]
        p2, qd2 = 0.5 * (Q[0, 0] + Q[0, 1]), 2.0 * (Q[0, 0] - Q[0, 1])
        M = np.array([[0.5, 0.5], [-1.0, 1.0]]) / np.sqrt([[p2], [qd2]])
        return M @ np.linalg.inv(self.unit_whiten[WSL, WSL])

    def cov(self, k) -> np.ndarray:
        """(8, 8) covariance of interval k's step (or (K, 8, 8) for a slice)."""
        return np.multiply.outer(self.span[k], self.unit)

    def whiten(self, k) -> np.ndarray:
        """Its inverse Cholesky factor, (8, 8) or (K, 8, 8)."""
        return np.multiply.outer(1.0 / np.sqrt(self.span[k]), self.unit_whiten)


#: Default thresholds [sigma] of the measurement losses. Cauchy at 5 sigma is
#: the smoothers' default loss: 99 % efficient on Gaussian noise, and a fix
#: 20 sigma off keeps 6 % of its weight, 100 sigma off 0.25 %.
ROBUST_K = {"huber": 1.345, "cauchy": 5.0}
#: Thresholds of the robust velocity random walk (95 % efficiency).
VELOCITY_LOSS_K = {"huber": 1.345, "cauchy": 2.385}
#: Default Huber threshold [sigma] of the slips' common-mode random-walk step
#: (BatchGraphOptions.slip_step_k, walk_rows). A stall (the robot held while its
#: wheels spin) steps the common-mode slip by the wheels' speed within a
#: second; a Gaussian step cost spreads that step over seconds. Measured
#: (fourteenth session, batch, common-mode step at 2): five stall logs
#: (tests/test_stalls.py) 4-12 cm at z 3.6-5.7 (Gaussian 13-43 cm at z
#: 11-25); slip RMS 6-55 % lower on the paper and yard logs (seeds 4-5).
#: On the joint step (thirteenth session, branch wip/slip-huber): at 1.345 a
#: stall under a frozen receiver (tests/test_honesty.py) zig-zagged (rows
#: 0.34 m off at z 9), and the differential step at a Huber loss let a range
#: bias slide under its floor (libRSF beacon 107, tests), so it stays Gaussian.
SLIP_STEP_K = 2.0
#: Floor of robust_curvature (a sqrt weight): a Huber step beyond its
#: threshold, where the loss is linear, keeps this much for the covariance.
LAPLACE_FLOOR = 1e-3


def robust_curvature(u: np.ndarray, kind: str, k: float) -> np.ndarray:
    """sqrt of the loss's second derivative rho''(u) at a whitened residual
    u, floored at LAPLACE_FLOOR: the rows' weight for a covariance (the
    Laplace approximation at the optimum), where robust_weight's IRLS
    secant k/|u| would claim the data knew more than the loss says. Huber:
    1 inside k, 0 beyond; Cauchy: (1 - (u/k)^2) / (1 + (u/k)^2)^2, below 0
    beyond k."""
    u = np.abs(u)
    if kind == "huber":
        c = np.where(u <= k, 1.0, 0.0)
    elif kind == "cauchy":
        r = (u / k) ** 2
        c = (1.0 - r) / (1.0 + r) ** 2
    else:
        raise ValueError(f"unknown robust loss {kind!r}")
    return np.sqrt(np.maximum(c, LAPLACE_FLOOR**2))


def robust_weight(u: np.ndarray, kind: str, k: float):
    """IRLS for a whitened residual norm u: (sqrt(weight), loss rho(u)).

    Huber: rho = u^2/2 (u <= k), k (u - k/2) beyond; Cauchy: rho = k^2/2 log(1 + (u/k)^2).
    Rows scaled by sqrt(weight) have the gradient of rho at the current point.
    """
    u = np.abs(u)
    if kind == "huber":
        w = np.where(u <= k, 1.0, k / np.maximum(u, 1e-300))
        rho = np.where(u <= k, 0.5 * u**2, k * (u - 0.5 * k))
    elif kind == "cauchy":
        w = 1.0 / (1.0 + (u / k) ** 2)
        rho = 0.5 * k**2 * np.log1p((u / k) ** 2)
    else:
        raise ValueError(f"unknown robust loss {kind!r}")
    return np.sqrt(w), rho


def _slots(k: np.ndarray) -> np.ndarray:
    """Rank of each measurement among those of its interval (k sorted)."""
    if k.size == 0:
        return k
    first = np.searchsorted(k, k, side="left")
    return np.arange(k.size) - first


@dataclass
class Linearization:
    A_u: np.ndarray
    """(N-1, Ru, 11) unary rows on block k."""
    b_u: np.ndarray
    A_m0: np.ndarray
    """(N-1, 3, 11) motion rows on block k."""
    A_m1: np.ndarray
    """(N-1, 3, 3) motion rows on the pose of block k+1."""
    b_m: np.ndarray
    A_w0: np.ndarray
    """(N-1, 8, 8) random-walk rows on W_k: A_w0 dW_k + A_w1 dW_{k+1} = b_w."""
    A_w1: np.ndarray
    """(N-1, 8, 8) the same rows on W_{k+1}."""
    b_w: np.ndarray
    A_p: np.ndarray
    """(11, 11) prior rows on block 0."""
    b_p: np.ndarray
    cost: float
    """0.5 * sum of squared whitened residuals (robust-weighted where robust)."""
    A_r: np.ndarray | None = None
    """With range biases: (R, 11) range rows on the block of interval ``kf.rng_k``."""
    A_rb: np.ndarray | None = None
    """(R, B) the same rows on the bias vector."""
    b_r: np.ndarray | None = None
    A_bp: np.ndarray | None = None
    """(B, B) prior rows on the bias vector."""
    b_bp: np.ndarray | None = None


def walk_rows(prob: Problem, W: np.ndarray, k0: int, k1: int, laplace: bool = False):
    """(A_w0, A_w1, b_w, cost): the whitened random-walk rows of W from
    keyframe k to k+1 for k in [k0, k1), (n, 8, 8) Jacobians on W_k and
    W_{k+1} and (n, 8) right-hand sides, in wheel-speed units when the scale
    factors are anchored (Problem.wheel_speed_units); with a finite
    Problem.slip_step_k the slips' rows are the common-mode and differential
    steps (RandomWalkSteps.slip_split), the first Huber-weighted, and
    ``cost`` is its true loss less its weighted square (else 0). Shared by
    batch (linearize) and the incremental smoothers, which give GTSAM the
    same rows.

    ``laplace``: rows for the covariance (batch.marginal_blocks), not for a
    step: a Huber step beyond its threshold gets the loss's own curvature
    there, 0 (LAPLACE_FLOOR), not the IRLS weight k/|u|. In its linear part
    the loss does not care when between two keyframes a stall's slip steps,
    and only the data say; the IRLS weight claimed to know. Measured on five
    stall logs (ranges, one with GPS too): the largest z 4.7-6.8 -> 3.6-5.7;
    the paper and yard logs' mean pose NEES within 0.03 of the IRLS weight's."""
    w0, w1 = W[k0:k1], W[k0 + 1:k1 + 1]
    A_w = prob.rw.whiten(slice(k0, k1))
    b_w = -np.einsum("kij,kj->ki", A_w, w1 - w0)
    A_w0, A_w1 = -A_w, A_w.copy()       # fresh arrays: the branches below write into them
    if prob.wheel_speed_units:
        # Steps of (mean ticks/m scale) v and scale x slip, relative to
        # speed_ref, instead of v and slip. A Gaussian walk on v itself is
        # cheapest when every speed is small, and the encoder model lets the
        # scale factors pay for that (k (v + slip) = measured): the MAP
        # estimate shrinks the speeds, inflating ticks/m and deflating track
        # by about (walk cost of the manoeuvres) / (GPS information on the
        # path's size), 2 % at 0.34 m GPS (benchmarks/README.md). In
        # wheel-speed units that trade earns nothing. omega keeps its plain
        # walk: heading sensors pin its scale, and a walk on scale_track x
        # omega measured worse (a track bias with a noisy gyro and good GPS).
        ref = np.asarray(prob.speed_ref, float)
        sc0, sc1 = w0[:, WSC] / ref, w1[:, WSC] / ref
        f0, f1 = 0.5 * (sc0[:, 0] + sc0[:, 1]), 0.5 * (sc1[:, 0] + sc1[:, 1])
        a = A_w[:, 0, 0]                                          # v: a diagonal whitener row
        b_w[:, 0] = -a * (f1 * w1[:, 0] - f0 * w0[:, 0])
        A_w0[:, 0, :] = 0.0
        A_w1[:, 0, :] = 0.0
        A_w0[:, 0, 0] = -a * f0
        A_w1[:, 0, 0] = a * f1
        for c in (5, 6):
            A_w0[:, 0, c] = -a * w0[:, 0] / (2 * ref[c - 5])
            A_w1[:, 0, c] = a * w1[:, 0] / (2 * ref[c - 5])
        L = A_w[:, WSL, WSL]                                      # slips: a 2x2 block
        b_w[:, WSL] = -np.einsum("kij,kj->ki", L, sc1[:, 0:2] * w1[:, WSL] - sc0[:, 0:2] * w0[:, WSL])
        A_w0[:, WSL, :] = 0.0
        A_w1[:, WSL, :] = 0.0
        A_w0[:, WSL, WSL] = -L * sc0[:, None, 0:2]
        A_w0[:, WSL, WWS] = -L * (w0[:, WSL] / ref[0:2])[:, None, :]
        A_w1[:, WSL, WSL] = L * sc1[:, None, 0:2]
        A_w1[:, WSL, WWS] = L * (w1[:, WSL] / ref[0:2])[:, None, :]
    cost = 0.0
    if math.isfinite(prob.slip_step_k):
        # Slip is not a slow random walk: a wheel grips or spins, and a stall
        # starts and ends within a second. Huber on the common-mode step costs
        # such a step linearly beyond k sigma, so it is taken where the data
        # put it; for the covariance (laplace) the loss's curvature there.
        R = prob.rw.slip_split
        A_w0[:, WSL, :] = np.einsum("ij,kjl->kil", R, A_w0[:, WSL, :])
        A_w1[:, WSL, :] = np.einsum("ij,kjl->kil", R, A_w1[:, WSL, :])
        b_w[:, WSL] = b_w[:, WSL] @ R.T
        c = WSL.start
        sw, rho = robust_weight(b_w[:, c], "huber", prob.slip_step_k)
        cost = float(np.sum(rho - 0.5 * (sw * b_w[:, c]) ** 2))
        if laplace:
            sw = robust_curvature(b_w[:, c], "huber", prob.slip_step_k)
        A_w0[:, c, :] *= sw[:, None]
        A_w1[:, c, :] *= sw[:, None]
        b_w[:, c] *= sw
    return A_w0, A_w1, b_w, cost


def slip_prior_rows(prob: Problem, w: np.ndarray, zero: np.ndarray):
    """The whitened rows of the slip priors on W rows w (n, 8): the schedule's
    zero-slip pseudo-prior (eq. 35-36) where ``zero`` (n,) is set, and
    elsewhere the sparse Cauchy prior (Problem.slip_robust) if there is one.
    Returns (b (n, 2), A (n, 2, 4) on tangent columns [SL, SR, KL, KR],
    slip_cost: the Cauchy rows' true loss minus their weighted square).
    Shared by batch (linearize) and the incremental smoothers.

    The Cauchy loss is of the whitened slip norm u = |s|/c, both wheels
    jointly as GTSAM's Robust(Cauchy): rho = log(1 + u^2) / 2. IRLS: at the
    current s it acts as Gaussian rows of weight 1 / (1 + u^2), whose
    gradient equals rho's.

    In wheel-speed units (Problem.wheel_speed_units) the sparse prior holds
    (k_i / ref_i) s_i near zero, the slip as encoders of the nominal scale
    ref see it, and not s_i. The wheels measure k (v + s); a prior on s
    itself is cheapest when every slip is small, and larger ticks/m pay for
    that at no cost to the wheel residuals. With weak fixes that pull wins:
    in its log tail during a slip, the Cauchy prior pulls with about one
    unit of cost per slipping keyframe and wheel on log k, and a 150 s yard
    log with 10 m fixes came out with ticks/m +14 % off at 4.7 sigma, on
    every seed. In wheel-speed units the trade earns nothing, as for the
    random walks (walk_rows)."""
    n = len(w)
    s_fixed = np.where(zero, 1.0 / prob.robot.process.pseudo_slip_sigma, 0.0)[:, None] * np.ones(2)
    A = np.zeros((n, 2, 4))
    if prob.wheel_speed_units and prob.slip_robust is not None:
        # The sparse prior only: the window's pseudo-prior holds the slip at
        # zero, where both forms agree and nothing pulls on the scale, and on
        # scale x slip it would tie the scale to the slip wherever an estimate
        # passes far from zero (a restart far off went to a track 9 % off).
        ref = np.asarray(prob.speed_ref, float)[0:2]
        sc = np.where(zero[:, None], 1.0, w[:, WWS] / ref)
        slip, d_slip, d_scale = sc * w[:, WSL], sc, np.where(zero[:, None], 0.0, w[:, WSL] / ref)
    else:
        slip, d_slip, d_scale = w[:, WSL], np.ones((n, 2)), None
    sw, slip_cost = s_fixed, 0.0
    if prob.slip_robust is not None:
        c = prob.slip_robust
        u2 = np.sum(slip ** 2, 1) / c**2
        free = ~zero
        sw = np.where(free[:, None], (np.sqrt(1.0 / (1.0 + u2)) / c)[:, None] * np.ones(2), s_fixed)
        slip_cost = float(np.sum((0.5 * np.log1p(u2) - 0.5 * np.sum((slip * sw) ** 2, 1))[free]))
    A[:, 0, 0] = sw[:, 0] * d_slip[:, 0]
    A[:, 1, 1] = sw[:, 1] * d_slip[:, 1]
    if d_scale is not None:
        A[:, 0, 2] = sw[:, 0] * d_scale[:, 0]
        A[:, 1, 3] = sw[:, 1] * d_scale[:, 1]
    return -slip * sw, A, slip_cost


def linearize(prob: Problem, pose: np.ndarray, W: np.ndarray, k0: int = 0, k1: int | None = None,
              range_bias: np.ndarray | None = None, laplace: bool = False) -> Linearization:
    """Whitened linearisation at the estimate (pose (N, 3) world, W (N, 8),
    range_bias (B,) [m] when prob.range_bias_sigma is set).

    Only the intervals k0 <= k < k1 (default: all) are linearised, reading
    keyframes k0..k1; the incremental smoothers linearise one new interval at a
    time. The prior on keyframe 0 is included when k0 == 0. ``laplace``: the
    robust random-walk rows weighted by their loss's curvature, for the
    covariance (walk_rows).
    """
    kf, r = prob.kf, prob.robot
    k1 = kf.n - 1 if k1 is None else k1
    n1 = k1 - k0
    x, y, th = pose[k0:k1, 0], pose[k0:k1, 1], pose[k0:k1, 2]
    w = W[k0:k1]
    dt = kf.dt[k0:k1]
    A_u = np.zeros((n1, prob.rows_unary, NB))
    b_u = np.zeros((n1, prob.rows_unary))
    robust_cost = 0.0

    # --- encoder over each interval (eq. 29-34), exact for the averages.
    h, J = encoder.wheel_speeds(w[:, 0], w[:, 1], w[:, 3], w[:, 4], w[:, 5], w[:, 6], w[:, 7], r.track_width)
    inv = 1.0 / kf.enc_sigma[k0:k1]
    b_u[:, ROW_ENC] = -(h - kf.enc_m[k0:k1]) * inv
    A_u[:, ROW_ENC][:, :, _ENC_COLS] = J * inv[:, :, None]
    # --- gyro average (eq. 10-11), and the velocity sensor's (sec. VI-B); keyframes.interval_means.
    s = 1.0 / kf.gyro_sigma[k0:k1]
    if np.any(s > 0):
        h, J = gyro.yaw_rate(w[:, 1], w[:, 2])
        b_u[:, ROW_GYRO] = -(h[:, 0] - kf.gyro_z[k0:k1]) * s
        A_u[:, ROW_GYRO, OM] = J[:, 0, 0] * s
        A_u[:, ROW_GYRO, B] = J[:, 0, 1] * s
    s = 1.0 / kf.vel_sigma[k0:k1]
    if np.any(s > 0):
        b_u[:, ROW_VEL] = -(w[:, S.W_VEL] - kf.vel_z[k0:k1]) * s
        A_u[:, ROW_VEL.start, V] = s[:, 0]
        A_u[:, ROW_VEL.start + 1, OM] = s[:, 1]
    # --- slip: the schedule's zero-slip pseudo-prior (eq. 35-36) inside the
    # calibration window; outside it, optionally a sparse (Cauchy) zero prior.
    b_u[:, ROW_SLIP], A_s, slip_cost = slip_prior_rows(prob, w, prob.zero_slip[k0:k1])
    A_u[:, ROW_SLIP][:, :, [SL, SR, KL, KR]] = A_s
    # --- GPS fixes (eq. 8-9) at tau after t_k, on the arc flown from X_k.
    g0, g1 = np.searchsorted(kf.gps_k, [k0, k1])
    if g1 > g0:
        k = kf.gps_k[g0:g1] - k0
        tvw = kf.gps_tau_vw[g0:g1]
        p, Jf = arc_at(x[k], y[k], th[k], w[k, 0], w[k, 1], tvw[:, 0], tvw[:, 1], _rows(kf.gps_bend, g0, g1))
        h, Jh = gps_model.antenna_position(p[:, 0], p[:, 1], p[:, 2], r.gps_lever_arm)
        Jt = Jh @ Jf                                              # (G, 2, 5) world (x, y, theta, v, omega)
        inv = (1.0 / kf.gps_sigma[g0:g1])[:, None]
        if prob.robust is not None:
            u = np.hypot(*((h - kf.gps_xy[g0:g1]) * inv).T)
            sw, rho = robust_weight(u, prob.robust, prob.loss_k())
            robust_cost += float(np.sum(rho - 0.5 * (sw * u) ** 2))   # replaces the weighted square below
            inv = inv * sw[:, None]
        rows = prob.gps_rows(prob.gps_slot[g0:g1])
        for j in range(2):
            b_u[k, rows + j] = -(h[:, j] - kf.gps_xy[g0:g1, j]) * inv[:, 0]
            A_u[k, rows + j, 0:3] = pose2.to_body(Jt[:, j:j + 1, 0:3], th[k])[:, 0] * inv
            A_u[k, rows + j, V] = Jt[:, j, 3] * inv[:, 0]
            A_u[k, rows + j, OM] = Jt[:, j, 4] * inv[:, 0]
    # --- ranges (eq. 12-16), likewise.
    q0, q1 = np.searchsorted(kf.rng_k, [k0, k1])
    A_r = A_rb = b_r = A_bp = b_bp = None
    nb = prob.n_bias
    if nb and range_bias is None:
        range_bias = np.zeros(nb)
    if q1 > q0:
        k = kf.rng_k[q0:q1] - k0
        tvw = kf.rng_tau_vw[q0:q1]
        p, Jf = arc_at(x[k], y[k], th[k], w[k, 0], w[k, 1], tvw[:, 0], tvw[:, 1], _rows(kf.rng_bend, q0, q1))
        bias = range_bias[kf.rng_id[q0:q1]] if nb else 0.0
        h, Jh = ranging.beacon_range(p[:, 0], p[:, 1], p[:, 2], kf.rng_beacon[q0:q1], r.range_lever_arm, bias)
        Jt = Jh[:, :, :3] @ Jf
        inv = np.full(q1 - q0, 1.0 / r.range_sigma)
        if prob.robust is not None:
            u = (h[:, 0] - kf.rng_z[q0:q1]) * inv
            sw, rho = robust_weight(u, prob.robust, prob.loss_k())
            robust_cost += float(np.sum(rho - 0.5 * (sw * u) ** 2))
            inv = inv * sw
        rb = -(h[:, 0] - kf.rng_z[q0:q1]) * inv
        ra = np.zeros((q1 - q0, NB))
        ra[:, 0:3] = pose2.to_body(Jt[:, :, 0:3], th[k])[:, 0] * inv[:, None]
        ra[:, V] = Jt[:, 0, 3] * inv
        ra[:, OM] = Jt[:, 0, 4] * inv
        if nb:
            A_r, b_r = ra, rb
            A_rb = np.zeros((q1 - q0, nb))
            A_rb[np.arange(q1 - q0), kf.rng_id[q0:q1]] = Jh[:, 0, 3] * inv
        else:
            rows = prob.range_rows(prob.rng_slot[q0:q1])
            b_u[k, rows] = rb
            A_u[k, rows] = ra
    if nb:
        A_bp = np.eye(nb) / prob.range_bias_sigma
        b_bp = -range_bias / prob.range_bias_sigma

    # --- motion: X_{k+1} against the arc of W_k's average velocity.
    nxt = pose[k0 + 1:k1 + 1]
    e, J0, J1 = transition_residual(x, y, th, w[:, 0], w[:, 1], dt, nxt[:, 0], nxt[:, 1], nxt[:, 2],
                                    _rows(kf.trans_bend, k0, k1))
    sm = prob.motion_whiten[k0:k1]
    b_m = -e * sm
    A_m0 = np.zeros((n1, 3, NB))
    A_m0[:, :, 0:3] = pose2.to_body(J0[:, :, 0:3], th) * sm[:, :, None]
    A_m0[:, :, V] = J0[:, :, 3] * sm
    A_m0[:, :, OM] = J0[:, :, 4] * sm
    A_m1 = pose2.to_body(J1, nxt[:, 2]) * sm[:, :, None]

    # --- random walk of W, in wheel-speed units when the scale factors are anchored.
    A_w0, A_w1, b_w, walk_cost = walk_rows(prob, W, k0, k1, laplace)
    robust_cost += walk_cost
    if prob.velocity_loss is not None:
        # Robust velocity steps: a robot whose commanded speed jumps (pivots
        # starting and stopping within one encoder period) breaks the Gaussian
        # random walk, and a quadratic penalty on those jumps pulls the scale
        # factors towards shrinking every velocity. v and omega have diagonal
        # whiteners, so their rows are weighted one by one (IRLS).
        sw, rho = robust_weight(b_w[:, 0:2], prob.velocity_loss, VELOCITY_LOSS_K[prob.velocity_loss])
        robust_cost += float(np.sum(rho - 0.5 * (sw * b_w[:, 0:2]) ** 2))
        if laplace:      # (walk_rows)
            sw = robust_curvature(b_w[:, 0:2], prob.velocity_loss, VELOCITY_LOSS_K[prob.velocity_loss])
        A_w0[:, 0:2, :] *= sw[:, :, None]
        A_w1[:, 0:2, :] *= sw[:, :, None]
        b_w[:, 0:2] *= sw

    # --- prior on keyframe 0 (world-frame covariance mapped to the body tangent).
    A_p = b_p = None
    if k0 == 0:
        d0 = np.concatenate([[pose[0, 0], pose[0, 1], pose[0, 2]], W[0]]) - prob.prior_mean
        d0[2] = np.angle(np.exp(1j * d0[2]))
        Lp = np.linalg.inv(np.linalg.cholesky(prob.prior_cov))
        M = np.eye(NB)
        c0, s0 = np.cos(pose[0, 2]), np.sin(pose[0, 2])
        M[0:2, 0:2] = [[c0, -s0], [s0, c0]]                      # d world / d body
        A_p = Lp @ M
        b_p = -Lp @ d0

    cost = 0.5 * (np.sum(b_u**2) + np.sum(b_m**2) + np.sum(b_w**2) + (np.sum(b_p**2) if b_p is not None else 0.0))
    if nb:
        cost += 0.5 * (np.sum(b_bp**2) + (np.sum(b_r**2) if b_r is not None else 0.0))
    # IRLS rows carry weighted squares; robust_cost holds (true loss - weighted square).
    cost += robust_cost
    cost += slip_cost
    return Linearization(A_u, b_u, A_m0, A_m1, b_m, A_w0, A_w1, b_w, A_p, b_p, float(cost), A_r, A_rb, b_r,
                         A_bp, b_bp)


def motion_sigma(kf: Keyframes, q_w: float, track_width: float) -> np.ndarray:
    """(N-1, 3) 1-sigma of the motion residual (along-track, lateral [m], heading [rad]).

    With W_k the exact interval average, the arc is exact for a constant
    yaw rate; what remains is the yaw rate varying inside the interval, which
    bends the path sideways by about |v| dt * sqrt(q_omega dt / 12), plus
    a 1 mm / 0.1 mrad floor for everything second order. |v| comes from the
    measured wheel speeds, not the estimate: a noise model that moved with the
    state would add a term to the cost that Gauss-Newton does not see.

    An interval longer than PAUSE_S (a silence of every sensor, or of the
    wheels alone, which keyframes.py gives one interval) is as loose as the
    EKF's pause: PAUSE_PATH_SHARE of the wheels' distance along and across,
    PAUSE_TURN_SHARE of their net turn (track_width [m]) in heading. A
    wheel_speeds.csv log has no speed across a silence (keyframes.py: zero),
    so its interval stays tight (a known gap).
    """
    dt = kf.dt
    speed = np.abs(kf.enc_m.mean(1))
    lat = speed * dt * np.sqrt(q_w * dt / 12.0)
    out = np.empty((len(dt), 3))
    out[:, 0] = 1e-3
    out[:, 1] = np.sqrt(1e-6 + lat**2)
    out[:, 2] = 1e-4
    # An interval across a silence of every sensor (keyframes.py gives it
    # one interval): the wheels' ticks say how far and how much it turned
    # net, not along what path, so the arc is as loose as the EKF makes it
    # (measurements.PAUSE_PATH_SHARE, PAUSE_TURN_SHARE): a share of the distance
    # along and across, a share of the turn in heading. Tight, it held the
    # incremental smoothers' pose metres from the fixes after a probe's
    # 30 s silence (400 fixes gated, z 25-130).
    pause = dt > PAUSE_S
    if pause.any():
        dist = speed[pause] * dt[pause]
        turn = np.abs(kf.enc_m[pause, 1] - kf.enc_m[pause, 0]) / track_width * dt[pause]
        out[pause, 0] = np.maximum(out[pause, 0], PAUSE_PATH_SHARE * dist)
        out[pause, 1] = np.maximum(out[pause, 1], PAUSE_PATH_SHARE * dist)
        out[pause, 2] = np.maximum(out[pause, 2], PAUSE_TURN_SHARE * turn)
    return out


#: Robust weight below which a measurement counts as rejected, and as down-weighted.
REJECTED_WEIGHT = 0.05
DOWNWEIGHTED_WEIGHT = 0.5


def _rows(a: np.ndarray | None, i0: int, i1: int) -> np.ndarray | None:
    """a[i0:i1], or None (keyframes without bends: arcs)."""
    return None if a is None else a[i0:i1]


def measurement_weights(prob: Problem, pose: np.ndarray, W: np.ndarray) -> dict[str, np.ndarray]:
    """Robust weight (IRLS, 0..1) of each GPS fix and range at the estimate, at
    the loss's target threshold; {} without a robust loss. For counting what
    the loss rejected (weight < REJECTED_WEIGHT) and down-weighted."""
    if prob.robust is None:
        return {}
    kf, r = prob.kf, prob.robot
    k = (prob.robust_k or ROBUST_K[prob.robust])
    out = {}
    if kf.gps_k.size:
        j = kf.gps_k
        p, _ = arc_at(pose[j, 0], pose[j, 1], pose[j, 2], W[j, 0], W[j, 1], kf.gps_tau_vw[:, 0], kf.gps_tau_vw[:, 1],
                      kf.gps_bend)
        h, _ = gps_model.antenna_position(p[:, 0], p[:, 1], p[:, 2], r.gps_lever_arm)
        u = np.hypot(*((h - kf.gps_xy) / kf.gps_sigma[:, None]).T)
        out["gps"] = robust_weight(u, prob.robust, k)[0] ** 2
    if kf.rng_k.size:
        j = kf.rng_k
        p, _ = arc_at(pose[j, 0], pose[j, 1], pose[j, 2], W[j, 0], W[j, 1], kf.rng_tau_vw[:, 0], kf.rng_tau_vw[:, 1],
                      kf.rng_bend)
        h, _ = ranging.beacon_range(p[:, 0], p[:, 1], p[:, 2], kf.rng_beacon, r.range_lever_arm)
        u = (h[:, 0] - kf.rng_z) / r.range_sigma
        out["ranges"] = robust_weight(u, prob.robust, k)[0] ** 2
    return out


def robust_counts(prob: Problem, pose: np.ndarray, W: np.ndarray) -> tuple[dict[str, int], dict[str, int]]:
    """(rejected, down-weighted) counts per sensor at the estimate (measurement_weights)."""
    wts = measurement_weights(prob, pose, W)
    rej = {s: int(np.sum(w < REJECTED_WEIGHT)) for s, w in wts.items()}
    down = {s: int(np.sum((w >= REJECTED_WEIGHT) & (w < DOWNWEIGHTED_WEIGHT))) for s, w in wts.items()}
    return {s: n for s, n in rej.items() if n}, {s: n for s, n in down.items() if n}
