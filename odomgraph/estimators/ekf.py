"""The velocity-augmented EKF of Kreinar & Quinn (paper sec. II-III).

State (paper eq. 1 + 28, plus the gyro bias of sec. II-C), ``state.NAMES``:
    [x, y, theta, v, omega, gyro_bias, slip_left, slip_right,
     scale_left, scale_right, scale_track]

Every measurement is processed at its own timestamp: the filter predicts to it
(exact-arc motion, factors.motion) and updates with that sensor's model from
``factors``. Encoder updates are preceded by the schedule's pseudo-update
(zero slip while calibrating; hold the scale factors afterwards).

Process noise (the paper's "system noise"): v and omega are random walks
driven by white acceleration; bias, slips and scale factors are random walks
(ProcessNoise). For a rate state r with intensity q and pose sensitivity
J_r = d pose / d r over the step, noise entering at a uniformly distributed
time inside the step gives
    Q_pose,pose += q dt/3 J_r J_r^T,  Q_pose,r += q dt/2 J_r,  Q_r,r += q dt,
which is exact for the straight-line case (the classic dt^3/3, dt^2/2, dt
white-acceleration blocks).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from odomgraph.factors import encoder, gps, gyro, pseudo, ranging, velocity
from odomgraph.factors._math import wrap_angle
from odomgraph.factors.motion import propagate
from odomgraph import state as S
from odomgraph.checks import bounded, check_fields
from odomgraph.errors import EstimatorDivergedError
from odomgraph.estimators.heading import HeadingWatch, circle_variance
from odomgraph.estimators.initial import ANCHOR_SHARE, InitialState, initial_state
from odomgraph.estimators.measurements import (PAUSE_PATH_SHARE, PAUSE_S, PAUSE_TURN_SHARE, from_log, pause_spans,
                                                slip_intensity)
from odomgraph.observability import decondition, held_pins
from odomgraph.estimators.slipcheck import in_stretches, in_window
from odomgraph.estimators.standstill import StillWatch
from odomgraph.result import DEPARTURE_SAYS, Estimate, Innovations
from odomgraph.estimators.schedule import Hold, Schedule
from odomgraph.io.log import Log

from odomgraph.estimators.sensors import (DOF, ENC_IDX, GATED, GPS, GYRO, GYRO_IDX, POSE_IDX, RANGE, SCALE_IDX,
                                         SENSOR_NAMES, SLIP_IDX, VEL, VEL_IDX, WHEEL, event_stream)

_I = np.eye(S.N)


#: Defaults of EKFOptions.jump_speed [m/s] and jump_hold [s]; the incremental
#: smoothers' first-linearisation gate holds jumps out by the same rule.
JUMP_SPEED = 3.0
JUMP_HOLD = 30.0



def common_scale_direction(x: np.ndarray) -> np.ndarray:
    """(..., 11) unit direction of the common scale at state(s) ``x`` (..., 11):
    ticks/m left and right up and the track scale down by the same relative
    amount, (k_L, k_R, -k_T) / norm on the scale states, 0 elsewhere. The
    wheels cannot see a change along it (EKFOptions.encoder_scale_gain)."""
    u = np.zeros(np.shape(x))
    u[..., SCALE_IDX] = x[..., SCALE_IDX] * np.array([1.0, 1.0, -1.0])
    return u / np.linalg.norm(u, axis=-1, keepdims=True)


def held_directions(x: np.ndarray, pinned: np.ndarray, common_pinned: bool) -> np.ndarray:
    """The direction(s) the encoder update's gain must not move the state
    along, at state(s) ``x`` (..., 11): the common scale
    (common_scale_direction), and the pinned scale combinations ``pinned``
    (3, k) (observability.pinned_basis), held at nominal by their tight prior.

    Taking the common direction out of a gain puts some of it back along a
    pinned one: on a probe's straight-line log the pinned track moved 4 % in
    2 s and ended "held at nominal" at 1.038 at a claimed sigma of 0.006
    (truth 0.90). So the pinned directions are taken out too, and the common
    one orthogonally to them. With the common scale pinned (``common_pinned``)
    the wheels see the track against the gyro, and only the pins are held:
    the common direction lies in the span of the common scale and the track,
    and taking it out would freeze the track.

    Returns (..., 11) the unit common direction when nothing is pinned (as
    before pins were held), else (..., 11, m) orthonormal columns."""
    u = common_scale_direction(x)
    k = pinned.shape[1]
    if k == 0:
        return u
    out = np.zeros(np.shape(x)[:-1] + (S.N, k + (0 if common_pinned else 1)))
    out[..., SCALE_IDX, :k] = pinned
    if not common_pinned:
        us = u[..., SCALE_IDX]
        up = us - (us @ pinned) @ pinned.T       # (u is never in the span of the ratio and the track)
        out[..., SCALE_IDX, k] = up / np.linalg.norm(up, axis=-1, keepdims=True)
    return out


@dataclass(frozen=True)
class EKFOptions:
    gate: float | None = bounded(None, gt=0, optional=True)
    """NIS threshold of the Mahalanobis gate on GPS, range and velocity
    updates; None: the chi-square quantile at ``gate_probability`` for each
    sensor's dimension (27.6 for GPS, 23.9 for a range at 1 - 1e-6)."""
    gate_probability: float = bounded(1 - 1e-6, gt=0, le=1)
    """Share of good measurements the default gate keeps; 1 turns the gate off.
    A gate at 0.9999 (NIS 18.4 for GPS) rejected good fixes during the lag
    after each slip step and cost 16 % of slip accuracy on the yard scenario;
    at 1 - 1e-6 it rejected none of them and still rejects a 5 m outlier of
    a 5 cm GPS (NIS ~ 10^4)."""
    reacquire_after: int = bounded(5, ge=2, integer=True)
    """After this many consecutive rejections of one sensor the gate does not
    lock the filter out: the covariance that sensor sees is widened by the
    rejected innovations, so that the next measurement can pull the state
    back (a recovery, counted and reported)."""
    jump_speed: float = bounded(JUMP_SPEED, gt=0, infinite=True)
    """A GPS fix or range whose innovation steps from the one before faster
    than this [m/s] (plus the noise of both) has jumped, not the state: no
    robot's position error changes that fast. Its sensor is held out
    (``jump_hold``) instead of re-acquired, until it comes back. Three
    growing innovations that step no faster are a departure (``departed``)."""
    jump_hold: float = bounded(JUMP_HOLD, gt=0, infinite=True)
    """How long [s] a jumped sensor is held out before the filter re-acquires
    it anyway (a datum that really moved). A probe's 2 s multipath burst of
    3.6 m at 20 Hz was followed, then its end rejected, and the filter stopped."""
    max_scale_error: float = bounded(5.0, gt=0, infinite=True)
    """|scale - 1| beyond which the filter is declared diverged (a scale factor
    must also stay above 0.05). Real nominal parameters can be off by 2x (the
    libRSF cut), so only the non-physical is divergence; far outside the
    prior is a warning (pipeline)."""
    max_mean_nis: float = bounded(50.0, gt=0, infinite=True)
    """Diverged when a sensor's running mean NIS (about its last 50 updates)
    exceeds this many times its dimension: the filter no longer explains the data."""
    pin: tuple[tuple[str, str], ...] = ()
    """(scale combination, reason) pairs to hold at nominal with their prior
    sigma, as if the log could not determine them (observability)."""
    slip_states: bool = True
    """False removes the slip states (they stay exactly 0 with zero variance):
    the conventional filter that believes odometry, the paper's fig. 7 baseline."""
    encoder_scale_gain: bool = False
    """True: the paper's encoder update (eq. 29-34), whose gain moves the
    scale factors in every direction. False (default): the gain has no
    component along the common scale (common_scale_direction; Joseph form,
    exact for that gain), nor along a pinned combination (held_directions),
    which only absolute sensors move, through the
    correlations the encoder updates build. Wheels measure ticks/m x speed:
    with the yaw rate known, (ticks/m L, R) x (1 + e), track / (1 + e) and
    speed / (1 + e) predict the same ticks, so the wheels carry no
    information along that direction. A gain along it lets the EKF
    relinearise that product at every speed it passes and gain information
    that is not in the data (the inconsistency of EKF-SLAM's heading, Huang
    et al. 2008, here on the surface k v = measured). With 2 m GPS at 1 Hz
    and a 120 s calibration window the paper's update put ticks/m 12-16 %
    off at 8-12 of its sigmas (yard and paper scenarios, both signs).
    Zeroing the whole scale gain fixed that but lost the track's
    calibration from wheels + gyro (1.1 % off on yard, target 0.5 %)."""

    def __post_init__(self):
        check_fields(self)




