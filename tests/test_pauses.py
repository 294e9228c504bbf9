"""A log that pauses: no sensor at all for minutes or a day, then the run
goes on (a robot parked while its logger stopped, two sessions in one file).

A probe's yard log with every stamp after 60 s shifted by an hour: the EKF
coasted through the hour at constant velocity, left the heading's sigma at
110 rad, rejected 894 of 1499 fixes after it and settled in the mirror
solution; batch (started from the EKF) followed it; isam2 stopped
(IndeterminateSystemException at the segment hand-over) and fixed-lag wrote
a row 2 m off at a sigma of 2.7 km. Now every method estimates across it
(ekf._pause, incremental: the hand-over's floor and fixed-lag's filing of a
long interval). The logs here are other scenarios, seeds, rates and pauses
than the probe's, and include a robot that drove during the silence.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from odomgraph.estimators.measurements import PAUSE_S
from odomgraph.io.log import Log, Truth
from odomgraph.pipeline import estimate
from odomgraph.analysis.metrics import truth_errors
from odomgraph.result import status_of
from odomgraph.sim.scenarios import Rates, paper, yard
from odomgraph.sim.simulate import simulate


def paused(log: Log, at: float, pause: float) -> Log:
    """``log`` with every stamp from ``at`` [s] on (sensors and truth) moved
    ``pause`` [s] later: the robot stood still, its logger stopped."""
    def shift(obj):
        if obj is None:
            return None
        t = np.where(obj.t >= at, obj.t + pause, obj.t)
        if isinstance(obj, Truth):
            return Truth(t, obj.values)
        return replace(obj, t=t)
    return log.with_(**{k: shift(getattr(log, k)) for k in ("encoders", "gyro", "gps", "ranges", "velocity",
                                                             "truth")})


def silent(log: Log, a: float, b: float) -> Log:
    """``log`` with no sensor row inside (a, b) [s] while the robot drove on:
    the encoder row after the silence carries every tick turned in it."""
    e = log.encoders
    gone = (e.t > a) & (e.t < b)
    after = int(np.argmax(e.t >= b))
    tl, tr = e.ticks_left.copy(), e.ticks_right.copy()
    tl[after] += tl[gone].sum()
    tr[after] += tr[gone].sum()
    keep = ~gone
    enc = replace(e, t=e.t[keep], ticks_left=tl[keep], ticks_right=tr[keep])

    def cut(obj):
        if obj is None:
            return None
        k = (obj.t <= a) | (obj.t >= b)
        return replace(obj, **{f: (v[k] if isinstance(v, np.ndarray) and v.shape[:1] == obj.t.shape else v)
                               for f, v in obj.__dict__.items()})
    return log.with_(encoders=enc, gyro=cut(log.gyro), gps=cut(log.gps), velocity=cut(log.velocity))


CASES = [
    # scenario, seed, rates, pause start [s], pause [s]
    ("paper", 3, Rates(encoders=20.0, gyro=25.0, gps=5.0), 70.0, 1800.0),
    ("yard", 12, Rates(encoders=50.0, gyro=100.0, gps=10.0), 33.0, 86400.0),
]


def _log(name, seed, rates, duration):
    sc = (paper if name == "paper" else yard)(duration)
    return simulate(sc.with_(rates=rates), seed)


@pytest.mark.parametrize("method", ["ekf", "batch", "isam2", "fixed-lag"])
@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_every_method_estimates_across_a_pause(case, method):
    name, seed, rates, at, pause = case
    log = _log(name, seed, rates, 100.0)
    est = estimate(paused(log, at, pause), method)
    errors = truth_errors(est, paused(log, at, pause))
    assert status_of(est)[0] in ("ok", "recovered"), (status_of(est), est.warnings)
    assert errors.rms_position_m < 0.15, errors.rms_position_m
    # No row is off by more than its sigma can say (the mid-pause row included).
    assert errors.coverage_3sigma["x"] >= 0.95 and errors.coverage_3sigma["y"] >= 0.95, errors.coverage_3sigma
    assert max(abs(v) for v in errors.final_scale_error.values()) < 0.02, errors.final_scale_error
    assert est.rejected.get("gps", 0) <= 2, est.rejected     # (the yard log's jump at 33 s, before the pause)
    if method == "ekf":
        notes = [n for n in est.notes if "pauses" in n]
        assert len(notes) == 1 and f"{pause:.4g} s" in notes[0], est.notes


def test_a_pause_changes_nothing_before_it():
    """The EKF's rows before the pause are those of the log that does not pause."""
    log = _log("paper", 4, Rates(), 90.0)
    a = estimate(log, "ekf")
    b = estimate(paused(log, 50.0, 600.0), "ekf")
    n = int(np.sum(a.t < 49.0))
    np.testing.assert_array_equal(a.mean[:n], b.mean[:n])


