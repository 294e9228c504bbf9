"""Seeded studies of an estimator on a scenario (the issue-level acceptance
numbers): run N seeds, score each against truth, aggregate.

Used by the tests (which assert the numbers) and by benchmarks/ (which print
and store them), so both report the same thing.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph.analysis.metrics import truth_errors


@dataclass(frozen=True)
class SeedResult:
    seed: int
    scale_rel_error: tuple[float, float, float]
    """|estimate / truth - 1| of (left, right, track) at the end [-]."""
    slip_sq_sum: tuple[float, float]
    """Sum of squared slip errors after the switch, per wheel [(m/s)^2]."""
    slip_n: int
    """Rows in that sum."""
    coverage: dict[str, float]
    updates: int
    wall_time_s: float
    rms_position: float = 0.0
    """RMS 2-D position error [m]."""
    online: "SeedResult | None" = None
    """The same scores for the causal (online) estimate, where there is one."""

    @property
    def slip_rms(self) -> tuple[float, float]:
        return tuple(float(np.sqrt(s / max(self.slip_n, 1))) for s in self.slip_sq_sum)


@dataclass(frozen=True)
class StudySummary:
    seeds: int
    scale_rel_error_max: tuple[float, float, float]
    slip_rms_pooled: tuple[float, float]
    """RMS over the rows of all seeds after the switch [m/s]."""
    slip_rms_worst_seed: tuple[float, float]
    coverage_min: dict[str, float]
    """Worst seed's fraction of rows inside +-3 sigma, per state."""
    updates_per_second: float
    scale_rel_error_rms: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """RMS over seeds of the final relative scale errors."""
    rms_position: float = 0.0
    """RMS over seeds of each seed's RMS position error [m]."""

def score_seed(est, log, seed) -> SeedResult:
    err = truth_errors(est, log)
    post = err.slip_mask
    sq = tuple(float(np.sum(err.error_series[f"slip_{w}"][post] ** 2)) for w in ("left", "right"))
    rel = tuple(abs(err.final_scale_error[k] / t) for k, t in zip(("left", "right", "track"), log.truth_scales))
    return SeedResult(seed, rel, sq, int(post.sum()), err.coverage_3sigma, est.n_updates, est.wall_time_s,
                      err.rms_position_m)


def summarize(results: list[SeedResult]) -> StudySummary:
    rel = np.array([r.scale_rel_error for r in results])
    sq = np.array([r.slip_sq_sum for r in results])
    n = sum(r.slip_n for r in results)
    states = results[0].coverage.keys()
    return StudySummary(
        seeds=len(results),
        scale_rel_error_max=tuple(rel.max(0)),
        slip_rms_pooled=tuple(np.sqrt(sq.sum(0) / n)),
        slip_rms_worst_seed=tuple(np.max([r.slip_rms for r in results], 0)),
        coverage_min={k: min(r.coverage[k] for r in results) for k in states},
        updates_per_second=(sum(r.updates for r in results) / wall) if (wall := sum(r.wall_time_s for r in results))
        else 0.0,
        scale_rel_error_rms=tuple(np.sqrt(np.mean(rel**2, 0))),
        rms_position=float(np.sqrt(np.mean([r.rms_position**2 for r in results]))),
    )