def gate_thresholds(options: EKFOptions) -> dict[int, float | None]:
    """NIS threshold of each gated sensor (None: no gate): the option, or the
    chi-square quantile at gate_probability for the sensor's dimension."""
    from statistics import NormalDist
    out = {}
    for code in GATED:
        if options.gate is not None:
            out[code] = options.gate
        elif options.gate_probability >= 1.0:
            out[code] = None
        elif DOF[code] == 1:
            out[code] = NormalDist().inv_cdf(0.5 * (1.0 + options.gate_probability)) ** 2
        else:                                  # chi-square with 2 dof: -2 ln(1 - p)
            out[code] = -2.0 * float(np.log1p(-options.gate_probability))
    return out


#: Recoveries (re-acquisitions, widenings) one run may take before it gives up.
MAX_RECOVERIES = 50


def watch_widening(code: int, y: np.ndarray) -> tuple[slice, np.ndarray] | None:
    """(state block, variance to add) that lets the filter follow an ungated
    sensor whose innovations stay far beyond their noise: wheel speeds the
    slip states cannot reach fast enough (a stall, nominal parameters far
    off), a gyro whose bias jumped. y: the latest innovation."""
    if code == WHEEL:
        return SLIP_IDX, y**2
    if code == GYRO:
        return slice(S.BIAS, S.BIAS + 1), y**2
    return None


#: Recent innovations per sensor (and beacon) the gate compares a measurement with.
GATE_HISTORY = 5


