"""An estimate that moved the robot sideways is flagged (analysis.sideways).

The check was tuned on the paper and yard scenarios with seeds 11-16 and
21-28; the tests below use other seeds, biases, directions and GPS rates."""
from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.analysis import sideways


def _rows(t, x, y, th, pos_sd=0.01, th_sd=0.01):
    mean = np.zeros((len(t), S.N))
    mean[:, S.X], mean[:, S.Y], mean[:, S.THETA] = x, y, th
    sigma = np.full((len(t), S.N), pos_sd)
    sigma[:, S.THETA] = th_sd
    return SimpleNamespace(t=np.asarray(t, float), mean=mean, sigma=sigma)


def test_a_sideways_jog_is_found_with_its_size_and_a_turn_is_not():
    t = np.arange(0.0, 40.0, 0.1)
    # along x at 1 m/s, with a 0.5 m jog to the left (across the heading) over 20-21 s
    jog = 0.5 * np.clip(t - 20.0, 0.0, 1.0)
    found = sideways.stretches(_rows(t, t, jog, np.zeros_like(t)))
    assert found, "a 0.5 m jog is not found"
    a, b, move, z = max(found, key=lambda f: abs(f[2]))
    assert a <= 20.0 + 1e-9 and b >= 21.0 - 1e-9
    assert move == pytest.approx(0.5, abs=1e-9)
    # what the rows allow: two ends at 0.01 m, and 0.01 rad over the
    # distance driven (3 m at least, in the shortest window)
    assert sideways.Z_SIDE < z <= 0.5 / np.sqrt(2 * 0.01**2 + (3.0 * 0.01) ** 2)
    # a circle of 5 m radius at 1 m/s, heading along the path: nothing sideways
    ang = t / 5.0
    assert sideways.stretches(_rows(t, 5 * np.sin(ang), 5 - 5 * np.cos(ang), ang)) == []
    # the same jog where the rows do not know the heading: no finding
    assert sideways.stretches(_rows(t, t, jog, np.zeros_like(t), th_sd=0.5)) == []
    # ... nor where the rows' sigmas cover it (0.5 m apart at 0.1 m each: 3.5 sigma)
    assert sideways.stretches(_rows(t, t, jog, np.zeros_like(t), pos_sd=0.1)) == []
    # ... nor a jog smaller than SIDE_M, however tight the sigmas
    assert sideways.stretches(_rows(t, t, 0.1 * np.clip(t - 20.0, 0.0, 1.0), np.zeros_like(t), pos_sd=1e-4)) == []
    # ... nor one across a gap in the rows longer than ROW_GAP_MAX
    keep = (t < 19.45) | (t > 21.55)
    assert sideways.stretches(_rows(t[keep], t[keep], jog[keep], np.zeros(keep.sum()))) == []


def _biased(log, a, b, amp):
    """``log`` with its fixes moved ``amp`` m to the left of the true
    heading at ``a`` between a and b [s] (1 s ramps: a multipath bias)."""
    g = log.gps
    ramp = np.clip(np.minimum(g.t - a, b - g.t), 0.0, 1.0)
    across = log.truth.at("theta", np.array([a]))[0] + np.pi / 2
    return log.with_(gps=replace(g, x=g.x + amp * ramp * np.cos(across), y=g.y + amp * ramp * np.sin(across)))


def _z(est, log):
    ex = est.mean[:, S.X] - log.truth.at("x", est.t)
    ey = est.mean[:, S.Y] - log.truth.at("y", est.t)
    return float(np.max(np.maximum(np.abs(ex) / est.sigma[:, S.X], np.abs(ey) / est.sigma[:, S.Y])))


@pytest.mark.parametrize("scenario,seed,hz,amp,span", [("paper", 41, 10.0, 0.8, (40.0, 50.0)),
                                                       ("yard", 42, 20.0, -0.6, (55.0, 63.0))])
@pytest.mark.parametrize("method", ["ekf", "batch", "isam2", "fixed-lag"])
def test_fixes_biased_sideways_are_flagged(scenario, seed, hz, amp, span, method):
    """A probe's log: a multipath bias across the heading for 8-10 s. Every
    estimator followed it (0.8 m off at z 82, status ok). Now the estimate
    is flagged (and the smoothers' rows, run again without the biased
    fixes, mostly right), or honest without it; and the unbiased log says
    nothing."""
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import estimate, status_of
    from odomgraph.sim.faults import Faults, inject
    from odomgraph.sim.scenarios import paper, yard
    base = paper(80.0) if scenario == "paper" else yard(90.0)
    clean = inject(base.with_(rates=replace(base.rates, gps=hz)), Faults(), seed)
    est = estimate(_biased(clean, *span, amp), method, Schedule(20.0))
    side = [f for f in est.flags if "sideways" in f]
    held = [f for f in side if "held out" in f]
    z = _z(est, clean)
    err = np.hypot(est.mean[:, S.X] - clean.truth.at("x", est.t), est.mean[:, S.Y] - clean.truth.at("y", est.t))
    assert side or z < 5.0, (z, est.flags)
    if method != "ekf":
        # the smoothers follow such a bias smoothly, and are always caught
        # here: flagged, and where a run without the biased fixes stood,
        # its rows honest (the clean log's reach z 4-7) and off by well
        # under the bias (the rows there are dead-reckoned: 0.24 m at z 2.8)
        assert side and status_of(est)[0] == "degraded", (z, est.flags)
        if method == "batch" and scenario == "paper":
            # (the run without the biased fixes stands here: its path is exercised)
            assert held, est.flags
        if held:
            assert z < 10.0 and err.max() < 0.4 * abs(amp), (z, err.max(), held)
            assert est.rejected["gps"] == len(est.held_out["gps"]) > 0
            on = (clean.gps.t > span[0] + 1.0) & (clean.gps.t < span[1] - 1.0)
            assert np.isin(clean.gps.t[on], est.held_out["gps"]).all()   # every fix of the bias held out
        else:
            a, b = (float(v) for v in side[0].split(" at ")[1].split(" s ")[0].split("-"))
            assert a < span[1] and b > span[0], side[0]
    if scenario == "yard":
        # the unbiased twin says nothing (the yard's own slips, slides and
        # reversals included; the paper scenario's clean runs are the other
        # tests' and the probe's)
        ref = estimate(clean, method, Schedule(20.0))
        assert not [f for f in ref.flags if "sideways" in f], ref.flags


def test_a_bias_longer_than_what_was_held_out_stays_flagged():
    """A probe: a 0.6 m bias for 30 s, seen only at its start. Batch held
    out the good fixes before it, followed the bias after them (0.63 m off
    at z 99) and called itself recovered. A run without fixes cannot tell
    which side of the stretch is right: it stays flagged."""
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import estimate, status_of
    from odomgraph.sim.faults import Faults, inject
    from odomgraph.sim.scenarios import paper
    clean = inject(paper(90.0), Faults(), 44)
    est = estimate(_biased(clean, 45.0, 75.0, 0.6), "batch", Schedule(20.0))
    side = [f for f in est.flags if "sideways" in f]
    assert side and status_of(est)[0] == "degraded", (_z(est, clean), est.flags)
