"""A stall (the robot held while its wheels spin on: the snowplow in a drift)
seen by ranges, and by GPS with ranges.

Found in the twelfth session: in range-only logs a 6 s stall put the EKF
0.3-2 m off at z 11-15 at the stall's start and end, status ok. The slips
are random walks, and a step of 1 m/s takes them about 2 s to follow.

Mended in part in the thirteenth session: the EKF floors v's and the slips'
variances where three growing innovations of one beacon (or of the GPS) say
the state is leaving what it sees (ekf.departed), and says so (a recovery).
Designed on paper and yard logs at 2 and 5 Hz a beacon, seeds 1-3, a stall
at 50-56 s; the logs here have other seeds, rates (3-5 Hz a beacon), stall
times, lengths and speeds, one with GPS as well. Not caught (README
Known limitations): paper at 3 Hz a beacon, seed 9, a 3 s stall at 0.6 m/s
(z 7.5, 0.30 m off), and paper with 20 Hz GPS and 2 Hz ranges, seed 11
(z 12.3, 0.24 m off), both status ok: no sensor shows three growing
innovations in a row.

batch (fourteenth session): a Huber loss on the slips' common-mode
random-walk step, and that loss's curvature in the covariance
(graph.SLIP_STEP_K, walk_rows): on five stall logs it was not designed on,
errors 2-5 times smaller and z 3.6-5.7 where Gaussian steps gave z 11-25.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from odomgraph.estimators.ekf import EKFOptions, run_ekf
from odomgraph.estimators.ekf_many import run_ekf_many
from odomgraph.pipeline import Schedule
from odomgraph.result import DEPARTURE_SAYS, status_of
from odomgraph.sim.faults import Faults, Stall, inject
from odomgraph.sim.scenarios import paper, yard
from odomgraph.sim.simulate import beacons_around_path


def stalled(scenario, rate: float, seed: int, t0: float, length: float, speed: float, gps: bool = False):
    """A 90 s log with ranges at ``rate`` [Hz] a beacon (3 beacons), and GPS
    if asked, in which the robot is held over [t0, t0 + length] while both
    wheels spin at ``speed`` [m/s]."""
    sc = scenario(90.0).with_(slips=())
    sc = sc.with_(rates=replace(sc.rates, ranges=rate, **({} if gps else {"gps": 0.0})))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around_path(sc, 3)))
    log = inject(sc, Faults(stalls=(Stall(t0, t0 + length, speed, speed),)), seed)
    return log if gps else log.with_(gps=None)


def position_errors(est, log):
    """(largest z of x or y over the rows, largest position error [m])."""
    tr = log.truth
    ex = est.mean[:, 0] - np.interp(est.t, tr.t, tr.values["x"])
    ey = est.mean[:, 1] - np.interp(est.t, tr.t, tr.values["y"])
    z = np.maximum(np.abs(ex) / est.sigma[:, 0], np.abs(ey) / est.sigma[:, 1])
    return float(z.max()), float(np.hypot(ex, ey).max())


CASES = {   # (scenario, ranges a beacon [Hz], seed, stall start [s], length [s], wheel speed [m/s], GPS)
    "yard-3Hz": (yard, 3.0, 7, 40.0, 4.0, 0.8, False),
    "yard-4Hz-long": (yard, 4.0, 8, 65.0, 8.0, 1.2, False),
    "paper-4Hz": (paper, 4.0, 7, 65.0, 5.0, 1.0, False),
    "yard-gps": (yard, 5.0, 10, 45.0, 6.0, 1.0, True),
}


@pytest.mark.parametrize("case,bound", [("yard-3Hz", 0.9), ("yard-4Hz-long", 0.8), ("paper-4Hz", 0.435),
                                        ("yard-gps", 0.27)])
def test_the_ekf_follows_a_stall_and_says_so(case, bound):
    """The largest position error over the rows. Measured: 0.83, 0.76,
    0.43, 0.25 m, z 10.8-13.2 (the rows in the second before the third
    growing innovation), each with a recovery naming the departure (before:
    1.16, 1.98, 0.44, 0.38 m, z 11.7-18.0, three with status ok)."""
    log = stalled(*CASES[case])
    est = run_ekf(log, Schedule(20.0))
    z, err = position_errors(est, log)
    assert err <= bound and z <= 14.0, (z, err)
    assert status_of(est)[0] == "recovered", status_of(est)
    assert est.departures and all(DEPARTURE_SAYS in r for r in est.departures), est.departures
    assert not any(DEPARTURE_SAYS in r for r in est.recoveries), est.recoveries


def test_the_vectorised_ekf_follows_the_same_departures():
    """ekf_many floors the same states at the same times, per run: a stalled
    run beside one that is not, and one with GPS."""
    logs = [stalled(*CASES["yard-4Hz-long"]), stalled(yard, 4.0, 8, 65.0, 0.01, 0.0),
            stalled(*CASES["yard-gps"])]
    many = run_ekf_many(logs[:2], Schedule(20.0))
    for log, b in zip(logs[:2], many):
        a = run_ekf(log, Schedule(20.0))
        np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.sigma, a.sigma, rtol=0, atol=1e-9)
        assert b.recoveries == a.recoveries and b.departures == a.departures
    assert many[0].departures and not many[1].departures
    a, b = run_ekf(logs[2], Schedule(20.0)), run_ekf_many([logs[2]], Schedule(20.0))[0]
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.sigma, a.sigma, rtol=0, atol=1e-9)
    assert b.recoveries == a.recoveries and b.departures == a.departures
    assert any(r.startswith("t=45.") and f"gps: {DEPARTURE_SAYS}" in r for r in a.departures), a.departures


def test_a_filter_without_slip_states_keeps_them_out_of_a_departure():
    """The conventional filter (slip_states off, the paper's fig. 7 baseline)
    follows a departure with v alone: its slips stay exactly 0 with zero
    variance (a second read found them floored too, 2.9 m/s at sigma 0.6)."""
    log = stalled(*CASES["yard-gps"])
    opt = EKFOptions(slip_states=False, max_mean_nis=float("inf"))
    a = run_ekf(log, Schedule(20.0), opt)
    b = run_ekf_many([log], Schedule(20.0), opt)[0]
    assert np.all(a.mean[:, 6:8] == 0.0) and np.all(a.sigma[:, 6:8] == 0.0)
    first = a.departures[0]
    assert first.startswith("t=45.") and DEPARTURE_SAYS in first and "; v widened to " in first, first
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(b.sigma, a.sigma, rtol=0, atol=1e-9)
    assert b.recoveries == a.recoveries and b.departures == a.departures


def test_stalls_again_and_again_are_not_a_lost_filter():
    """Each stall's start and end is a departure (Estimate.departures, not a
    recovery): six stalls make a run "recovered", not "degraded" (more than
    5 recoveries would), and they do not count towards the EKF's
    MAX_RECOVERIES. Measured: 12 departures and nothing else, the largest
    error 0.86 m (counted as recoveries, those 12 made it degraded)."""
    sc = yard(150.0).with_(slips=())
    sc = sc.with_(rates=replace(sc.rates, ranges=4.0, gps=0.0))
    sc = sc.with_(robot=sc.robot.with_(beacons=beacons_around_path(sc, 3)))
    stalls = tuple(Stall(t, t + 5.0, 1.0, 1.0) for t in (35.0, 55.0, 75.0, 95.0, 115.0, 135.0))
    log = inject(sc, Faults(stalls=stalls), 12).with_(gps=None)
    est = run_ekf(log, Schedule(20.0))
    assert len(est.departures) >= 6 and len(est.recoveries) < 6, (est.departures, est.recoveries)
    assert all(DEPARTURE_SAYS in r for r in est.departures), est.departures
    status, why = status_of(est)
    assert status == "recovered" and why[-1] == f"{len(est.departures)} departure(s) followed", why
    from odomgraph.pipeline import summary, warnings_of
    s = summary(est, log, Schedule(20.0))
    assert s["departures"] == est.departures and s["recoveries"] == est.recoveries
    assert s["status"] == "recovered"
    said = [w for w in warnings_of(est, log) if " followed a departure at " in w]
    assert said == [f"ekf followed a departure at {d}" for d in est.departures]


BATCH_CASES = {   # logs the smoother's Huber slip steps were not designed on (graph.SLIP_STEP_K)
    "yard-6Hz": (yard, 6.0, 21, 35.0, 7.0, 0.7, False),
    "paper-2.5Hz": (paper, 2.5, 22, 60.0, 4.0, 1.3, False),
    "paper-gps": (paper, 3.0, 23, 55.0, 6.0, 0.9, True),
    "yard-2Hz": (yard, 2.0, 24, 70.0, 5.0, 1.0, False),
    "paper-8Hz-short": (paper, 8.0, 25, 45.0, 2.5, 1.5, False),
}


@pytest.mark.parametrize("case,bound", [("yard-6Hz", 0.08), ("paper-2.5Hz", 0.15), ("paper-gps", 0.06),
                                        ("yard-2Hz", 0.09), ("paper-8Hz-short", 0.08)])
def test_batch_takes_a_stall_where_the_data_put_it(case, bound):
    """batch with its default Huber loss on the common-mode slip step and the
    loss's curvature in its covariance (graph.walk_rows). Measured, largest
    error and z: 0.060 m z 4.3, 0.124 z 5.7, 0.039 z 4.3, 0.069 z 3.6, 0.054
    z 4.5; with Gaussian steps (slip_step_k inf, before the fourteenth
    session): 0.145 z 11.4, 0.427 z 21.1, 0.128 z 16.2, 0.256 z 14.0, 0.285
    z 24.9, all status ok. The rows at the stall's edges are still beyond
    3 sigma (README Known limitations)."""
    from odomgraph.pipeline import estimate
    log = stalled(*BATCH_CASES[case])
    est = estimate(log, "batch", Schedule(20.0))
    z, err = position_errors(est, log)
    assert err <= bound and z <= 6.5, (z, err)


@pytest.mark.parametrize("option, value", [("slip_step_k", 2.0), ("velocity_loss", "huber"), ("range_bias", True)])
def test_batch_only_options_are_refused_by_the_incremental_smoothers(option, value):
    """isam2 and fixed-lag keep Gaussian slip steps and implement no range
    bias or robust velocity walk: their options type has none of batch's own
    graph options (BatchGraphOptions), and each set is refused with one line
    naming whose option it is, not ignored."""
    from odomgraph.errors import OdomgraphError
    from odomgraph.estimators.batch import BatchGraphOptions, GraphOptions
    from odomgraph.estimators.incremental import IncrementalOptions
    from odomgraph.pipeline import estimate
    assert option in BatchGraphOptions.__dataclass_fields__
    assert option not in GraphOptions.__dataclass_fields__ and option not in IncrementalOptions.__dataclass_fields__
    log = stalled(*BATCH_CASES["paper-8Hz-short"])
    for method in ("isam2", "fixed-lag"):
        with pytest.raises(OdomgraphError, match=rf"^{option} \(--{option.replace('_', '-')}\) is an option of "
                                                 rf"batch, not of {method}$"):
            estimate(log, method, Schedule(20.0), **{option: value})


@pytest.mark.parametrize("seed", [52, pytest.param(61, marks=pytest.mark.slow)])
def test_without_a_gyro_batch_keeps_gaussian_slip_steps(seed):
    """A yard log without a gyro (GPS 5 Hz), one wheel slipping at a time
    (right +0.5 m/s over 60-63 s, left +0.8 over 100-102 s). A second read
    (helper, fourteenth session) found that with Huber slip steps batch read
    the left wheel's slip as a spin in place (both slips +2 m/s, the heading
    3 rad off, rows 0.72-0.77 m off at z 40-43) and said `ok` on seeds 52, 53,
    54 and 61, where Gaussian steps flag the run (the sideways check). Without
    a yaw-rate sensor, the default (slip_step_k None) is Gaussian steps: the
    same run as slip_step_k inf, flagged."""
    import math
    from odomgraph.estimators.batch import build_problem, SmootherOptions
    from odomgraph.pipeline import estimate
    from odomgraph.sim.scenarios import SlipEvent
    sc = yard(150.0)
    sc = sc.with_(rates=replace(sc.rates, gyro=0.0, gps=5.0),
                  slips=(SlipEvent("right", 60, 63, 0.5, 0.1), SlipEvent("left", 100, 102, 0.8, 0.1)))
    log = inject(sc, Faults(), seed).with_(gyro=None)
    assert math.isinf(build_problem(log, Schedule(30.0), SmootherOptions()).slip_step_k)
    est = estimate(log, "batch", Schedule(30.0))
    assert status_of(est)[0] == "degraded", status_of(est)


def test_a_live_stream_says_each_departure_as_it_happens():
    """`odomgraph stream` writes each departure the live EKF follows to
    stderr as it happens, as a departure, not a recovery, and its summary
    lists them: the same lines as the replayed filter's Estimate.departures."""
    import io

    from odomgraph.io.stream import log_lines
    from odomgraph.livestream import run_stream
    from odomgraph.online import Online
    log = stalled(*CASES["yard-gps"])
    ref = run_ekf(log, Schedule(20.0))
    assert ref.departures
    live = Online(log.robot, "ekf", Schedule(20.0))
    out, err = io.StringIO(), io.StringIO()
    run_stream(live, log_lines(log), out, err)
    lines = err.getvalue().splitlines()
    said = [ln.removeprefix("odomgraph: followed a departure: ") for ln in lines
            if ln.startswith("odomgraph: followed a departure: ")]
    assert said == ref.departures, (said, ref.departures)
    assert not any(DEPARTURE_SAYS in ln for ln in lines if "recovered" in ln), lines
    assert live.summary()["departures"] == ref.departures


def test_an_older_checkpoint_moves_its_departures_out_of_the_recoveries():
    """A live EKF checkpointed before departures had a field of their own
    kept them among its recoveries; resumed so, they would count towards
    MAX_RECOVERIES and "degraded". Loading moves them out."""
    from odomgraph.estimators.ekf import EKF
    f = EKF(stalled(*CASES["yard-3Hz"]), Schedule(20.0))
    state = dict(f.__dict__)
    state.pop("departures", None)           # (set when a run starts)
    dep = f"t=45.10 s: ranges: {DEPARTURE_SAYS} (a stall, or its end); v and the slips widened to 0.8 m/s to follow"
    other = "t=51.00 s: 5 gps measurements in a row rejected; covariance widened to re-acquire"
    state["recoveries"] = [dep, other]
    g = EKF.__new__(EKF)
    g.__setstate__(state)
    assert g.departures == [dep] and g.recoveries == [other]
