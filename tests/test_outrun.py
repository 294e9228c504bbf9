"""An estimate that moved the robot further than its wheels turned is
flagged (analysis.plausible.outrun_stretches): fixes shifted along the path.

The thresholds were set on the probe's four logs (paper seeds 13, 15, yard
14, 16) and clean paper/yard seeds 1-8 (/tmp notes of the fifteenth
session); the logs below use other seeds, shifts, ramps, directions and
GPS rates."""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.analysis import plausible

TRACK = 0.5


def _rows(t, v, slip_left, slip_right, omega=0.0, slip_sd=0.01):
    n = len(t)
    mean = np.zeros((n, S.N))
    mean[:, S.V], mean[:, S.OMEGA] = v, omega
    mean[:, S.SLIP_L], mean[:, S.SLIP_R] = slip_left, slip_right
    mean[:, S.SCALE] = 1.0
    sigma = np.full((n, S.N), slip_sd)
    return SimpleNamespace(t=np.asarray(t, float), mean=mean, sigma=sigma)


def test_the_distance_beyond_the_wheels_and_what_is_not():
    t = np.arange(0.0, 20.0, 0.1)
    on = (t >= 10.0) & (t <= 11.0)
    # 1 m/s along x; over 10-11 s both wheels turn 0.3 m/s slower than the robot moves
    found = plausible.outrun_stretches(_rows(t, 1.0, np.where(on, -0.3, 0.0), np.where(on, -0.3, 0.0)), TRACK)
    assert len(found) == 1
    a, b, dist, z = found[0]
    assert (a, b) == pytest.approx((10.0, 11.0), abs=1e-9)
    assert dist == pytest.approx(0.3, abs=1e-9)          # 0.3 m/s for 1 s
    assert z == pytest.approx(30.0)                      # 0.3 m/s at a slip sigma of 0.01
    # the same backwards (v < 0, slips of the other sign): the same finding
    back = plausible.outrun_stretches(_rows(t, -1.0, np.where(on, 0.3, 0.0), np.where(on, 0.3, 0.0)), TRACK)
    assert len(back) == 1 and back[0] == pytest.approx(found[0])
    # wheels that spin (slip along the travel) or a stall: nothing
    assert plausible.outrun_stretches(_rows(t, 1.0, np.where(on, 0.3, 0.0), np.where(on, 0.3, 0.0)), TRACK) == []
    # standing still with v a hair below zero while both wheels spin forward
    # (a yard log's stuck robot): the clip to |v| keeps it a hair
    e, _ = plausible.outrun_excess(_rows(t, -0.01, 0.4, 0.4), TRACK)
    assert np.allclose(e, 0.01)
    # a turn: the outer wheel turns faster than the centre moves; one wheel
    # dragging 0.2 m/s (the inner) is no finding either
    assert plausible.outrun_stretches(_rows(t, 1.0, np.where(on, -0.2, 0.0), 0.0, omega=0.5), TRACK) == []
    # both wheels dragging 0.15 m/s in that turn: found, although the outer
    # wheel still turns faster than the centre moves (a first version missed it)
    turn = plausible.outrun_stretches(_rows(t, 1.0, np.where(on, -0.15, 0.0), np.where(on, -0.15, 0.0), omega=0.5), TRACK)
    assert len(turn) == 1 and turn[0][2] == pytest.approx(0.15, abs=1e-9)
    # below OUTRUN_M (0.05 m/s for 1 s), or within the rows' slip sigma: nothing
    small = np.where(on, -0.05, 0.0)
    assert plausible.outrun_stretches(_rows(t, 1.0, small, small, slip_sd=1e-4), TRACK) == []
    assert plausible.outrun_stretches(_rows(t, 1.0, np.where(on, -0.3, 0.0), np.where(on, -0.3, 0.0), slip_sd=0.1),
                            TRACK) == []
    # ... nor across a gap in the rows longer than OUTRUN_GAP: a drag of
    # 0.3 m/s over 9.9-12.6 s with the rows between 10.1 and 12.4 s missing
    # leaves 0.06 m on either side (under OUTRUN_M); one row inside the gap
    # bridges it (two gaps of 1.1-1.2 s): 0.81 m
    wide = (t >= 9.9 - 1e-9) & (t <= 12.6 + 1e-9)
    keep = (t <= 10.1 + 1e-9) | (t >= 12.4 - 1e-9)
    sl = np.where(wide, -0.3, 0.0)[keep]
    assert plausible.outrun_stretches(_rows(t[keep], 1.0, sl, sl), TRACK) == []
    bridged = keep | (np.abs(t - 11.2) < 1e-9)
    sl = np.where(wide, -0.3, 0.0)[bridged]
    (only,) = plausible.outrun_stretches(_rows(t[bridged], 1.0, sl, sl), TRACK)
    assert only[2] == pytest.approx(0.81, abs=1e-9)


