"""The wheels slipped inside a gap in the fixes (estimators.gaps).

A hostile probe's yard log (a 10 s stall inside a 14 s GPS outage, seed 181)
had batch 0.5-1.2 m off at sigma 1-4 cm, status ok: the smoother put the
stall where its sparse slip prior liked it, and nothing in the log says
when it was. Other scenarios, stalls, outages and seeds here."""
import re

import numpy as np
import pytest

from odomgraph.estimators import gaps
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.sim.faults import Faults, Stall, inject
from odomgraph.sim.scenarios import paper, yard

CASES = {
    "paper, stall 40-47 s inside an outage 36-52 s, seed 71": (paper, Stall(40.0, 47.0, 0.6, 0.6), (36.0, 52.0), 71),
    "yard, stall 61-66 s inside an outage 55-70 s, seed 72": (yard, Stall(61.0, 66.0, 0.4, 0.45), (55.0, 70.0), 72),
}


def _inside_the_gap(case, method):
    """The case's log and estimate, and the rows' x and y error / sigma inside the gap."""
    make, stall, (a, b), seed = CASES[case]
    log = inject(make(90.0).with_(slips=()), Faults(stalls=(stall,), outages=(("gps", a, b),)), seed)
    est = estimate(log, method, Schedule(20.0))
    inside = (est.t > a) & (est.t < b)
    ex = est.mean[inside, 0] - log.truth.at("x", est.t[inside])
    ey = est.mean[inside, 1] - log.truth.at("y", est.t[inside])
    return log, est, np.abs(ex) / est.sigma[inside, 0], np.abs(ey) / est.sigma[inside, 1]


@pytest.mark.parametrize("method", ["batch", "isam2"])
@pytest.mark.parametrize("case", list(CASES))
def test_positions_inside_the_gap_are_covered(case, method):
    _, stall, _, _ = CASES[case]
    _, est, zx, zy = _inside_the_gap(case, method)
    cov = min(np.mean(zx <= 3.0), np.mean(zy <= 3.0))
    assert cov >= 0.97, cov
    said = [w for w in est.warnings if w.startswith("the wheels slipped inside gaps in the fixes")]
    assert len(said) == 1, est.warnings
    dist = float(re.search(r"s \(([0-9.]+) m\)", said[0]).group(1))
    truth = 0.5 * (stall.speed_left + stall.speed_right) * (stall.end - stall.start)
    assert dist == pytest.approx(truth, rel=0.3)


def test_an_outage_the_wheels_did_not_slip_in_is_not_widened():
    log = inject(yard(90.0).with_(slips=()), Faults(outages=(("gps", 30.0, 45.0),)), 73)
    est = estimate(log, "batch", Schedule(20.0))
    assert not [w for w in est.warnings if "slipped inside gaps" in w], est.warnings


def test_the_widening_is_a_bridge():
    """Unit check: rows every 0.1 s through a 10 s gap, 0.5 m/s common-mode
    slip for 4 s (2 m): the added variance is 4 f (1 - f) m^2 in x and in y,
    none outside the gap."""
    t = np.arange(0.05, 20.0, 0.1)
    mean = np.zeros((t.size, 11))
    mean[:, 2] = np.radians(30.0)
    slipping = (t > 8.0) & (t < 12.0)
    mean[slipping, 6:8] = 0.5
    sigma = np.full((t.size, 11), 0.01)
    pc = np.zeros((t.size, 3, 3))
    pc[:, 0, 0] = pc[:, 1, 1] = 1e-4
    fix_t = np.concatenate([np.arange(0.0, 5.01, 0.5), np.arange(15.0, 20.01, 0.5)])
    found = gaps.widen_gaps(t, mean, sigma, pc, fix_t)
    assert len(found) == 1 and found[0][:2] == (5.0, 15.0) and found[0][2] == pytest.approx(2.0, abs=1e-9)
    inside = (t > 5.0) & (t < 15.0)
    f = (t[inside] - 5.0) / 10.0
    for i in (0, 1):
        np.testing.assert_allclose(pc[inside, i, i], 1e-4 + 4.0 * f * (1.0 - f), atol=1e-12)
        np.testing.assert_allclose(sigma[inside, i] ** 2, 1e-4 + 4.0 * f * (1.0 - f), atol=1e-12)
    assert np.all(pc[inside, 0, 1] == 0.0)
    assert np.all(sigma[~inside, 0:2] == 0.01) and np.all(pc[~inside, 0, 0] == 1e-4)


