"""Encoder rows lost with their ticks (analysis.wheelgaps).

A probe's log with the encoder rows from 25 to 45 s deleted (the ticks not
summed into the next row, against LOG_FORMAT.md) had batch 2.6 m off at
z 72, status ok, and `calibrate` wrote ticks/m 8 sigma off. Here: other
scenarios, seeds and gaps; a dropout whose ticks arrive in the next row
(the contract) is silent."""
from dataclasses import replace

import numpy as np
import pytest

from odomgraph.analysis.wheelgaps import lost_tick_warnings
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import calibrate, estimate
from odomgraph.result import status_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper, yard


def _drop_rows(log, a, b):
    """The log with the encoder rows in (a, b] deleted, their ticks lost."""
    e = log.encoders
    keep = (e.t <= a) | (e.t > b)
    return log.with_(encoders=replace(e, t=e.t[keep], ticks_left=e.ticks_left[keep], ticks_right=e.ticks_right[keep]))


@pytest.mark.parametrize("make,seed,a,b", [(yard, 31, 40.0, 52.0), (paper, 32, 70.0, 76.0), (yard, 33, 95.0, 99.0)])
def test_rows_lost_with_their_ticks_are_said(make, seed, a, b):
    log = _drop_rows(inject(make(120.0), Faults(), seed), a, b)
    said = lost_tick_warnings(log)
    assert len(said) == 1 and f"t={a:.1f}-{b:.1f} s" in said[0] and said[0].endswith("not trustworthy"), said
    counted = float(said[0].split(": the wheels counted ")[1].split(" m")[0])
    moved = float(said[0].split("the fixes moved ")[1].split(" m")[0])
    assert moved > counted + 0.3


def test_an_estimate_over_lost_ticks_is_flagged_and_not_calibrated_from():
    log = _drop_rows(inject(yard(120.0), Faults(), 34), 50.0, 62.0)
    est = estimate(log, "batch", Schedule(20.0))
    assert status_of(est)[0] == "degraded" and any(w.startswith("encoders: gaps in the rows") for w in est.flags)
    _, rep = calibrate(log, tune=False)
    assert any(w.startswith("encoders: gaps in the rows") for w in rep["problems"])


@pytest.mark.parametrize("make,seed", [(paper, 35), (yard, 36), (yard, 37)])
def test_a_dropout_whose_ticks_arrive_later_is_silent(make, seed):
    log = inject(make(120.0), Faults(encoder_dropouts=((50.0, 53.0), (80.0, 86.0)), encoder_drop_rate=0.03), seed)
    assert np.diff(log.encoders.t).max() > 2.9
    assert lost_tick_warnings(log) == []
