"""The pseudo-update schedule of the paper (sec. III-D and IV).

Before ``calibrate_until`` seconds (from the log's first sample, or the
wheels' first row when the other sensors ran well before them:
io.log.Log.t_schedule) the slips are
forced to zero and the scale factors are estimated; after it the scale factors
are held and the slips are estimated. ``calibrate_until = 0`` is slip-only.
``None`` applies neither (only the smoother offers that; see LOG_FORMAT).
"""
from __future__ import annotations

from dataclasses import dataclass
from enum import Enum


class Hold(str, Enum):
    """How the EKF holds the scale factors after calibration."""

    consider = "consider"
    """Zero Kalman gain on the scale states (a Schmidt "consider" update): they
    stay constant and their uncertainty keeps feeding the other states. The
    reported sigma stays honest. Default."""
    pseudo = "pseudo"
    """The paper's literal pseudo-measurement (eq. 37-38) at every encoder
    update. It drives the scale covariance to ~0 and makes the slips
    overconfident; the reported scale sigma is the one at the switch."""


@dataclass(frozen=True)
class Schedule:
    calibrate_until: float | None = 20.0
    """Seconds after the schedule's origin (Log.t_schedule); 0 = slip only; None = no schedule."""
    hold: Hold = Hold.consider
    slipping: tuple[tuple[float, float], ...] = ()
    """(start, end) [s, the log's clock] stretches of the calibration window
    not taken as slip-free, besides those the estimators find before they
    start (estimators.slipcheck): where a first estimate's fixes said the
    wheels slipped (analysis.windowfit)."""

    def __post_init__(self):
        import math
        from odomgraph.errors import OptionError
        c = self.calibrate_until
        if c is not None and (isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c)
                              or c < 0):
            from odomgraph.checks import value_text
            raise OptionError(f"calibrate_until (--calibrate-until) must be seconds >= 0 or None, got {value_text(c)}")
        object.__setattr__(self, "hold", Hold(self.hold))

    def slip_stretches(self, found) -> list[tuple[float, float]]:
        """``found`` (the estimators' own slipcheck stretches) and ``slipping``, merged."""
        from odomgraph.estimators.slipcheck import merged
        return merged(list(found) + [tuple(s) for s in self.slipping])

    def switch_time(self, t_start: float) -> float | None:
        """When calibration ends [s, the log's clock] for a log starting at
        ``t_start``; None without a schedule. Every estimator uses this one."""
        return None if self.calibrate_until is None else t_start + self.calibrate_until

    def calibrating(self, t_rel: float) -> bool:
        return self.calibrate_until is not None and t_rel < self.calibrate_until
