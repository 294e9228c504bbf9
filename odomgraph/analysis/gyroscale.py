"""The gyro's scale factor, profiled: what the fixes say of it, and what it
does to the track width.

The model reads the gyro as omega + bias (paper eq. 10): no scale. A gyro
that reads 2 % high turns every heading change 2 % too far, and the
estimators make the wheels agree by shrinking the track width: on the
yard and paper scenarios a 2 % gyro gave a track 1.2-1.4 % off at a sigma
of 0.2 % (z -6 to -8, status ok), and ``calibrate`` wrote it.

The fixes do see it (their heading changes are the truth's), so the scale
is estimated by its profile likelihood: batch is run with the gyro divided
by g for a few g, and its final cost (half the whitened sum of squares:
minus the log-likelihood up to a constant, with the noise model the run
fitted) is fitted by a parabola, cost(g) = c0 + (g - g_hat)^2 / (2 sigma^2).
On those scenarios (3 seeds each, g 0.97-1.02) g_hat came within 2 sigma
of the truth at sigma 0.2 %. ``calibrate`` then runs on the rescaled gyro
and widens each scale factor's sigma by its sensitivity to g times sigma_g
(a Schmidt "consider" term: the scale factors are not re-estimated jointly
with g). A log that does not determine g (no fixes, or no turns) is given
PRIOR as sigma_g: its track width is only as good as the gyro's scale.
"""
from __future__ import annotations

import numpy as np

#: The profile's step [-]: g = 1 - STEP, 1, 1 + STEP (then g_hat).
STEP = 0.01
#: The gyro scale's sigma when the log does not determine it [-]: a MEMS
#: gyro's scale factor error is typically under 1 %.
PRIOR = 0.01
#: A g_hat further than this from 1 is no scale error (a unit or mounting
#: mistake: analysis.mounting): not determined, not corrected.
MAX_OFF = 0.1
#: Corrected when g_hat is this many sigma from 1, and at least MIN_OFF.
N_SIGMA = 3.0
MIN_OFF = 0.002


def fit_profile(g: np.ndarray, cost: np.ndarray) -> tuple[float, float] | None:
    """(g_hat, sigma_g) of the parabola through the costs (K,) at gyro
    scales g (K,), K >= 3, by least squares; None when it opens downwards or
    its sigma exceeds PRIOR (the log does not determine the scale)."""
    g, cost = np.asarray(g, float), np.asarray(cost, float)
    a, b, _ = np.polyfit(g - 1.0, cost, 2)
    if not a > 0:
        return None
    sigma = float(1.0 / np.sqrt(2.0 * a))
    if sigma > PRIOR:
        return None
    return float(1.0 - b / (2.0 * a)), sigma


def rescaled(log, g: float):
    """The log with its gyro's readings divided by g (a gyro reading g times the truth)."""
    from dataclasses import replace
    return log.with_(gyro=replace(log.gyro, omega=log.gyro.omega / g))


def significant(g_hat: float, sigma: float) -> bool:
    """Whether g_hat is off 1 by more than N_SIGMA sigma and MIN_OFF."""
    return abs(g_hat - 1.0) > max(N_SIGMA * sigma, MIN_OFF)


def warning(g_hat: float, sigma: float) -> str:
    """The line saying the gyro's scale is off, and what calibrate did."""
    return (f"the gyro reads {g_hat - 1.0:+.1%} (+- {sigma:.1%}) against the turns the fixes show (its scale "
            "factor; the model has none): calibrate divided its readings by that for the fit and widened the "
            "scale factors' sigmas by it; fix the gyro's scale (the driver's units or its calibration), or "
            "every estimate puts it into the track width")


def unknown_note(sigma: float) -> str:
    """The line for a log that does not determine the gyro's scale."""
    return (f"this log does not determine the gyro's scale factor (no fixes, or too few turns): the scale "
            f"factors' sigmas include a gyro scale error of {sigma:.0%} (analysis.gyroscale.PRIOR)")