@pytest.mark.parametrize("seed", [5, 6])
def test_the_wheels_carry_the_pose_across_a_silence_the_robot_drove_through(seed):
    """No sensor for 15 s while the robot drove on (paper scenario, its
    straight runs and pivots): the encoder row after the silence holds the
    ticks, and the EKF carries the pose by them, its sigma widened by the
    unknown path shape; the fixes after the silence are all taken."""
    log = _log("paper", seed, Rates(encoders=20.0, gyro=25.0, gps=5.0), 100.0)
    a, b = 60.0, 75.0
    assert b - a > PAUSE_S
    cut = silent(log, a, b)
    est = estimate(cut, "ekf")
    errors = truth_errors(est, cut)
    assert status_of(est)[0] in ("ok", "recovered"), (status_of(est), est.warnings)
    # The path's shape in the silence is unknown: the first fixes after it
    # may be held out as a jump, a few, not the run's.
    assert est.rejected.get("gps", 0) <= 5, est.rejected
    after = (est.t > b + 5.0)
    e = np.hypot(est.mean[after, 0] - cut.truth.at("x", est.t[after]),
                 est.mean[after, 1] - cut.truth.at("y", est.t[after]))
    assert e.max() < 0.2, e.max()
    note = next(n for n in est.notes if "pauses" in n)
    assert "wheels' travel" in note
    # the distance the note gives is the wheels' travel over the silence (the
    # ticks of the row that spans it, the true scale factors), to 2 %: not
    # the ground's, where a wheel slipped (this scenario's slips)
    travelled = float(note.split("(")[-1].split(" m")[0])
    e, r = cut.encoders, cut.robot
    row = int(np.argmax(e.t >= b))
    sl, sr, _ = cut.truth_scales
    wheels = abs(0.5 * (e.ticks_left[row] / (r.ticks_per_meter_left * sl)
                        + e.ticks_right[row] / (r.ticks_per_meter_right * sr)))
    assert abs(travelled - wheels) < 0.02 * wheels + 0.01, (travelled, wheels)
    assert errors.coverage_3sigma["x"] >= 0.95


def _as_wheel_speeds(log: Log) -> Log:
    """``log`` with its encoder rows as wheel_speeds.csv samples (each row's
    average speed at its interval's midpoint): samples are instants, so a
    pause holds no odometry."""
    from odomgraph.io.log import WheelSpeeds
    e, r = log.encoders, log.robot
    dt = np.diff(e.t)
    ws = WheelSpeeds(0.5 * (e.t[1:] + e.t[:-1]), e.ticks_left[1:] / (r.ticks_per_meter_left * dt),
                     e.ticks_right[1:] / (r.ticks_per_meter_right * dt))
    return log.with_(encoders=None, wheel_speeds=ws)


