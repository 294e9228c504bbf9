"""Does a beacon read constantly long or short? Per-beacon range offsets from the residuals.

UWB anchors carry antenna delays and NLOS offsets of 0.05-0.3 m that stay
put for the whole log. Widening the range sigma for persistence
(analysis.noise.correlation_factors) covers offsets the size of the
scatter, but a mean of N biased ranges keeps the whole bias: simulated
beacons reading 0.2-0.3 m off (sigma 0.05 m) held under half of the
positions inside 3 sigma after a 13x widening (tests/test_noise_model.py).
Bias states (BatchGraphOptions.range_bias, batch) find them within 1 cm.

Here each beacon's post-fit residuals are tested for a non-zero mean: the
mean of those within OUTLIER robust sigmas, against its own sigma with the
residuals' lag-1 correlation counted (n_eff = n (1 - rho) / (1 + rho)). The
fit pulls the trajectory towards a compromise, so a post-fit mean is
smaller than the offset and spreads over the other beacons: the test errs
small. Measured z: below 1 for white ranges (6 runs), 22-33 for 0.2-0.3 m
offsets, 5-9 on the libRSF cut's 0.07-0.15 m.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph.factors._math import robust_sigma

#: A beacon's mean residual is an offset beyond this many of its sigmas...
OFFSET_Z = 5.0
#: ...and this share of the configured range sigma (a fast anchor makes a millimetre significant).
OFFSET_MIN_SIGMA = 0.25
#: Residuals beyond this many robust sigmas of the beacon's median are outliers, not offset.
OUTLIER = 4.0
#: Fewest residuals a beacon is tested with, and fewest beacons bias states are estimated for
#: (with fewer, a bias and the position trade off).
MIN_COUNT = 20
MIN_BEACONS = 3


@dataclass(frozen=True)
class Offset:
    beacon: str
    mean: float
    """Mean post-fit residual [m] (measured minus predicted: positive reads long)."""
    sigma: float
    """Its 1-sigma [m], correlation counted."""
    n: int

    @property
    def z(self) -> float:
        return self.mean / max(self.sigma, 1e-12)


def range_offsets(est, log) -> list[Offset]:
    """Each beacon's mean post-fit residual against ``est``, with its sigma
    (module docstring); [] without ranges. Residuals of an estimate with
    range biases are taken with them (analysis.metrics.range_residuals)."""
    from odomgraph.analysis.metrics import range_residuals
    res = range_residuals(est, log)
    if res is None or not res[0].size:
        return []
    r = log.ranges
    beacon = r.beacon[(r.t >= est.t[0]) & (r.t <= est.t[-1])]
    out = []
    for b in np.unique(beacon):
        x = res[1][beacon == b]
        x = x[np.isfinite(x)]
        if x.size < MIN_COUNT:
            continue
        med = float(np.median(x))
        s = robust_sigma(x - med)
        x = x[np.abs(x - med) <= OUTLIER * max(s, 1e-12)]
        if x.size < MIN_COUNT:
            continue
        m = float(x.mean())
        c = x - m
        den = float(np.sum(c * c))
        rho = float(np.sum(c[1:] * c[:-1]) / den) if den > 0 else 0.0
        rho = min(max(rho, 0.0), 0.95)
        n_eff = x.size * (1.0 - rho) / (1.0 + rho)
        out.append(Offset(log.robot.beacons[int(b)].id, m, float(np.std(x)) / np.sqrt(n_eff), int(x.size)))
    return out


def significant(offsets: list[Offset], range_sigma: float) -> list[Offset]:
    """The offsets beyond OFFSET_Z sigmas and OFFSET_MIN_SIGMA of ``range_sigma`` [m]."""
    return [o for o in offsets if abs(o.z) > OFFSET_Z and abs(o.mean) > OFFSET_MIN_SIGMA * range_sigma]


def offsets_text(found: list[Offset]) -> str:
    return ", ".join(f"{o.beacon} {o.mean:+.3f} m ({abs(o.z):.0f} sigma)" for o in found)