@pytest.mark.parametrize("method", ["ekf", "fixed-lag", "isam2"])
@pytest.mark.parametrize("case", list(CASES))
def test_causal_rows_inside_the_gap_are_covered_or_flagged(case, method):
    """A filter's rows (isam2's online.csv, and fixed-lag's, out before the
    gap ends) cannot be widened after the fact: covered, or flagged by the
    first fix after it."""
    from odomgraph.result import status_of
    make, stall, (a, b), seed = CASES[case]
    if method == "isam2":
        log = inject(make(90.0).with_(slips=()), Faults(stalls=(stall,), outages=(("gps", a, b),)), seed)
        est = estimate(log, method, Schedule(20.0))
        o = est.online
        inside = (o.t > a) & (o.t < b)
        zx = np.abs(o.mean[inside, 0] - log.truth.at("x", o.t[inside])) / o.sigma[inside, 0]
        zy = np.abs(o.mean[inside, 1] - log.truth.at("y", o.t[inside])) / o.sigma[inside, 1]
    else:
        _, est, zx, zy = _inside_the_gap(case, method)
    z = np.maximum(zx, zy)
    if z.max() > 5.0:
        said = [w for w in est.warnings if "the first fix after a gap in the fixes lay far" in w
                or ("slipped inside gaps in the fixes" in w and "not trustworthy there" in w)]
        assert said and status_of(est)[0] == "degraded", (z.max(), est.warnings)


def test_the_first_fix_after_a_gap_is_read_against_the_last_row_before_it():
    """Unit check: rows at 10 Hz heading east, antenna 0.5 m ahead; fixes at
    1 Hz with a 6 s gap. The fix after it 1 m north of the prediction is
    flagged at a row sigma of 0.1 m (10 sigma), not at 0.5 m (2 sigma)."""
    t = np.arange(0.0, 20.0, 0.1) + 0.05
    mean = np.zeros((t.size, 11))
    mean[:, 0] = t                                       # 1 m/s east
    gt = np.concatenate([np.arange(0.0, 8.01, 1.0), np.arange(14.0, 20.0, 1.0)])
    xy = np.stack([gt + 0.5, np.zeros_like(gt)], -1)
    xy[gt == 14.0, 1] = 1.0
    gps = (gt, xy, np.full(gt.size, 0.01))
    path = (np.arange(0.0, 20.01, 0.05), np.stack([np.arange(0.0, 20.01, 0.05), np.zeros(401), np.zeros(401)], -1))
    for s, flagged in ((0.1, True), (0.5, False)):
        pc = np.tile(np.diag([s * s, s * s, 1e-6]), (t.size, 1, 1))
        out = gaps.gap_end_warnings("m", t, mean, pc, gps, (0.5, 0.0), path)
        assert bool(out) == flagged, (s, out)
    assert "t=8.0-14.0 s: 1.00 m, 10.0 sigma" in gaps.gap_end_warnings(
        "m", t, mean, np.tile(np.diag([0.01, 0.01, 1e-6]), (t.size, 1, 1)), gps, (0.5, 0.0), path)[0]


def test_a_slip_that_ended_before_the_outage_is_not_said_to_be_inside_it():
    """A second probe's false alarm: yard's 75-79 s slip ends before a GPS
    outage from 79.5 s; the smoothed slip leaks a few centimetres into the
    gap's first seconds. The rows may carry that, but it is not said."""
    log = inject(yard(150.0), Faults(outages=(("gps", 79.5, 100.0),)), 303)
    est = estimate(log, "batch", Schedule(20.0))
    assert not [w for w in est.warnings if "slipped inside gaps" in w], est.warnings