@pytest.mark.parametrize("method", ["ekf", "batch", "isam2", "fixed-lag"])
def test_a_pause_in_wheel_speeds_adds_no_error_and_no_flag(method):
    """wheel_speeds.csv (libRSF's kind of log), 2 Hz GPS, paused 2 h: no
    method flags the paused log for anything it does not flag the same log
    unpaused for, and its rows outside the pause are as close to the
    truth; fixed-lag's, where they are not, are flagged. Before, the
    smoothers took the last sample before the pause for the speed over all
    of it (3.6 km in the first linearisation)."""
    plain = _as_wheel_speeds(_log("yard", 21, Rates(encoders=20.0, gyro=50.0, gps=2.0), 100.0))
    ws = plain.wheel_speeds
    held = paused(plain, 40.0, 7200.0).with_(
        wheel_speeds=replace(ws, t=np.where(ws.t >= 40.0, ws.t + 7200.0, ws.t)))
    a, b = estimate(plain, method), estimate(held, method)
    # a flag's kind: its words before the first number
    flags = lambda est: sorted(__import__("re").split(r"\d", f, maxsplit=1)[0] for f in est.flags)

    def rms_outside(est, log):
        out = (est.t < 40.0) | (est.t > 7240.0)
        t = est.t[out]
        return float(np.sqrt(np.mean((est.mean[out, 0] - log.truth.at("x", t)) ** 2
                                     + (est.mean[out, 1] - log.truth.at("y", t)) ** 2)))
    if method == "fixed-lag" and rms_outside(b, held) >= 1.5 * rms_outside(a, plain) + 0.01:
        # Fixed-lag after a long silence (README, Known limitations): its
        # re-solves after the pause left rows 0.55 m off at z 50 inside the
        # stuck-wheels slip 35 s later (8 cm RMS against 1 cm); it says so.
        assert status_of(b)[0] == "degraded"
        assert any("did not bring the estimate back" in f for f in b.flags), b.flags
        return
    assert rms_outside(b, held) < 1.5 * rms_outside(a, plain) + 0.01
    # The pause adds no flag; it may take one away where a run's figures sit
    # at a check's threshold (the unpaused run's path scale 0.68 % off at z
    # 5.0, flagged; paused, after the re-solves the pause sets off, 0.49 %,
    # under the 0.5 % floor).
    assert set(flags(b)) <= set(flags(a)), (a.flags, b.flags)
    if flags(a) == flags(b) and not b.recoveries:
        assert status_of(a)[0] == status_of(b)[0]


def test_a_stream_finds_a_short_pause_as_the_whole_log_does():
    """A 14 s pause: the encoder row spanning it is stamped at its midpoint,
    so no step is longer than 10 s. A stream does not know the log's pauses
    in advance (its warm-up has none); the row's interval says it."""
    from odomgraph.estimators.ekf import EKF
    log = paused(_log("yard", 23, Rates(encoders=20.0, gyro=50.0, gps=5.0), 80.0), 41.0, 14.0)
    whole = EKF(log)
    assert whole.pause_spans
    a = whole.run()
    live = EKF(log)
    live.pause_spans = []                      # as a stream's, whose measurements grow
    b = live.run()
    np.testing.assert_array_equal(a.mean, b.mean)
    assert [n for n in b.notes if "pauses" in n] == [n for n in a.notes if "pauses" in n] != []