# (scenario, seed, GPS Hz, shift [m], span [s], ramp [s], the methods flagged; the others must be right)
CASES = {
    "paper-10Hz-0.6m": ("paper", 51, 10.0, 0.6, (50.0, 56.0), 0.0, {"ekf", "batch", "isam2", "fixed-lag"}),
    "yard-5Hz-0.4m-ramped": ("yard", 52, 5.0, 0.4, (40.0, 47.0), 1.0, {"ekf", "fixed-lag"}),
    "yard-20Hz-0.8m": ("yard", 54, 20.0, 0.8, (100.0, 104.0), 0.5, {"ekf", "batch", "isam2", "fixed-lag"}),
    # a helper's probe of the first version (which compared the centre with the faster wheel): in a turn,
    # no slip events; batch 0.36 m off at z 30, status ok
    "paper-5Hz-0.5m-turn": ("paper-noslip", 103, 5.0, 0.5, (42.5, 48.5), 0.0, {"ekf", "batch"}),
}


def _case(name):
    from odomgraph.sim.faults import Faults, inject
    from odomgraph.sim.scenarios import paper, yard
    scenario, seed, hz, amp, span, ramp, flagged = CASES[name]
    base = paper(100.0) if scenario.startswith("paper") else yard(150.0)
    base = base.with_(slips=()) if scenario.endswith("noslip") else base
    base = base.with_(rates=replace(base.rates, gps=hz))
    clean, shifted = (inject(base, Faults(gps_shifts=shifts), seed) for shifts in ((), ((*span, amp, ramp),)))
    return clean, shifted, span, flagged, 20.0 if scenario.startswith("paper") else 30.0


# The yard cases (150 s logs) run weekly (ODOMGRAPH_WEEKLY); benchmarks/outrun.py runs these checks
# on 76 other logs every time the benchmarks are.
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow) if n.startswith("yard") else n for n in CASES])
@pytest.mark.parametrize("method", ["ekf", "batch", "isam2", "fixed-lag"])
def test_fixes_shifted_along_the_path_are_flagged(name, method):
    """Every estimator followed such a shift (a probe: batch 0.5 m off at
    z 80, status ok). Now the estimate is flagged where its rows outran the
    wheels, stops, is right (batch and isam2 dropped the ramped shift's
    fixes: 2-5 cm) or is flagged by another check; the unshifted twin is
    never flagged."""
    from odomgraph.errors import EstimatorDivergedError
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import estimate, status_of
    clean, log, span, flagged, cal = _case(name)
    try:
        est = estimate(log, method, Schedule(cal))
    except EstimatorDivergedError:
        # stopping, and saying so, is honest: isam2 and fixed-lag at 20 Hz do
        assert name == "yard-20Hz-0.8m" and method in ("isam2", "fixed-lag"), (name, method)
        est = None
    if est is not None:
        found = [f for f in est.flags if "further than its wheels turned" in f]
        if method in flagged:
            assert found and status_of(est)[0] == "degraded", est.flags
            a, b = (float(v) for v in found[0].split(" turned at ")[1].split(" s ")[0].split("-"))
            assert a < span[1] + 1.0 and b > span[0] - 1.0, found[0]
        elif name == "yard-5Hz-0.4m-ramped":
            # batch and isam2 dropped the shifted fixes: right
            err = np.hypot(est.mean[:, S.X] - clean.truth.at("x", est.t), est.mean[:, S.Y] - clean.truth.at("y", est.t))
            assert err.max() < 0.1, err.max()
        else:
            # isam2 and fixed-lag on the turn (z 18-25): flagged by another check
            assert name == "paper-5Hz-0.5m-turn" and status_of(est)[0] == "degraded", (name, est.flags)
    ref = estimate(clean, method, Schedule(cal))
    assert not [f for f in ref.flags if "further than" in f], ref.flags


@pytest.mark.xfail(strict=True, reason="README Known limitations: a shift backwards along the path in a turn is "
                                       "taken for one wheel's slip: the right wheel spins, only the left drags")
def test_a_backward_shift_in_a_turn_is_not_seen():
    """Paper seed 53, GPS 2 Hz, fixes 0.5 m back along the path over 60-66 s
    (inside a turn): batch put the right wheel at +0.5 m/s slip and the left
    at -0.14, rows 0.40 m off at z 14, status ok. Not flagged: one wheel
    drags, the other spins."""
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import estimate
    from odomgraph.sim.faults import Faults, inject
    from odomgraph.sim.scenarios import paper
    base = paper(100.0)
    log = inject(base.with_(rates=replace(base.rates, gps=2.0)), Faults(gps_shifts=((60.0, 66.0, -0.5, 0.0),)), 53)
    est = estimate(log, "batch", Schedule(20.0))
    assert [f for f in est.flags if "further than" in f]
