"""What every estimator returns, and what ``io.estimate`` writes."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from odomgraph import state


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
    """(3,) honest 1-sigma of the final scale factors (see Schedule.Hold)."""
    notes: list[str] = field(default_factory=list)
    online: "Estimate | None" = None
    """For incremental smoothers: the causal estimate as it stood at each time."""
    update_times: np.ndarray | None = None
    """Wall time of each incremental update [s] (incremental smoothers)."""
    range_bias: dict[str, dict[str, float]] | None = None
    """Estimated constant range bias per beacon id, {"value", "sigma"} [m] (batch --range-bias)."""

    def __post_init__(self):
        n = len(self.t)
        assert self.mean.shape == (n, state.N) and self.sigma.shape == (n, state.N)

    @property
    def calibration(self) -> dict[str, dict[str, float]]:
        """Final scale factors with their 1-sigma."""
        sig = self.calibration_sigma if self.calibration_sigma is not None else self.sigma[-1, state.SCALE]
        return {name: {"value": float(self.mean[-1, i]), "sigma": float(s)}
                for name, i, s in zip(("scale_left", "scale_right", "scale_track"), state.SCALE, sig)}