@pytest.mark.parametrize("name,seed,a,b", [("paper", 7, 40.0, 58.0), ("yard", 8, 30.0, 55.0)])
def test_batch_rows_inside_a_silence_carry_the_unknown_path(name, seed, a, b):
    """No sensor while the robot drove on: batch draws its rows there between
    the states either side (one long keyframe interval), which say nothing of
    the path's shape. Before: a probe's 30 s silence, a row 4.1 m and 1.7 rad
    off at sigma 1-3 cm, status ok. Now each row inside, and each row resampled
    at 5 Hz, is inside 3 sigma, the silence is named with the wheels' travel,
    and nothing is added outside it."""
    from odomgraph.analysis.resample import regular_times, resampled
    from odomgraph.estimators import gaps
    log = _log(name, seed, Rates(encoders=50.0, gyro=50.0, gps=10.0), 90.0)
    cut = silent(log, a, b)
    est = estimate(cut, "batch")
    (pa, pb, dist, _), = est.pauses
    assert pa == pytest.approx(a, abs=0.05) and pb == pytest.approx(b, abs=0.05)
    # the wheels' travel over the silence (nominal parameters), to the scale factors' few per cent
    e, r = cut.encoders, cut.robot
    row = int(np.argmax(e.t >= b))
    wheels = abs(0.5 * (e.ticks_left[row] / r.ticks_per_meter_left + e.ticks_right[row] / r.ticks_per_meter_right))
    assert dist == pytest.approx(wheels, rel=0.01) and dist > 5.0
    assert any(f"t={pa:.1f}-{pb:.1f} s" in n and f"{dist:.2f} m" in n for n in est.notes), est.notes
    for rows in (est, resampled(est, regular_times(est, 5.0))):
        inside = (rows.t > a) & (rows.t < b)
        assert inside.sum() >= (1 if rows is est else 5 * (b - a) - 2)
        ex = rows.mean[inside, 0] - cut.truth.at("x", rows.t[inside])
        ey = rows.mean[inside, 1] - cut.truth.at("y", rows.t[inside])
        assert np.all(np.abs(ex) < 3 * rows.sigma[inside, 0]) and np.all(np.abs(ey) < 3 * rows.sigma[inside, 1])
        # mid-silence the heading is as unknown as a start's without one
        mid = inside & (np.abs(rows.t - 0.5 * (a + b)) < 0.25 * (b - a))
        assert np.all(rows.sigma[mid, 2] > 1.5), rows.sigma[mid, 2]
    # outside the silence nothing changed: the widening is the rows' own variance plus the bridge's
    pos, th = gaps.pause_variance(est.t, est.pauses)
    assert np.all(pos[(est.t <= a) | (est.t >= b)] == 0.0)
    assert np.all(th[(est.t <= a) | (est.t >= b)] == 0.0)


@pytest.mark.parametrize("name,seed,a,b", [("paper", 9, 45.0, 62.0), ("yard", 10, 30.0, 58.0)])
def test_isam2_comes_out_of_a_silence_on_the_fixes(name, seed, a, b):
    """After a silence the robot drove through, the interval across it is an
    arc whose length and net turn the wheels give, not its shape: its motion
    row is as loose as the EKF's pause (graph.motion_sigma). Held tight, it
    kept isam2's pose metres from the fixes after a probe's 30 s silence
    (300-400 fixes gated, rows 3-9 m off at z 40-130 for 40 s); on the yard
    log here isam2 stopped (diverged). Now isam2's rows after it are inside
    3 sigma but for its first second or so (the yard: 0.2 m off at z 12 for
    1.2 s; its online rows' jump there makes the status degraded), and every
    row inside it; batch's, 97 % after and every row inside."""
    log = _log(name, seed, Rates(encoders=50.0, gyro=50.0, gps=10.0), 100.0)
    cut = silent(log, a, b)
    for method in ("isam2", "batch"):
        est = estimate(cut, method)
        ex = est.mean[:, 0] - cut.truth.at("x", est.t)
        ey = est.mean[:, 1] - cut.truth.at("y", est.t)
        inside3 = (np.abs(ex) < 3 * est.sigma[:, 0]) & (np.abs(ey) < 3 * est.sigma[:, 1])
        after = est.t > b
        assert inside3[after].mean() >= (0.97 if method == "batch" else 0.92), (method, inside3[after].mean())
        assert np.all(inside3[(est.t > a) & (est.t < b)]), method
        assert np.hypot(ex[-1], ey[-1]) < 0.1, method


def test_a_parked_robot_keeps_its_heading_through_the_pause():
    """The logger stopped while the robot stood (paused): the keyframe states
    either side of the silence are one pose and the wheels turned nothing,
    so the distance is a few centimetres at most and the heading is not
    widened (an earlier form measured the distance between the rows either
    side, 0.2 s of driving away from the silence, and gave a parked robot's
    mid-pause row a heading sigma of pi)."""
    log = _log("yard", 14, Rates(encoders=50.0, gyro=50.0, gps=10.0), 90.0)
    est = estimate(paused(log, 40.0, 600.0), "batch")
    (a, b, dist, turn), = est.pauses
    assert b - a == pytest.approx(600.0, abs=1.0)
    assert dist < 0.1 and turn < 0.1, (dist, turn)
    mid = (est.t > a) & (est.t < b)
    assert mid.any() and np.all(est.sigma[mid, 2] < 0.1), est.sigma[mid, 2]
