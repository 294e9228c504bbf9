"""Which scale factors a log can determine, and honest sigma for those it cannot.

The three scale factors (LOG_FORMAT: true = scale x nominal) are looked at as
three combinations, because that is how the data see them:

* ``scale_common``, the mean wheel scale (scale_left + scale_right)/2: fixed
  only by an absolute position or speed reference (GPS, ranges, a velocity
  sensor). Wheels and a gyro alone leave it free: every wheel speed and the
  travel scale together, and (scale_left, scale_right, scale_track) ->
  (scale_left/l, scale_right/l, l scale_track) explains the data equally well
  for any l (ESTIMATION-NOTES.md: a smoother moved it 25 % with a tight sigma);
* ``scale_ratio``, right against left: needs a yaw-rate or heading reference
  (a gyro, a velocity sensor's omega, or absolute fixes over some travel);
* ``scale_track``: needs that reference and rotation.

``structure`` decides from which sensors the log has and how far it moved and
turned. A combination it cannot determine is *pinned*: the estimators get a
tight prior on it at the nominal value (``prior_scale_cov``), so that no
random-walk prior can pass off its own preference as information, and the
report gives back their prior uncertainty, with its effect on every other
state (``decondition``). Combinations the structure allows but the data
barely inform (posterior sigma near the prior's) are flagged by
``weakly_determined``.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Combinations of (scale_left, scale_right, scale_track) as row vectors.
COMBINATIONS = {
    "scale_common": np.array([0.5, 0.5, 0.0]),
    "scale_ratio": np.array([-1.0, 1.0, 0.0]),
    "scale_track": np.array([0.0, 0.0, 1.0]),
}
#: Which scale factors each combination's absence leaves undetermined. A free
#: common scale takes the track with it: the data fix only track x common.
AFFECTS = {"scale_common": ("scale_left", "scale_right", "scale_track"),
           "scale_ratio": ("scale_left", "scale_right"), "scale_track": ("scale_track",)}
#: Prior sigma of a pinned combination in the estimators (a constraint, not information) [-].
#: 1e-4 outweighs the pseudo-information a random-walk prior can lend (about
#: 1/0.03^2, ESTIMATION-NOTES.md) by 1e5, and keeps C_ss well above rounding.
PIN_SIGMA = 1e-4
#: Least turning for the track to be observable [rad].
MIN_ROTATION = 0.5
#: Posterior/prior sigma ratio above which a combination counts as undetermined
#: by the data (the data then carry under a quarter of the prior's information):
#: it is reported unobservable, and pipeline.estimate holds it at nominal.
WEAK_RATIO = 0.9


@dataclass(frozen=True)
class Observability:
    """What a log can determine about the scale factors (see the module doc)."""
    unobservable: dict[str, str] = field(default_factory=dict)
    """Pinned combination -> reason, in words."""
    travel_m: float = 0.0
    """Distance the wheels report [m] (nominal parameters)."""
    rotation_rad: float = 0.0
    """Total turning the wheels report [rad]."""
    prior_sigma: float | None = None
    """Prior 1-sigma of each scale factor [-] (ProcessNoise.initial_scale_sigma)."""
    slip_observable: bool = True
    """False when nothing but the wheels sees the motion (no gyro, velocity
    sensor or absolute fixes): slip is then indistinguishable from motion, and
    the estimators take it as zero throughout (the paper's zero-slip
    pseudo-update over the whole log) instead of letting it soak up the path."""

    def pinned(self, name: str) -> bool:
        return name in self.unobservable


def _count(src) -> int:
    return 0 if src is None else len(src[0])


def structure(robot, meas) -> Observability:
    """Structural observability of the scale factors from a log's sensors and motion.

    meas: estimators.measurements.Measurements of the log.
    """
    w = meas.wheel
    if len(w.t) > 1:
        dt = np.diff(w.t, append=w.t[-1])
        dt = np.minimum(dt, 5.0 * np.median(np.diff(w.t)))      # a gap is not motion
    else:
        dt = np.zeros(len(w.t))
    v = 0.5 * (w.m[:, 0] + w.m[:, 1])
    om = (w.m[:, 1] - w.m[:, 0]) / robot.track_width
    # Distances from the net motion of each second, not from |speed|: tick
    # noise of a robot standing still would otherwise add up to metres.
    b = np.floor((w.t - w.t[0]) / 1.0).astype(int) if len(w.t) else np.zeros(0, int)
    net = lambda x: np.bincount(b, x * dt) if len(b) else np.zeros(1)
    # A turn in place with wheels a few percent apart shows a forward creep
    # that is no translation: only what exceeds that (at twice the prior
    # sigma) counts.
    half_diff = 0.5 * (w.m[:, 1] - w.m[:, 0])
    travel = float(np.sum(np.maximum(np.abs(net(v)) - 2.0 * robot.process.initial_scale_sigma
                                     * np.abs(net(half_diff)), 0.0)))
    rotation = float(np.sum(np.abs(net(om))))
    wheel_travel = float(np.sum(0.5 * (np.abs(net(w.m[:, 0])) + np.abs(net(w.m[:, 1])))))   # a pivot turns them
    n_gps, n_rng = _count(meas.gps), _count(meas.ranges)
    sig_abs = np.inf
    if n_gps >= 3:
        sig_abs = float(np.median(meas.gps[2]))
    elif n_rng >= 3:
        sig_abs = robot.range_sigma
    # Fixes pin the travel scale only if the robot moved well beyond their noise.
    absolute = np.isfinite(sig_abs) and travel > max(0.1, 5.0 * sig_abs)
    velocity = _count(meas.velocity) >= 3
    yaw_ref = _count(meas.gyro) >= 3 or velocity or absolute
    out = {}
    if not (absolute or velocity):
        if np.isfinite(sig_abs):
            out["scale_common"] = (f"the robot moved {travel:.2g} m, too little against its fixes' noise "
                                   f"({sig_abs:.2g} m) to fix the wheel scale")
        else:
            out["scale_common"] = "no absolute position or speed reference (GPS, ranges or a velocity sensor)"
    if wheel_travel < 0.1:
        out["scale_ratio"] = f"the wheels report {wheel_travel:.2g} m of travel: nothing to compare them on"
    elif not yaw_ref:
        out["scale_ratio"] = "no yaw-rate or heading reference (gyro, velocity sensor or absolute fixes)"
    if not yaw_ref:
        out["scale_track"] = "no yaw-rate or heading reference (gyro, velocity sensor or absolute fixes)"
    elif rotation < MIN_ROTATION:
        out["scale_track"] = f"the robot turned only {rotation:.2g} rad in all: the track is not observable"
    return Observability(out, travel, rotation, robot.process.initial_scale_sigma,
                         slip_observable=bool(yaw_ref or velocity))


def pinned_basis(obs: Observability) -> np.ndarray:
    """(3, k) orthonormal basis of the pinned combinations (k = 0: none)."""
    names = list(obs.unobservable)
    if not names:
        return np.zeros((3, 0))
    q, _ = np.linalg.qr(np.stack([COMBINATIONS[n] for n in names], 1))
    return q


def held_pins(obs: Observability) -> tuple[np.ndarray, bool]:
    """(pinned_basis (3, k), whether the common scale is among the pins): what
    the filters' encoder update holds (estimators.ekf.held_directions)."""
    return pinned_basis(obs), "scale_common" in obs.unobservable


