"""A log whose first GPS fix comes long after the robot started driving.

Before the first fix nothing ties the wheels' frame to the world: the rows
there are known only up to a turn about where the fixes begin, a circle as
wide as the path driven since (estimators.heading). batch solves the whole
log and is right there; fixed-lag's rows leave its window before any fix and
kept their wheels-frame sigma: a probe of the ninth session (paper seed 12,
first fix at 35 s, 5 Hz keyframes) found rows 25.5 m off at z 13, status ok,
no flag. Not mended yet (README Known limitations): the fixed-lag cases are
strict xfails, so that the fix flips them.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from odomgraph.pipeline import Method, Schedule, estimate
from odomgraph.sim.scenarios import paper
from odomgraph.sim.simulate import simulate


def late_fix_log(seed: int, first_fix: float):
    """The paper log (90 s, no slip) with every GPS fix before ``first_fix`` [s] removed."""
    log = simulate(paper(90.0).with_(slips=()), seed)
    g = log.gps
    k = g.t > first_fix
    extra = {"sigma": g.sigma[k]} if g.sigma is not None else {}
    return log.with_(gps=replace(g, t=g.t[k], x=g.x[k], y=g.y[k], **extra))


def worst_position_z(est, log) -> tuple[float, float]:
    """(largest position error [m], largest |error| / sigma of x or y) over the rows."""
    tr = log.truth
    x = np.interp(est.t, tr.t, tr.values["x"])
    y = np.interp(est.t, tr.t, tr.values["y"])
    ex, ey = est.mean[:, 0] - x, est.mean[:, 1] - y
    z = np.maximum(np.abs(ex) / est.sigma[:, 0], np.abs(ey) / est.sigma[:, 1])
    return float(np.hypot(ex, ey).max()), float(z.max())


@pytest.mark.parametrize("seed, first_fix", [(12, 35.0), (13, 30.0), (16, 25.0)])
def test_batch_is_right_before_a_late_first_fix(seed, first_fix):
    log = late_fix_log(seed, first_fix)
    est = estimate(log, Method.batch, Schedule(20.0), keyframe_hz=5.0)
    err, z = worst_position_z(est, log)
    assert err < 1.0 and z < 4.0, (err, z)                              # measured 0.4 m, z 0.9-2.1 (seeds 12, 13)


@pytest.mark.xfail(strict=True, reason="fixed-lag rows before a late first fix keep their wheels-frame sigma "
                                       "(README Known limitations, ninth session's probe)")
@pytest.mark.parametrize("seed, first_fix", [(12, 35.0), (16, 25.0)])
def test_fixed_lag_rows_before_a_late_first_fix_are_honest(seed, first_fix):
    """Each row inside 5 sigma, or the estimate flagged. Unflagged here:
    seed 12 at 35 s, 25.5 m at z 13; seed 16 at 25 s, 10.1 m at z 45.
    Seeds 13-15 (first fix at 30-40 s) are flagged by the re-solve check,
    with rows 5-13 m off at z 36-184."""
    log = late_fix_log(seed, first_fix)
    est = estimate(log, Method.fixed_lag, Schedule(20.0), keyframe_hz=5.0)
    err, z = worst_position_z(est, log)
    assert z < 5.0 or est.flags, (err, z)                               # measured 25.5 m at z 13.3 (seed 12)
