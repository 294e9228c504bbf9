"""Ranges with many gross outliers (either sign), as UWB gives out of line of sight.

The EKF's gate rescues a rejected range when it lies near the median of its
beacon's last five innovations (ekf.gate_reference): that is how it follows
a state that has left what the sensor sees. A range's outliers have one of
two signs, so three like-signed ones among five are common: with 20 %
outliers about one a run is let in. Until the twelfth session it was taken
at full weight (a 2 m one would move a position known to 10 cm by 1.6 m,
worked out with 5 cm ranges); range-only paper logs
(2 Hz a beacon, seeds 1-16) came out within 3.5 sigma on 3 of 16, 0.9-6 m off
on 11 (flagged), one a typed divergence, and seed 12 0.37 m off at z 24 with
status ok. A rescued range is now taken at a Huber weight (its NIS the
gate's): 12 of 16 within 3.5 sigma. The change was measured on seeds 1-10 of
the paper log; the yard and the GPS-and-ranges logs below are others.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from odomgraph.errors import EstimatorDivergedError
from odomgraph.pipeline import Schedule, estimate
from odomgraph.result import status_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper, yard
from odomgraph.sim.simulate import beacons_around_path


def _ranges(scenario, rate: float, size: float, outliers: float, seed: int, first: float = -1.0,
            gps: bool = False):
    sc = scenario.with_(slips=())
    sc = sc.with_(rates=replace(sc.rates, ranges=rate, **({} if gps else {"gps": 0.0})))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around_path(sc, 3)))
    log = inject(sc, Faults(outlier_rate=outliers, outlier_size=size), seed)
    if not gps:
        log = log.with_(gps=None)
    r = log.ranges
    keep = r.t > first
    return log.with_(ranges=replace(r, t=r.t[keep], range=r.range[keep], beacon=r.beacon[keep]))


def _z(est, log):
    tr = log.truth
    ex = est.mean[:, 0] - np.interp(est.t, tr.t, tr.values["x"])
    ey = est.mean[:, 1] - np.interp(est.t, tr.t, tr.values["y"])
    z = np.maximum(np.abs(ex) / est.sigma[:, 0], np.abs(ey) / est.sigma[:, 1])
    return float(z.max()), float(np.mean(z <= 3.0)), float(np.hypot(ex, ey).max())


@pytest.mark.parametrize("seed", [12, 13, 14, 15, 16])
def test_paper_ranges_with_a_fifth_outliers(seed):
    """Measured: z 2.8-3.5, 99.1-100 % inside 3 sigma, at most 0.30 m off
    (before: seeds 12, 13, 14, 16 0.37-3.2 m off at z 24-35)."""
    log = _ranges(paper(90.0), 2.0, 2.0, 0.2, seed)
    est = estimate(log, "ekf", Schedule(20.0))
    z, inside, err = _z(est, log)
    assert z <= 4.0 and inside >= 0.98 and err <= 0.4, (z, inside, err)


def test_a_run_the_outliers_still_defeat_is_flagged():
    """Seed 11: outliers early, while the start's sigma is a metre, pass any
    gate; the rows end 4.7 m off (6.0 before). Said, not ok."""
    log = _ranges(paper(90.0), 2.0, 2.0, 0.2, 11)
    est = estimate(log, "ekf", Schedule(20.0))
    assert status_of(est)[0] == "degraded", status_of(est)


@pytest.mark.parametrize("seed", [11, 12, 14])
def test_yard_ranges_with_a_fifth_outliers_of_three_metres(seed):
    """5 Hz a beacon. Measured: z 3.0-3.8, 0.10-0.15 m off (before: seeds
    11 and 14 4.6 and 2.2 m off at z 90 and 39)."""
    log = _ranges(yard(90.0), 5.0, 3.0, 0.2, seed)
    est = estimate(log, "ekf", Schedule(20.0))
    z, inside, err = _z(est, log)
    assert z <= 4.5 and inside >= 0.98 and err <= 0.3, (z, inside, err)


@pytest.mark.parametrize("seed", [12, 13, 16])
def test_gps_and_ranges_with_a_fifth_outliers(seed):
    """GPS at the paper's rate with ranges at 2 Hz a beacon, 20 % of both
    outliers (GPS's 2 m in any direction). Measured: z 2.7-3.1, 8 cm off
    (before: z 10-36, 0.2-2.6 m off on these seeds)."""
    log = _ranges(paper(90.0), 2.0, 2.0, 0.2, seed, gps=True)
    est = estimate(log, "ekf", Schedule(20.0))
    z, inside, err = _z(est, log)
    assert z <= 4.0 and inside >= 0.98 and err <= 0.15, (z, inside, err)


@pytest.mark.parametrize("seed", [1, 2, 4, 6])
def test_two_fifths_outliers_after_a_late_first_range_stop_or_are_flagged(seed):
    """40 % outliers and the first range 20 s in: beyond what the gate can
    sort out (the start is fitted to fixes half of whose ranges are wrong).
    A typed divergence, or a result flagged degraded; never ok (seed 1 was
    ok at z 9.7, 15 m off, before)."""
    log = _ranges(paper(90.0), 2.0, 2.0, 0.4, seed, first=20.0)
    try:
        est = estimate(log, "ekf", Schedule(20.0))
    except EstimatorDivergedError as e:
        assert "diverged" in str(e)
        return
    assert status_of(est)[0] == "degraded", (status_of(est), _z(est, log))