def prior_scale_cov(obs: Observability, sigma: float) -> np.ndarray:
    """(3, 3) prior covariance of the scale factors for the estimators: sigma^2
    in every direction, PIN_SIGMA^2 along the pinned combinations."""
    U = pinned_basis(obs)
    return sigma**2 * (np.eye(3) - U @ U.T) + PIN_SIGMA**2 * (U @ U.T)


def decondition(cov: np.ndarray, obs: Observability, scale_idx, sigma: float) -> np.ndarray:
    """Covariance to report, from one conditional on the pinned combinations.

    The estimators hold the pinned combinations s = U^T k at nominal (prior
    variance PIN_SIGMA^2), and the data do not inform them (that is why they
    are pinned). The joint posterior with their true prior variance sigma^2
    keeps p(x | s, data) and replaces p(s), so with B = C_xs C_ss^-1:

        C' = C + B (sigma^2 I - C_ss) B^T

    Every state correlated with s (the pose through the travel scale, the
    track through the product the gyro sees) gets the uncertainty the pinned
    combination leaves it. cov: (..., n, n); scale_idx: the 3 indices of
    (scale_left, scale_right, scale_track) in it. Returns a new array; cov
    itself when nothing is pinned.
    """
    U = pinned_basis(obs)
    if U.shape[1] == 0:
        return cov
    C = np.asarray(cov, float)
    Cxs = C[..., :, scale_idx] @ U                                # (..., n, k)
    Css = np.swapaxes(U, 0, 1) @ C[..., scale_idx, :][..., :, scale_idx] @ U   # (..., k, k)
    B = Cxs @ np.linalg.inv(Css)
    D = sigma**2 * np.eye(U.shape[1]) - Css
    out = C + B @ D @ np.swapaxes(B, -1, -2)
    return 0.5 * (out + np.swapaxes(out, -1, -2))