def gate_reference(history: list) -> np.ndarray | None:
    """The median of a sensor's recent innovations, or None while there are fewer than 3.

    The gate rejects a measurement only when it is far from the state *and*
    from what the sensor has been saying lately. A gross outlier is a spike in
    the innovation sequence, far from both; when the state itself is off (a
    wrong nominal wheel scale, an unmodelled stall) every innovation is large
    and alike, and they are used, which is how the filter gets back. On the
    real libRSF cut as first imported (its track halved and its wheels
    swapped, io/importers/librsf.py), a state-only gate rejected 21 good
    ranges early and the error went from 0.36 to 0.48 m."""
    n = len(history)
    if n < 3:
        return None
    # per axis, in plain floats: np.median cost 50 us a fix, a third of the
    # filter's time on a 10 Hz log (the same values: the middle one, or the
    # mean of the middle two)
    out = []
    for j in range(len(history[0])):
        v = sorted(float(h[j]) for h in history)
        out.append(v[n // 2] if n % 2 else 0.5 * (v[n // 2 - 1] + v[n // 2]))
    return np.array(out)


def jumped(y: np.ndarray, y_prev: np.ndarray, R: np.ndarray, dt: float, speed: float, gate: float) -> np.ndarray:
    """Whether innovations y (..., m) stepped from the sensor's previous ones
    y_prev by more than the state can move in dt seconds at ``speed`` [m/s],
    plus the noise R (..., m, m) of both: the NIS of the step against gate.
    (Batched over leading axes, for ekf_many.)"""
    d = y - y_prev
    m = d.shape[-1]
    Sj = 2.0 * R + (speed * dt) ** 2 * np.eye(m)
    return np.einsum("...i,...ij,...j->...", d, np.linalg.inv(Sj), d) > gate


def reacquire_widening(code: int, Y: np.ndarray) -> tuple[slice, np.ndarray]:
    """(state block, variance to add to its diagonal) that lets the filter
    re-acquire a sensor whose last measurements were all rejected.

    Y: (n, m) their innovations. A run of rejections from one sensor means the
    state has left what that sensor sees (a bad start, an unmodelled stall),
    not that every one of them was an outlier: widen the block the sensor
    measures by the mean squared innovation per axis, and the next
    measurement passes the gate and corrects the state through the usual
    update, its correlations included."""
    s2 = np.mean(Y**2, 0)
    if code == VEL:
        return VEL_IDX, s2
    per_axis = float(np.mean(s2))              # GPS: both axes; a range: its one value
    return POSE_IDX, np.array([per_axis, per_axis, 0.0])


#: NIS per degree of freedom beyond which an innovation counts as far (3 sigma)
#: in the departure test (departed).
DEPARTURE_NIS = 9.0


def departure_possible(nis, nis_prev, gate: float, dof: int):
    """The departure test's cheap half (``departed``'s first condition), on
    its own so the filters can skip the rest at once: the last NIS beyond the
    gate and the one before beyond DEPARTURE_NIS per dof. A bool or (...) bools."""
    return (nis > gate) & (nis_prev > DEPARTURE_NIS * dof)


def huber_widening(R: np.ndarray, Sm: np.ndarray, Sinv: np.ndarray, nis, gate: float):
    """(R, S^-1) of a measurement taken at a Huber weight: its noise widened
    until its NIS is the gate's (EKF.update's rescued ranges; ekf_many
    batched). R, Sm (innovation covariance), Sinv (..., m, m); nis (...)
    beyond the gate."""
    return R + Sm * (np.asarray(nis / gate)[..., None, None] - 1.0), Sinv * np.asarray(gate / nis)[..., None, None]


def departed(ys, nis, nis_prev, gate: float, dof: int, dts, R: np.ndarray, speed: float):
    """Whether a sensor's (or a beacon's) last three innovations say the
    state is leaving what it sees: the last beyond the gate, the one before
    beyond DEPARTURE_NIS per dof, all three in one direction and growing,
    and each step |d| no larger than ``speed`` dt and 3 sigma of the noise
    of both, added in quadrature (for a GPS fix, |d|^2 against 9 times the
    summed per-axis variance: chi-square with 2 dof at 9, about 2.5 sigma).
    Innovations: a range's [m], a GPS fix's world x, y [m]. ys: three (..., m) innovations [m], oldest first; nis, nis_prev
    (...): the last two's NIS; dts: the two steps [s]; R (..., m, m): the
    noise. Batched over leading axes (ekf_many); a bool or (...) bools.

    A rate state that stepped (a stall: the robot stops while its wheels
    spin on; the stall's end) puts the position off by an error that grows
    smoothly with time: a range-only yard log's stall end read -0.17, -0.23,
    -0.34, -0.54 m on the one beacon that saw it. An outlier steps up from
    the noise faster than a robot moves (a 2 m one within 0.5 s); three
    like-signed ones in a row, growing, are rare (20 % outliers of either
    sign: about one range in 2000). Taken on two in a row, 2 of the 16
    logs with 20 % range outliers in tests/test_range_outliers.py failed."""
    ok = departure_possible(nis, nis_prev, gate, dof)
    m = ys[0].shape[-1]
    n2 = 18.0 * np.trace(R, axis1=-2, axis2=-1) / m       # (3 sigma)^2 of a difference of two
    for (p, q), dt in zip(((ys[0], ys[1]), (ys[1], ys[2])), dts):
        d = q - p
        ok = ok & (np.sum(q * p, -1) > 0.0) & (np.sum(q * q, -1) > np.sum(p * p, -1)) \
            & (np.sum(d * d, -1) <= (speed * dt) ** 2 + n2)
    return ok


def departure_widening(y: np.ndarray, y_prev: np.ndarray, dt: float,
                       slips: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """(states, variance floor (...,)) that let the filter follow a
    departure (``departed``): v and the two slips floored at the square of
    the rate the innovation grew at, |y - y_prev| / dt [m/s]; y, y_prev
    (..., m) [m], dt [s]. ``slips`` False (EKFOptions.slip_states off: the
    conventional filter): v alone, the slips stay 0 with zero variance.

    v and the slips are random walks: a step of 1 m/s takes them about 2 s
    to follow while the position's sigma stays a few cm (a range-only 6 s
    stall: rows 0.3-2 m off at z 11-15, status ok). A floor, not an
    addition: a departure seen again and again does not pile up variance.
    The wheels tie v + slip tightly, so the next updates say which of the
    two stepped. (The position is not floored too: with it, lined-up
    outliers taken for a departure let the next ones in, and 2 of those 16
    logs failed, one 3.3 m off.)"""
    d = y - y_prev
    idx = np.array([S.V, S.SLIP_L, S.SLIP_R] if slips else [S.V])
    return idx, np.sum(d * d, -1) / (dt * dt)


def departure_note(t: float, code: int, floor: float, last: float, slips: bool = True) -> str | None:
    """The line of a departure at t [s] (Estimate.departures) (v, and the slips if
    ``slips``, floored at ``floor`` [(m/s)^2]), or None within 2 s of the
    one before (at ``last`` [s], -inf for none): one line per episode."""
    if t - last <= 2.0:
        return None
    return (f"t={t:.2f} s: {SENSOR_NAMES[code]}: {DEPARTURE_SAYS} (a stall, or its end); "
            f"{'v and the slips' if slips else 'v'} widened to {np.sqrt(floor):.2g} m/s to follow")


def rate_noise(q: dict, q_slip: np.ndarray) -> np.ndarray:
    """(11, 11) intensity matrix of the rate states' own random walks: v,
    omega, the bias, the slips' (2, 2) block and the scale factors, each
    added to P times dt at every step (ProcessNoise; q, q_slip as in
    add_process_noise). The pose's blocks depend on the step: add_process_noise."""
    Q = np.zeros((S.N, S.N))
    Q[S.V, S.V], Q[S.OMEGA, S.OMEGA], Q[S.BIAS, S.BIAS] = q["v"], q["w"], q["bias"]
    Q[SLIP_IDX, SLIP_IDX] = q_slip
    if q["scale"]:
        Q[SCALE_IDX, SCALE_IDX] = np.eye(3) * q["scale"]
    return Q


def add_process_noise(P: np.ndarray, J: np.ndarray, dt: float, q: dict, q_slip: np.ndarray,
                      rates: np.ndarray | None = None) -> None:
    """Add the discrete process noise of one step to P (11, 11) in place.

    J: (3, 5) motion Jacobian of the step; q: intensities (see ProcessNoise)
    squared, keys v, w, bias, scale; q_slip: (2, 2) slip intensity matrix;
    rates: their ``rate_noise`` matrix, when the caller keeps it (the EKF
    does: one addition instead of six slices per step).
    See the module docstring for the derivation; G = [J_v, J_omega].
    ``ekf_many.add_process_noise_many`` is the same for a batch of runs; this
    one stays scalar because it runs once per event (the throughput benchmark
    measured the broadcasting version about 25 % slower on the yard log).
    """
    G = J[:, VEL_IDX]                  # the step's columns are the state's first five
    Gq = G * (q["v"], q["w"])
    P[POSE_IDX, POSE_IDX] += (dt / 3.0) * (Gq @ G.T)
    P[POSE_IDX, VEL_IDX] += (0.5 * dt) * Gq
    P[VEL_IDX, POSE_IDX] += (0.5 * dt) * Gq.T
    P += dt * (rates if rates is not None else rate_noise(q, q_slip))


def _inv_small(A: np.ndarray) -> np.ndarray:
    """Inverse of a 1x1 or 2x2 innovation covariance in closed form (np.linalg.inv
    costs more than the rest of a scalar update); larger ones go to LAPACK."""
    m = A.shape[0]
    if m == 1:
        return 1.0 / A
    if m == 2:
        a, b, c, d = A[0, 0], A[0, 1], A[1, 0], A[1, 1]
        det = a * d - b * c
        return np.array([[d, -b], [-c, a]]) / det
    return np.linalg.inv(A)


class EKF:
    """One run of the filter over one log. Use ``run_ekf`` for the common case."""

    def __init__(self, log: Log, schedule: Schedule = Schedule(), options: EKFOptions = EKFOptions(),
                 init: InitialState | None = None):
        self.log, self.robot, self.schedule, self.options = log, log.robot, schedule, options
        self.meas = from_log(log)
        self.init = init or initial_state(self.robot, self.meas, dict(options.pin))
        self.x = self.init.x.copy()
        self.P = self.init.P.copy()
        self.t = self.init.t
        pn = self.robot.process
        self._q = dict(v=pn.accel**2, w=pn.yaw_accel**2, bias=pn.gyro_bias**2, scale=pn.scale**2)
        self._q_slip = slip_intensity(pn, self.meas)
        if not options.slip_states:
            self._q_slip = np.zeros((2, 2))
            self.x[SLIP_IDX] = 0.0
            self.P[SLIP_IDX, :] = 0.0
            self.P[:, SLIP_IDX] = 0.0
        self._rates = rate_noise(self._q, self._q_slip)
        self._R_slip = np.eye(2) * pn.pseudo_slip_sigma**2
        self._R_scale = np.eye(3) * pn.pseudo_scale_sigma**2
        self.holding_scale = False
        self.consider_heading = False      # (heading.HeadingWatch: no heading known yet)
        self.pause_spans = pause_spans(self.meas)              # the log's pauses (measurements.pause_spans)
        self.pauses: list[tuple[float, float]] = []           # (start, end) [s] of each pause crossed
        self.pause_travel: list[tuple[float, float, float]] = []  # (t, distance [m], turn [rad]) across them

    def __setstate__(self, state: dict) -> None:
        # a checkpoint written before pauses were handled has none of their state
        state.setdefault("pause_spans", [])
        state.setdefault("pauses", [])
        state.setdefault("pause_travel", [])
        state.setdefault("_anchor", None)     # nor a late fit's anchor
        state.setdefault("_anchor_until", (-1, -np.inf))
        state.setdefault("anchored", None)
        state.setdefault("_prev", {})     # nor the departures' watch
        if "still_watch" not in state:        # nor the standstill's (it starts afresh)
            state["still_watch"] = StillWatch(state["robot"])
        state.setdefault("last_departure", -np.inf)
        if "departures" not in state:         # older checkpoints kept them among the recoveries
            rec = state.get("recoveries", [])
            state["departures"] = [r for r in rec if DEPARTURE_SAYS in r]
            state["recoveries"] = [r for r in rec if DEPARTURE_SAYS not in r]
        self.__dict__.update(state)
        if "_rates" not in state:            # nor the rate noise kept whole
            self._rates = rate_noise(self._q, self._q_slip)
        if "_pinned" in state and "_held" not in state:     # nor the pins' basis
            obs = self.init.observability
            self._held = held_pins(obs)

    # ------------------------------------------------------------ predict
    def predict(self, t: float) -> None:
        """Propagate state and covariance to absolute time t (paper eq. 2-7)."""
        dt = t - self.t
        if dt <= 0.0:
            return
        if self._in_pause(t):
            self._pause(t)
            return
        x = self.x
        pose, J = propagate(x[0], x[1], x[2], x[3], x[4], dt)
        F = _I.copy()
        F[0:3, 0:5] = J
        P = F @ self.P @ F.T
        add_process_noise(P, J, dt, self._q, self._q_slip, self._rates)
        x[0], x[1], x[2] = pose[0], pose[1], wrap_angle(pose[2])
        self.P = P
        self.t = t

    def _in_pause(self, t: float) -> bool:
        """Whether the step from self.t to t [s] crosses a pause in the log:
        mostly inside one of ``pause_spans`` (a row spanning it is stamped at
        its midpoint, and splits it in two steps), or, where those are not
        known (a stream's measurements grow), a step longer than PAUSE_S."""
        dt = t - self.t
        if dt > PAUSE_S:
            return True
        return any(min(t, b) - max(self.t, a) > max(0.5 * dt, 0.25 * PAUSE_S) for a, b in self.pause_spans)

    def _pause(self, t: float) -> None:
        """Cross a pause (no reading of any sensor for more than PAUSE_S; a
        probe's log paused for an hour: coasting through it at constant
        velocity moved the mean by v dt and left the heading's sigma at
        110 rad, and 894 of 1499 fixes after it were rejected) to time t [s].

        The robot is taken to have stood still: the pose is held, and the
        velocity and the slips start afresh (zero, their starting variances,
        no correlation with the rest: after a pause the robot may drive off at
        any speed). The gyro bias and the scale factors keep their random
        walks over the whole pause. If the wheels did turn meanwhile, the
        encoder row that spans the pause says how far (``_pause_odometry``);
        if the robot was moved otherwise, the fixes after the pause show a
        jump, which the gate holds out and then re-acquires (counted)."""
        dt = t - self.t
        x, P, q = self.x, self.P, self._q
        fresh = [S.V, S.OMEGA] + ([S.SLIP_L, S.SLIP_R] if self.options.slip_states else [])
        start_var = np.diagonal(self.init.P)[fresh]
        self._prev = {}      # a departure's three innovations do not span a pause
        x[fresh] = 0.0
        P[fresh, :] = 0.0
        P[:, fresh] = 0.0
        P[fresh, fresh] = start_var
        P[S.BIAS, S.BIAS] += q["bias"] * dt
        if q["scale"]:
            P[SCALE_IDX, SCALE_IDX] += np.eye(3) * q["scale"] * dt
        if self.pauses and self.pauses[-1][1] == self.t:
            # one event alone between two silences (an encoder row spanning
            # the pause sits at its midpoint): one pause
            self.pauses[-1] = (self.pauses[-1][0], t)
        else:
            self.pauses.append((self.t, t))
        self.t = t

    def _pause_odometry(self, z: np.ndarray, interval: float) -> None:
        """Move the pose by the wheels' travel across a pause: ``z`` (2,) the
        nominal-converted (left, right) average wheel speeds [m/s] of an
        encoder row whose ``interval`` [s] spans it (no slip assumed, the
        current scale factors applied; paper eq. 29 inverted). The arc of
        the average velocity is exact in length and turn, not in shape:
        PAUSE_PATH_SHARE and PAUSE_TURN_SHARE give it its sigma."""
        x, P = self.x, self.P
        ul, ur = z[0] / x[S.SCALE_L], z[1] / x[S.SCALE_R]
        v, om = 0.5 * (ul + ur), (ur - ul) / (x[S.SCALE_B] * self.robot.track_width)
        dist, turn = abs(v) * interval, abs(om) * interval
        if dist == 0.0 and turn == 0.0:
            return
        pose, _ = propagate(x[0], x[1], x[2], v, om, interval)
        x[0], x[1], x[2] = pose[0], pose[1], wrap_angle(pose[2])
        scale_sd = float(np.sqrt(np.max(np.diagonal(P)[SCALE_IDX])))
        P[0, 0] += (PAUSE_PATH_SHARE * dist + scale_sd * dist) ** 2
        P[1, 1] += (PAUSE_PATH_SHARE * dist + scale_sd * dist) ** 2
        P[2, 2] += (PAUSE_TURN_SHARE * turn + scale_sd * turn) ** 2
        self.pause_travel.append((self.t, dist, turn))

    # ------------------------------------------------------------- update
    def update(self, z, h, H, idx, R, gate: float | None = None, ref=None, no_gain=None,
               huber: bool = False) -> float:
        """Kalman update with a Jacobian H (m, k) on the states ``idx``.

        Returns the NIS, or -NIS when the gate rejected the measurement: its
        NIS exceeds ``gate``, and so does its distance from ``ref``, the
        median of the sensor's recent innovations (see gate_reference).
        While ``self.holding_scale`` is set, the gain rows of the scale
        factors are zero (Schmidt "consider" update): they are held, while
        their uncertainty still enters every other state's covariance.
        ``no_gain``: a unit (11,) direction, or (11, m) orthonormal ones, the
        gain must not move the state along (held_directions: the encoder
        update's), considered the same way. ``huber``: a measurement the
        median rescues is taken with its NIS brought down to the gate's (ranges).
        """
        P = self.P
        PHt = P[:, idx] @ H.T                    # (n, m)
        Sm = H @ PHt[idx, :] + R                 # innovation covariance
        y = z - h
        self.last_y = y
        Sinv = _inv_small(Sm)
        nis = float(y @ Sinv @ y)
        if gate is not None and nis > gate:
            d = y if ref is None else y - ref
            if ref is None or float(d @ Sinv @ d) > gate:
                return -nis
            if huber:
                # A range rescued by its beacon's recent innovations: taken
                # with its noise widened until its NIS is the gate's (a Huber
                # weight). A range's outliers have one of two signs, so three
                # like-signed ones among five are common (20 % outliers: about
                # one a run) and the median lets the next in: at full weight a
                # 2 m one moved the state 1.6 m, at this weight P H gate / |y|,
                # 0.12 m. A run of them (a state that really left) still pulls
                # it back, a step at a time. GPS outliers point anywhere in the
                # plane and hardly ever line up, and a fix rescued after a
                # silence is taken whole: weighted, the rows 5 s after a 15 s
                # silence were 0.27 m off where they were under 0.2.
                R, Sinv = huber_widening(R, Sm, Sinv, nis, gate)
        K = PHt @ Sinv
        if self.holding_scale:
            K[SCALE_IDX, :] = 0.0
        elif no_gain is not None:
            K -= np.outer(no_gain, no_gain @ K) if no_gain.ndim == 1 else no_gain @ (no_gain.T @ K)
        if self.consider_heading:
            K[S.THETA, :] = 0.0
        self.x += K @ y
        self.x[2] = wrap_angle(self.x[2])
        # Joseph form P = (I-KH) P (I-KH)' + K R K'. It keeps P symmetric
        # positive semi-definite, and, unlike P = (I-KH)P, it stays exact for
        # the deliberately suboptimal gain of the consider update.
        IKH = _I.copy()
        IKH[:, idx] -= K @ H
        self.P = IKH @ P @ IKH.T + K @ R @ K.T
        return nis

    def _check(self) -> None:
        x = self.x
        d = np.diagonal(self.P)
        # one sum carries any inf or nan (it runs after every encoder update)
        if not math.isfinite(float(x.sum() + d.sum())) or d.min() < -1e-12:
            raise EstimatorDivergedError(f"EKF diverged at t={self.t:.3f} s: non-finite state or covariance")
        sc = x[SCALE_IDX]
        if np.abs(sc - 1.0).max() > self.options.max_scale_error or sc.min() < 0.05:
            raise EstimatorDivergedError(
                f"EKF diverged at t={self.t:.3f} s: scale factors {np.round(x[S.SCALE], 3).tolist()} are not "
                f"physical (outside 0.05 to {1 + self.options.max_scale_error:g})")

    # ---------------------------------------------------------------- run
    def run(self, progress=None) -> Estimate:
        """Filter the whole log. ``progress(done, total)`` is called now and then."""
        wall0 = time.perf_counter()
        m = self.meas
        t_ev, code_ev, row_ev = event_stream(m, self.init.t)
        n_rows = int(np.sum(code_ev == WHEEL))
        out_t = np.empty(n_rows)
        out_x = np.empty((n_rows, S.N))
        out_var = np.empty((n_rows, S.N))
        out_pose = np.empty((n_rows, 3, 3))
        nis = {k: [] for k in range(5)}
        self.begin()
        slip_ev = in_stretches(t_ev, self.slipping)
        row = 0
        stride = max(1, len(t_ev) // 200)
        for k in range(len(t_ev)):
            t, code, i = t_ev[k], code_ev[k], row_ev[k]
            value = self.step(t, code, *event_values(m, code, i), in_slip=slip_ev[k])
            nis[code].append((t, value))
            if code == WHEEL:
                out_t[row] = t
                out_x[row], out_var[row], out_pose[row] = self.row()
                row += 1
            if progress is not None and k % stride == 0:
                progress(k, len(t_ev))
        if progress is not None:
            progress(len(t_ev), len(t_ev))
        self._check()
        if row == 0:
            raise EstimatorDivergedError(f"EKF: no wheel measurement at or after its start (t={self.init.t:.6g} s, "
                                         f"{self.init.note}); the wheel odometry ends at t={m.wheel.t[-1]:.6g} s")
        return self.finish(out_t[:row], out_x[:row], out_var[:row], out_pose[:row], nis, time.perf_counter() - wall0)

    def begin(self) -> None:
        """Set up the event loop's state (the schedule's switch, the gates'
        histories, the divergence watch). ``run`` calls it; a caller that
        feeds ``step`` itself (odomgraph.online) calls it once first."""
        m, r, sch, opt = self.meas, self.robot, self.schedule, self.options
        self.t_switch = sch.switch_time(m.t_start)
        self.switch_sigma = None
        self._R = {GYRO: np.array([[r.gyro_sigma**2]]), VEL: np.diag(np.square(r.velocity_sigma)),
                   RANGE: np.array([[r.range_sigma**2]])}
        self._gates = gate_thresholds(opt)
        self.n_up = 0
        self._nis_ema = [float(d) for d in DOF]
        self._nis_clip = [10.0 * opt.max_mean_nis * d for d in DOF]
        self._n_seen = [0] * len(DOF)
        self._run = {c: [] for c in GATED}   # innovations of the current run of rejections
        self._hist: dict[tuple, list] = {}    # (sensor, beacon) -> its last GATE_HISTORY innovations
        self._jump: dict[tuple, tuple] = {}   # (sensor, beacon) -> (t, innovation before) of a jump held out
        self._last_t: dict[tuple, float] = {}  # (sensor, beacon) -> time of its previous measurement
        self.held_t: dict[str, list] = {}     # sensor -> times of the measurements held out as a jump
        self._rearm: set[tuple] = set()       # sensors whose hold expired: no new jump until one is accepted
        self.recoveries: list[str] = []
        self.departures: list[str] = []       # (Estimate.departures: not recoveries)
        self._prev: dict[tuple, list] = {}    # (sensor, beacon) -> its last two measurements (_gated)
        self.last_departure = -np.inf         # time [s] the rate states were last widened (_departure)
        self.pauses, self.pause_travel = [], []
        self.still_watch = StillWatch(r)      # (step: the slips held at zero while the robot stands still)
        obs = self.init.observability
        self._pinned = bool(obs.unobservable)
        self._held = held_pins(obs)   # (held_directions)
        # The schedule's window, less where the fixes say the wheels slipped (slipcheck).
        # (the schedule's own stretches are the pipeline's, which says why: analysis.windowfit)
        self.slipping = in_window(sch.slip_stretches(self.init.slipping), m.t_start, self.t_switch)[0]
        self.window_warnings = in_window(self.init.slipping, m.t_start, self.t_switch)[1]
        # A start with no heading (standing still, no [initial]): fixes must not
        # make one up (estimators.heading). Until the motion shows it, they
        # are taken with the heading considered and the position floored.
        self._anchor = self.init.anchor       # (_take_anchor)
        self._anchor_until = (-1, -np.inf)  # (sensor, last time) the anchor shares
        self.anchored = None
        self.heading_watch = None
        self.heading_considered = 0          # fixes taken with the heading considered
        self.heading_known_at = None
        if self.init.heading_unknown:
            gps_first = m.gps is not None
            self.heading_watch = HeadingWatch(r.track_width, r.gps_lever_arm if gps_first else r.range_lever_arm,
                                              float(np.median(m.gps[2])) if gps_first else r.range_sigma,
                                              fixes=gps_first, record=False)
            self._t_wheel = None

    def row(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The output row at the current time: state (11,), variances (11,)
        and pose covariance (3, 3). Rows carry honest covariance: what pinned
        (unobservable) scale combinations leave uncertain (observability.decondition)."""
        obs = self.init.observability
        Pr = self.P if not self._pinned else decondition(self.P, obs, S.SCALE, obs.prior_sigma)
        return self.x.copy(), np.diagonal(Pr).copy(), Pr[0:3, 0:3].copy()

    def step(self, t: float, code: int, z, *aux, in_slip: bool = False) -> float:
        """Predict to t [s] and process one measurement of sensor ``code``
        (sensors.WHEEL ...): wheels (speeds (2,) [m/s], their sigma (2,),
        and the encoder row's interval [s], 0 for wheel_speeds.csv), gyro
        (rate (1,) [rad/s]), GPS (antenna x, y (2,) [m], sigma [m]), range
        ((1,) [m], beacon x, y (2,) [m], beacon id) or velocity ((v, omega)
        (2,)). ``in_slip``: t lies where the wheels slipped inside the
        calibration window (no zero-slip pseudo-update). Where the robot
        stands still (standstill.StillWatch, fed here) the slips are held at
        zero as in the window. Returns the NIS,
        negative when the gate rejected it."""
        sch, opt = self.schedule, self.options
        # an encoder row whose ticks span more than a pause's length
        long_row = code == WHEEL and len(aux) > 1 and aux[1] > PAUSE_S
        if long_row and self.t <= t - 0.5 * aux[1] + min(0.5, 0.05 * aux[1]):
            # An encoder row over a long interval with nothing else since it
            # began, stamped at its midpoint: a pause, as pause_spans would
            # have found had the log been known (a stream's is not).
            self.pause_spans = sorted({*self.pause_spans, (t - 0.5 * aux[1], t + 0.5 * aux[1])})
        if code == WHEEL:
            in_still = self.still_watch.wheel(t, z, aux[1] if len(aux) > 1 else 0.0)
        else:
            self.still_watch.other(code, t, z, aux)
        if self._anchor is not None and t >= self._anchor.t:
            self._take_anchor()
        self.predict(t)
        if self.switch_sigma is None and self.t_switch is not None and t >= self.t_switch:
            # The schedule switches: from here on every update holds the scale factors.
            self.switch_sigma = self.P[SCALE_IDX, SCALE_IDX].copy()
            self.holding_scale = sch.hold is Hold.consider
        x = self.x
        gates, hist, jump = self._gates, self._hist, self._jump
        hw = self.heading_watch
        if hw is not None:
            if code == WHEEL:
                hw.wheel(t, z[0], z[1], t - self._t_wheel if self._t_wheel is not None else 0.0)
                self._t_wheel = t
            elif code == GPS:
                hw.fix(t, z)
            if hw.known:
                self.heading_known_at = hw.t_known
                self.heading_decided = hw          # what it waited for (heading.warning)
                self.heading_watch = hw = None
        if long_row and self.pauses \
                and min(t + 0.5 * aux[1], self.pauses[-1][1]) - max(t - 0.5 * aux[1], self.pauses[-1][0]) > 0:
            # An encoder row spanning a pause: its ticks are the travel across
            # it, not a speed at its midpoint (see _pause).
            self._pause_odometry(z, aux[1])
            self.n_up += 1
            return float(DOF[WHEEL])      # no innovation: the NIS its expected value
        if code == WHEEL:
            window = ((self.switch_sigma is None and self.t_switch is not None and not in_slip)
                      or not self.init.observability.slip_observable)
            if window or in_still:
                h, H = pseudo.zero_slip(x[6], x[7])                              # eq. 35-36
                self.update(np.zeros(2), h, H, SLIP_IDX, self._R_slip)
            if not window and self.switch_sigma is not None and sch.hold is Hold.pseudo:
                h, H = pseudo.hold_scale(x[8], x[9], x[10])                      # eq. 37-38
                self.update(h.copy(), h, H, SCALE_IDX, self._R_scale)
            x = self.x  # the pseudo-update has moved the state
            h, H = encoder.wheel_speeds(x[3], x[4], x[6], x[7], x[8], x[9], x[10], self.robot.track_width)  # eq. 29-34
            s = aux[0]
            nis_k = self.update(z, h, H, ENC_IDX, np.diag(s * s),
                                no_gain=None if opt.encoder_scale_gain else held_directions(x, *self._held))
            self._check()
        elif code == GYRO:
            h, H = gyro.yaw_rate(x[4], x[5])                                      # eq. 10-11
            nis_k = self.update(z, h, H, GYRO_IDX, self._R[GYRO])
        elif code == GPS:
            h, H = gps.antenna_position(x[0], x[1], x[2], self.robot.gps_lever_arm)   # eq. 8-9
            sg = aux[0]
            key = (GPS, 0)
            R_k = np.eye(2) * (sg * sg * self._anchor_inflation(GPS, t))
            # a sensor held out after a jump gets no rescue from its recent innovations (the jump's)
            ref = None if key in jump else gate_reference(hist.setdefault(key, []))
            nis_k = self._pose_update(z, h, H, R_k, gates[GPS], ref, self.robot.gps_lever_arm, hw)
        elif code == RANGE:
            h, H = ranging.beacon_range(x[0], x[1], x[2], aux[0], self.robot.range_lever_arm)   # eq. 12-16
            key = (RANGE, aux[1])
            R_k = self._R[RANGE] * self._anchor_inflation(RANGE, t)
            ref = None if key in jump else gate_reference(hist.setdefault(key, []))
            nis_k = self._pose_update(z, h, H[:, :3], R_k, gates[RANGE], ref, self.robot.range_lever_arm, hw,
                                      huber=True)
        else:
            h, H = velocity.body_velocity(x[3], x[4])                             # sec. VI-B
            key = (VEL, 0)
            R_k = self._R[VEL]
            nis_k = self.update(z, h, H, VEL_IDX, R_k, gates[VEL], gate_reference(hist.setdefault(key, [])))
        self.n_up += 1
        if code in self._run:
            self._gated(t, code, key, nis_k, R_k)
        if nis_k >= 0:          # (a rejected or held-out measurement says nothing of divergence)
            self._watch(t, code, nis_k)
        return nis_k

    def _take_anchor(self) -> None:
        """At the first measurement of a start fitted to late fixes
        (initial.Anchor): the pose becomes the fit's pose there, with the
        anchor's covariance and no correlation with the other states, when
        that is tighter than the pose carried back to the start and forward
        again (both come from the same fixes, so the prediction adds nothing
        to it). The fixes' updates are then linearised where the robot is;
        the fit's fixes are taken at the information the anchor left them
        (_anchor_inflation)."""
        a = self._anchor
        self._anchor = None
        self.predict(a.t)
        before = np.sqrt(np.diagonal(self.P)[0:3])
        if before[2] ** 2 <= a.cov[2, 2] and np.trace(self.P[0:2, 0:2]) <= np.trace(a.cov[0:2, 0:2]):
            return
        self.x[POSE_IDX] = a.pose
        self.P[POSE_IDX, :] = 0.0
        self.P[:, POSE_IDX] = 0.0
        self.P[POSE_IDX, POSE_IDX] = a.cov
        self._anchor_until = (GPS if a.sensor == "gps" else RANGE, a.until)
        after = np.sqrt(np.diagonal(a.cov))
        self.anchored = (f"the start was carried back {a.t - self.init.t:.1f} s along the wheels from the first "
                         f"{'GPS fix' if a.sensor == 'gps' else 'range'}; there (t={a.t:.2f} s) the filter took the "
                         f"start fit's pose (position sigma {max(before[:2]):.2g} -> {max(after[:2]):.2g} m, heading "
                         f"{np.degrees(before[2]):.0f} -> {np.degrees(after[2]):.1f} deg), sharing the information of "
                         f"the {a.n} fixes it was fitted to (up to t={a.until:.2f} s) with them")

    def _anchor_inflation(self, code: int, t: float) -> float:
        """Variance factor of a measurement the anchor shares (initial.Anchor): 1 / (1 - ANCHOR_SHARE)."""
        c, until = self._anchor_until
        return 1.0 / (1.0 - ANCHOR_SHARE) if code == c and t <= until else 1.0

    def _pose_update(self, z, h, H, R, gate, ref, lever, watch, huber: bool = False) -> float:
        """A fix's or range's update (eq. 8-9, 12-16). While ``watch`` says
        the heading is not known yet, the heading is considered, not
        estimated (its gain row zero), and the position covariance is kept at
        least the circle's the centre lies on (heading.circle_variance of
        watch.arm(): the lever-arm circle standing still): relinearised
        at a heading that wanders with the noise, the fixes would otherwise
        build up heading information that a robot standing still never gives."""
        if watch is None:
            return self.update(z, h, H, POSE_IDX, R, gate, ref, huber=huber)
        # No heading column either: the fix then speaks of the position only,
        # at the antenna less the lever arm turned by the heading held; the
        # floor below keeps the circle that heading could be anywhere on.
        H = H.copy()
        H[:, 2] = 0.0
        self.consider_heading = True
        self.heading_considered += 1
        try:
            nis = self.update(z, h, H, POSE_IDX, R, gate, ref, huber=huber)
        finally:
            self.consider_heading = False
        if nis >= 0:
            # at least this sensor's own lever-arm circle (the watch's is the GPS's in a log with both)
            floor = float(circle_variance(max(watch.arm(), float(np.hypot(*lever)))))
            w, V = np.linalg.eigh(self.P[0:2, 0:2])
            if w.min() < floor:
                self.P[0:2, 0:2] += (V * np.maximum(floor - w, 0.0)) @ V.T    # adds PSD: stays a covariance
        return nis

    def _gated(self, t: float, code: int, key: tuple, nis_k: float, R_k: np.ndarray) -> None:
        """After a gated sensor's update: hold a jump out, end a hold that
        lasted too long, and re-acquire after a run of rejections."""
        opt, jump, rearm, run = self.options, self._jump, self._rearm, self._run
        h_k = self._hist[key]
        y_now = np.atleast_1d(self.last_y).copy()
        t_prev, self._last_t[key] = self._last_t.get(key), t
        if (nis_k < 0 and code != VEL and key not in jump and key not in rearm and h_k
                and jumped(y_now, h_k[-1], R_k, t - t_prev, opt.jump_speed, self._gates[code])):
            jump[key] = (t, h_k[-1].copy())
        last = self._prev.setdefault(key, [])          # its last two: (t, innovation, |NIS|)
        if code != VEL and len(last) == 2 and key not in jump and t > last[1][0] > last[0][0]:
            self._departure(t, code, y_now, abs(nis_k), last, R_k)
        last.append((t, y_now, abs(nis_k)))
        if len(last) > 2:
            del last[0]
        held = key in jump
        if held and nis_k < 0 and t - jump[key][0] > opt.jump_hold:
            # Held out long enough: the jump is the sensor's new level (a
            # datum that moved). Its history becomes that level, no new
            # jump is taken until one is accepted, and the usual
            # re-acquisition below takes over.
            self.recoveries.append(f"t={t:.2f} s: {SENSOR_NAMES[code]} jumped at t={jump[key][0]:.2f} s "
                                   f"and did not come back in {opt.jump_hold:g} s; re-acquiring it")
            del jump[key]
            held = False
            h_k[:] = [y_now.copy() for _ in h_k]
            rearm.add(key)
        h_k.append(jump[key][1].copy() if held and nis_k < 0 else y_now)
        if len(h_k) > GATE_HISTORY:
            del h_k[0]
        if held and nis_k < 0:
            # Held out after a jump: no re-acquisition, until it comes back or the hold ends.
            self.held_t.setdefault(SENSOR_NAMES[code], []).append(t)
            return
        if held:
            del jump[key]        # back where the state expects it: the jump is over
        if nis_k >= 0:
            rearm.discard(key)
            run[code].clear()
            return
        # The gate never locks the filter out: a run of rejections widens
        # what the sensor sees, and the next measurement re-acquires it.
        run[code].append(y_now.copy())
        if len(run[code]) >= opt.reacquire_after:
            blk, add = reacquire_widening(code, np.asarray(run[code]))
            self.P[blk, blk] += np.diag(add)
            self.recoveries.append(f"t={t:.2f} s: {len(run[code])} {SENSOR_NAMES[code]} measurements in a row "
                                   "rejected; covariance widened to re-acquire")
            run[code].clear()

    def _departure(self, t: float, code: int, y: np.ndarray, nis: float, last: list, R: np.ndarray) -> None:
        """Floor the rate states' variances where a GPS fix or a beacon's
        range says the state is leaving what it sees (``departed``,
        ``departure_widening``); ``last``: the same sensor's two measurements
        before, (t, innovation, |NIS|) each."""
        (t0, y0, _), (t1, y1, nis1) = last
        gate = self._gates[code]
        if (gate is None or not departure_possible(nis, nis1, gate, DOF[code])     # (the common case, at once)
                or not departed((y0, y1, y), nis, nis1, gate, DOF[code], (t1 - t0, t - t1), R,
                                self.options.jump_speed)):
            return
        idx, floor = departure_widening(y, y1, t - t1, self.options.slip_states)
        self.P[idx, idx] += np.maximum(floor - np.diagonal(self.P)[idx], 0.0)
        note = departure_note(t, code, float(floor), self.last_departure, self.options.slip_states)
        if note:
            self.departures.append(note)
        self.last_departure = t

    def _watch(self, t: float, code: int, nis_k: float) -> None:
        """Divergence watch: a running mean of each sensor's accepted NIS. One
        gross outlier is clipped so it cannot trip it; a sustained mismatch does."""
        opt = self.options
        ema = self._nis_ema[code] = 0.98 * self._nis_ema[code] + 0.02 * min(nis_k, self._nis_clip[code])
        self._n_seen[code] += 1
        if self._n_seen[code] > 100 and ema > opt.max_mean_nis * DOF[code]:
            what = (f"the running mean NIS of {SENSOR_NAMES[code]} is {ema:.0f} (expected {DOF[code]})")
            widen = watch_widening(code, np.atleast_1d(self.last_y))
            if widen is None or len(self.recoveries) >= MAX_RECOVERIES:
                raise EstimatorDivergedError(f"EKF diverged at t={t:.3f} s: {what}; the model no longer "
                                             "explains the data")
            # Recover instead of stopping: open up the states that explain
            # this sensor's mismatch (a stall's slip, a bias jump) and go on.
            blk, add = widen
            self.P[blk, blk] += np.diag(add)
            self._nis_ema[code], self._n_seen[code] = float(DOF[code]), 0
            self.recoveries.append(f"t={t:.2f} s: {what}; its states' covariance widened")

    def finish(self, t, x, var, pose_cov, nis: dict, wall: float) -> Estimate:
        """The run's Estimate from its rows (t (N,), states (N, 11), variances
        (N, 11), pose covariances (N, 3, 3)) and NIS lists (see make_estimate)."""
        opt, m, sch = self.options, self.meas, self.schedule
        est = make_estimate("ekf" if opt.slip_states else "ekf-no-slip", t, x, var, pose_cov, nis,
                            list(m.notes) + [self.init.note], wall, self.n_up, self.t_switch, self.switch_sigma,
                            sch.hold, self.P[SCALE_IDX, SCALE_IDX].copy(), self.init)
        est.recoveries = list(self.recoveries)
        est.departures = list(self.departures)
        est.held_out = {k: np.asarray(v) for k, v in self.held_t.items()}
        est.warnings += self.window_warnings + self.heading_warnings()
        est.notes += self.pause_notes() + ([self.anchored] if self.anchored else [])
        for k, v in m.spikes.items():
            est.rejected[k] = est.rejected.get(k, 0) + v
        return est


    def pause_notes(self) -> list[str]:
        """One line per pause crossed (see _pause)."""
        out = []
        for a, b in self.pauses:
            moved = [f"{d:.2f} m, {np.degrees(w):.0f} deg" for tt, d, w in self.pause_travel if a <= tt <= b]
            out.append(f"the log pauses from t={a:.3f} to {b:.3f} s (no sensor for {b - a:.4g} s): the filter held "
                       "the pose, started v, omega and the slips afresh after it"
                       + (f", and carried the pose by the wheels' travel across it ({'; '.join(moved)})"
                          if moved else ""))
        return out

    def heading_warnings(self) -> list[str]:
        """The warning of a start whose heading the motion had not shown yet, if fixes were taken so."""
        if not self.heading_considered:
            return []
        from odomgraph.estimators.heading import warning
        return [warning(self.heading_known_at if self.heading_known_at is not None else float("inf"),
                        getattr(self, "heading_decided", None) or self.heading_watch)]


def event_values(meas, code: int, i: int) -> tuple:
    """Row i of sensor ``code`` of ``meas`` (measurements.Measurements) as
    ``EKF.step`` takes it."""
    if code == WHEEL:       # speeds, sigmas, the encoder row's interval [s] (0 for wheel_speeds.csv)
        return meas.wheel.m[i], meas.wheel.sigma[i], float(meas.wheel.dt[i]) if meas.wheel.dt is not None else 0.0
    if code == GYRO:
        return (meas.gyro[1][i:i + 1],)
    if code == GPS:
        return meas.gps[1][i], meas.gps[2][i]
    if code == RANGE:
        return meas.ranges[2][i:i + 1], meas.ranges[1][i], meas.ranges_id[i]
    return (meas.velocity[1][i],)


def make_estimate(method: str, t, mean, var, pose_cov, nis: dict, notes: list, wall: float, n_up: int,
                  t_switch, switch_cov, hold: Hold, final_cov, init: InitialState) -> Estimate:
    """The Estimate of one EKF run from its recorded rows.

    nis: sensor code -> list of (t, NIS), a negative NIS marking a gated
    measurement; switch_cov: (3, 3) scale covariance at the schedule's switch
    (None if it never switched); final_cov: (3, 3) at the end.
    """
    sigma = np.sqrt(np.maximum(var, 0.0))
    innov, rejected = {}, {}
    for code, lst in nis.items():
        if lst:
            arr = np.asarray(lst)
            acc = arr[:, 1] >= 0
            if (~acc).any():
                rejected[SENSOR_NAMES[code]] = int((~acc).sum())
            innov[SENSOR_NAMES[code]] = Innovations(arr[acc, 0], arr[acc, 1], DOF[code])
    given = final_cov
    if hold is Hold.pseudo and switch_cov is not None:
        given = switch_cov  # the pseudo-update's sigma is not an uncertainty
    given = 0.5 * (given + given.T)
    obs = init.observability
    cal_cov = decondition(given, obs, [0, 1, 2], obs.prior_sigma) if obs.unobservable else given
    return Estimate(method=method, t=t, mean=mean, sigma=sigma, pose_cov=pose_cov, innovations=innov,
                    wall_time_s=wall, n_updates=n_up, t_switch=t_switch,
                    calibration_sigma=np.sqrt(np.maximum(np.diagonal(cal_cov), 0.0)), calibration_cov=cal_cov,
                    calibration_cov_given=given, observability=obs, warnings=list(init.warnings), notes=notes,
                    rejected=rejected, used={SENSOR_NAMES[c]: len(v) for c, v in nis.items() if v})


def run_ekf(log: Log, schedule: Schedule = Schedule(), options: EKFOptions = EKFOptions(), progress=None) -> Estimate:
    """Run the paper's EKF over ``log``; see ``EKF``."""
    return EKF(log, schedule, options).run(progress)
