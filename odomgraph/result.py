"""What every estimator returns, and what ``io.estimate`` writes."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from odomgraph import state
from odomgraph.observability import Observability


@dataclass
class Innovations:
    """Normalised innovation squared of one sensor's updates."""
    t: np.ndarray
    """(K,) update times [s]."""
    nis: np.ndarray
    """(K,) y^T S^-1 y."""
    dof: int
    """Measurement dimension (the chi-square degrees of freedom)."""


@dataclass
class Estimate:
    method: str
    t: np.ndarray
    """(N,) row times [s], the log's clock."""
    mean: np.ndarray
    """(N, 11) states in ``state.NAMES`` order; frames and units as LOG_FORMAT."""
    sigma: np.ndarray
    """(N, 11) 1-sigma marginals; 0 where a state is not estimated."""
    pose_cov: np.ndarray | None = None
    """(N, 3, 3) covariance of (x, y, theta) for NEES, when available."""
    innovations: dict[str, Innovations] = field(default_factory=dict)
    wall_time_s: float = 0.0
    n_updates: int = 0
    """Measurement updates processed (pseudo-updates excluded)."""
    t_switch: float | None = None
    """Absolute time the schedule switched from calibration to slip estimation."""
    calibration_sigma: np.ndarray | None = None
    """(3,) 1-sigma of the final scale factors (see Schedule.Hold)."""
    calibration_cov: np.ndarray | None = None
    """(3, 3) their covariance, honest: pinned combinations carry their prior
    uncertainty (observability.decondition); None: diag(calibration_sigma^2)."""
    calibration_cov_given: np.ndarray | None = None
    """(3, 3) the same conditional on the pinned combinations at nominal, as
    the estimator solved it (None: equal to calibration_cov)."""
    observability: "Observability | None" = None
    """What the log determines about the scale factors (estimators.observability)."""
    rejected: dict[str, int] = field(default_factory=dict)
    """Measurements rejected per sensor (the EKF's gate, a smoother's robust loss at weight ~0)."""
    downweighted: dict[str, int] = field(default_factory=dict)
    """Measurements a robust loss kept at reduced weight, per sensor."""
    used: dict[str, int] = field(default_factory=dict)
    """Measurements offered to the estimator, per sensor."""
    recoveries: list[str] = field(default_factory=list)
    """Each time the estimator caught itself diverging and recovered, with when and how."""
    departures: list[str] = field(default_factory=list)
    """Each time the EKF followed a step of the robot's (a stall, or its end:
    three innovations of one sensor in a row drifting away from the state) by
    widening its rate states, with when and how much (estimators.ekf.
    departure_note). Not a recovery: the filter did not lose itself, so these
    count towards neither "degraded" nor the EKF's MAX_RECOVERIES (a plow
    stuck in a drift six times is six stalls, not a lost filter), but they
    make a run "recovered"."""
    time_offsets: dict[str, dict[str, float]] = field(default_factory=dict)
    """Sensor time offsets estimated and applied, {"gps": {"value", "sigma"}} [s]."""
    noise_scales: dict[str, dict[str, float | str]] = field(default_factory=dict)
    """Per sensor (gps, ranges), the factor by which the data scatter beyond
    robot.toml's sigma ("measured"), the lag-1 correlation of its residuals
    ("correlation"), the factor the sigma was widened by ("applied") and
    what the scatter was measured from ("from": analysis.noise.measured_from);
    per velocity random walk ([process] accel, yaw_accel), the factor by which
    the wheels' own motion exceeds it ("measured") and the widening
    ("applied"). analysis.noise."""
    warnings: list[str] = field(default_factory=list)
    """One line each: what the user must know to trust the result (unobservable
    parameters, rejected measurements, a hit iteration cap, ...)."""
    flags: list[str] = field(default_factory=list)
    """Those warnings that say the result itself is suspect (a mounting
    mistake, a GPS clock off, scale factors far outside their prior): the
    status is "degraded" while any is there."""
    notes: list[str] = field(default_factory=list)
    online: "Estimate | None" = None
    """For incremental smoothers: the causal estimate as it stood at each time."""
    pauses: list[tuple[float, float, float, float]] = field(default_factory=list)
    """(start, end [s], distance [m], turn [rad]) of each silence of every sensor whose rows
    a smoother drew between the states either side and widened by the unknown
    path (estimators.gaps.pause_variance; resampled rows inside are widened
    alike)."""
    update_times: np.ndarray | None = None
    """Wall time of each incremental update [s] (incremental smoothers)."""
    range_bias: dict[str, dict[str, float]] | None = None
    """Estimated constant range bias per beacon id, {"value", "sigma"} [m] (batch --range-bias)."""
    held_out: dict[str, np.ndarray] = field(default_factory=dict)
    """Times [s] of the measurements held out, per sensor: as a sensor's
    jump (a GPS multipath burst: ekf.EKFOptions.jump_speed), or as fixes
    that pulled the rows sideways (analysis.sideways); counted in
    ``rejected`` too."""
    t_origin: int = 0
    """``t`` counts seconds from this integer second of the log's clock (Log.t_origin)."""
    cost: float | None = None
    """batch: the final cost, half the sum of the whitened squared residuals
    (robust losses and priors included); differences between runs on one
    log with one noise model are log-likelihood ratios (the gyro scale's
    profile, analysis.gyroscale)."""
    slip_check: "SlipPriorRows | None" = None
    """batch: the check of its sparse slip prior (estimators.priorcheck),
    not yet applied to these rows: the pipeline applies it to the answer it
    gives, once the checks of the fixes (noise, sideways, outrun) have run
    on the prior's rows (pipeline._with_slip_check)."""


    def __post_init__(self):
        n = len(self.t)
        assert self.mean.shape == (n, state.N) and self.sigma.shape == (n, state.N)

    @property
    def columns(self) -> tuple[str, ...]:
        """The names of ``named()``'s arrays: states.csv's columns (LOG_FORMAT.md)."""
        return ("t", *state.NAMES, *(f"sigma_{n}" for n in state.NAMES))

    def named(self) -> dict[str, np.ndarray]:
        """{column: (N,) array} in states.csv's order and units: ``t`` [s since
        t_origin], each state by name, and its 1-sigma as ``sigma_<name>``."""
        out = {"t": self.t}
        out.update({n: self.mean[:, i] for i, n in enumerate(state.NAMES)})
        out.update({f"sigma_{n}": self.sigma[:, i] for i, n in enumerate(state.NAMES)})
        return out

    def frame(self):
        """``named()`` as a pandas DataFrame (pandas is not a dependency: an
        OdomgraphError says so when it is not installed)."""
        try:
            import pandas as pd
        except ImportError:
            from odomgraph.errors import OdomgraphError
            raise OdomgraphError("Estimate.frame() needs pandas (pip install pandas); named() gives the same "
                                 "columns as a dict of arrays") from None
        return pd.DataFrame(self.named())

    def scale_cov(self, given: bool = False) -> np.ndarray:
        """(3, 3) covariance of the final scale factors: honest, or with
        ``given`` conditional on the pinned combinations (see the fields)."""
        if given and self.calibration_cov_given is not None:
            return np.asarray(self.calibration_cov_given)
        if self.calibration_cov is not None:
            return np.asarray(self.calibration_cov)
        sig = self.calibration_sigma if self.calibration_sigma is not None else self.sigma[-1, state.SCALE]
        return np.diag(np.square(sig))

    def unobservable(self) -> dict[str, str]:
        """Scale combinations the log does not determine, with the reason:
        those pinned by the structure and those the data barely inform
        (estimators.observability)."""
        from odomgraph.observability import weakly_determined
        obs = self.observability
        if obs is None:
            return {}
        out = dict(obs.unobservable)
        if obs.prior_sigma is not None:
            out.update(weakly_determined(obs, self.scale_cov(given=True), obs.prior_sigma))
        return out

    @property
    def calibration(self) -> dict[str, dict]:
        """Final scale factors: value, honest 1-sigma, and whether the log
        determines it (a scale factor touched by an unobservable combination
        is not)."""
        from odomgraph.observability import AFFECTS, WEAK_RATIO
        undetermined = {p for name in self.unobservable() for p in AFFECTS[name]}
        sig = np.sqrt(np.maximum(np.diagonal(self.scale_cov()), 0.0))
        prior = self.observability.prior_sigma if self.observability is not None else None
        # Observable: no undetermined combination touches it, and its honest
        # sigma is well inside the prior's (a free common scale leaves the
        # track as uncertain as the prior through their product).
        return {name: {"value": float(self.mean[-1, i]), "sigma": float(s),
                       "observable": bool(name not in undetermined and (prior is None or s <= WEAK_RATIO * prior))}
                for name, i, s in zip(("scale_left", "scale_right", "scale_track"), state.SCALE, sig)}