def weakly_determined(obs: Observability, cov: np.ndarray, sigma: float) -> dict[str, str]:
    """Combinations the structure allows but the data barely inform: posterior
    sigma above WEAK_RATIO of the prior's (cov: the estimator's (3, 3) scale
    covariance). {name: reason}."""
    out = {}
    for name, u in COMBINATIONS.items():
        if obs.pinned(name):
            continue
        prior = sigma * float(np.linalg.norm(u))
        post = float(np.sqrt(max(u @ cov @ u, 0.0)))
        if post > WEAK_RATIO * prior:
            out[name] = (f"the log barely informs it: its sigma {post:.2g} is {post / prior:.0%} of the prior's "
                         f"{prior:.2g}")
    return out


def combinations_of(mean: np.ndarray, cov: np.ndarray) -> dict[str, dict[str, float]]:
    """The combinations' values with their 1-sigma (first order), from the
    estimator's scale mean (3,) and covariance (3, 3). The ratio is
    scale_right / scale_left."""
    kl, kr, kt = (float(v) for v in mean)
    J = {"scale_common": np.array([0.5, 0.5, 0.0]), "scale_ratio": np.array([-kr / kl**2, 1.0 / kl, 0.0]),
         "scale_track": np.array([0.0, 0.0, 1.0])}
    val = {"scale_common": 0.5 * (kl + kr), "scale_ratio": kr / kl, "scale_track": kt}
    return {n: {"value": val[n], "sigma": float(np.sqrt(max(J[n] @ cov @ J[n], 0.0)))} for n in J}


#: The start's note and warning when ranges are the only absolute sensor and
#: never give a fix (estimators.initial; few_beacons_warnings flags the estimate).
UNPLACED_BY_RANGES = ("no [initial] pose in robot.toml and the first ranges never give a multilateration fix (three "
                      "beacons within 3 s, not in a line), so the start cannot be placed: it is taken as the origin, "
                      "heading 0")


def few_beacons_warnings(log, warnings: list[str] = ()) -> list[str]:
    """One line when ranges are the only absolute sensor, there is no
    [initial] pose, and they come from fewer than three beacons: the start
    pose cannot be multilaterated, and the ranges leave the path free (one
    beacon: turned about it; two: mirrored across their line). The start is
    then taken as the origin, which the ranges contradict: a probe's log
    with one beacon got 1 m RMS at 40 % coverage, unflagged. With three or
    more beacons that never give a fix together (``warnings``, the
    estimate's, hold UNPLACED_BY_RANGES) the same holds: a yard log
    13 m off at z 12000 was unflagged."""
    r = log.ranges
    if r is None or not len(r.t) or log.robot.initial is not None:
        return []
    if log.gps is not None and len(log.gps.t):
        return []
    n = int(np.unique(r.beacon).size)
    if n >= 3:
        if UNPLACED_BY_RANGES in warnings:
            return [f"ranges from {n} beacons but no multilateration fix from the first of them (three beacons "
                    "within 3 s, not in a line), and no GPS or [initial] pose: the start was taken as the origin, "
                    "which the ranges contradict; positions and heading are not trustworthy; give robot.toml an "
                    "[initial] pose"]
        return []
    how = "turned about it" if n == 1 else "mirrored across the line through them"
    return [f"ranges from only {n} beacon{'s' if n > 1 else ''} and no GPS or [initial] pose: the start cannot be "
            f"multilaterated, and the ranges fix the path only up to being {how}; positions and heading are not "
            "trustworthy; give robot.toml an [initial] pose"]