#: A sensor losing more than this share of its measurements to the gate or the
#: robust loss makes the run "degraded".
DEGRADED_REJECTED = 0.2


#: What the EKF's line of a departure says (estimators.ekf.departure_note).
DEPARTURE_SAYS = "three in a row drift away from the state"


def status_of(est: Estimate) -> tuple[str, list[str]]:
    """("ok" | "recovered" | "degraded", the reasons): recovered when the
    estimator caught itself diverging and recovered; degraded when a flag
    says the result is suspect (Estimate.flags), it hit an iteration cap,
    recovered many times, or lost more than DEGRADED_REJECTED of a sensor's
    measurements."""
    why = list(est.flags)
    for s, n in est.rejected.items():
        used = est.used.get(s)
        if used and n / used > DEGRADED_REJECTED:
            why.append(f"{s}: {n} of {used} measurements rejected")
    if any("iteration cap" in w for w in est.warnings):
        why.append("an iteration cap was hit")
    if len(est.recoveries) > 5:
        why.append(f"{len(est.recoveries)} recoveries")
    if why:
        return "degraded", why
    said = ([f"{len(est.recoveries)} recovery(ies)"] if est.recoveries else []) + \
           ([f"{len(est.departures)} departure(s) followed"] if est.departures else [])
    if said:
        return "recovered", said
    return "ok", []


@dataclass
class SlipPriorRows:
    """What batch's slip-prior check would make of an Estimate's rows:
    ``distance`` [sigma] between the prior's and the prior-free solutions
    (95th percentile near the fixes); ``prior_free``: the prior-free
    solution replaces the prior's; ``fields``: the Estimate fields it sets
    (mean, sigma, pose_cov, calibration_sigma, calibration_cov, range_bias),
    row for row; ``note``: one line for the notes."""
    distance: float
    prior_free: bool
    fields: dict
    note: str
