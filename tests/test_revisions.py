"""Causal rows that jump further than their sigma allowed (analysis.plausible.revision_warnings).

A probe's yard log with 10 m fixes at 0.2 Hz had isam2's online.csv jump
~100 m between keyframes 0.2 s apart at sigma 7-9 m (up to 194 m off at
33 sigma), status `recovered`: the overshoot check waited for a jump beyond
any fix's reach (303 m). Here: the rule on rows built by hand (exact
numbers), the benchmark's two seeds (83, 84), and other seeds and another
scenario that the rule was not written around, flagged wherever rows are
far off and silent on clean logs."""
import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.analysis.plausible import REVISION_SIGMAS, revision_warnings


def _rows(n=50, dt=0.2, v=1.0, sig=0.5):
    t = np.arange(n) * dt
    mean = np.zeros((n, S.N))
    mean[:, S.X] = v * t
    mean[:, S.V] = v
    sigma = np.full((n, S.N), sig)
    return t, mean, sigma


def test_a_robot_driving_at_its_speed_is_not_a_jump():
    t, mean, sigma = _rows(v=8.0, sig=0.01)          # 1.6 m per row, at 1 cm sigma
    assert revision_warnings("ekf", t, mean, sigma) == []


def test_a_revision_within_its_sigma_is_not_a_jump():
    t, mean, sigma = _rows(sig=0.5)
    # 0.2 s at 1 m/s is 0.2 m; a revision of 5.5 x hypot(0.5, 0.5) = 3.9 m beyond it stays under 6
    mean[25:, S.Y] += 5.5 * np.hypot(0.5, 0.5)
    assert revision_warnings("ekf", t, mean, sigma) == []


def test_a_jump_beyond_its_sigma_is_said_with_its_size():
    t, mean, sigma = _rows(sig=0.5)
    mean[30:, S.Y] += 10.0                           # 10 m sideways between rows 29 and 30
    out = revision_warnings("fixed-lag", t, mean, sigma)
    assert len(out) == 1 and out[0].startswith("fixed-lag: 1 time(s) from t=5.8 to 6.0 s")
    beyond = np.hypot(10.0, 0.2) - 0.2
    assert f"at most {beyond:.1f} m beyond it" in out[0]
    assert f"{beyond / np.hypot(0.5, 0.5):.0f} sigma" in out[0] and out[0].endswith("not trustworthy")
    assert REVISION_SIGMAS == 6.0


def test_a_tiny_jump_on_a_tiny_sigma_is_not_said():
    t, mean, sigma = _rows(sig=1e-4)
    mean[30:, S.Y] += 0.15                           # 1000 sigma, but under REVISION_MIN
    assert revision_warnings("ekf", t, mean, sigma) == []


def _weak_yard(seed):
    """yard, 150 s, 10 m fixes at 0.2 Hz, no [initial] (benchmarks/weak_gps.py's online case)."""
    from dataclasses import replace
    from odomgraph.sim.faults import Faults, inject
    from odomgraph.sim.scenarios import yard
    base = yard(150.0)
    sc = base.with_(robot=base.robot.with_(gps_sigma=10.0), rates=replace(base.rates, gps=0.2))
    return inject(sc, Faults(), seed)


def _far_rows(log, rows) -> int:
    ex = np.abs(rows.mean[:, S.X] - log.truth.at("x", rows.t)) / rows.sigma[:, S.X]
    ey = np.abs(rows.mean[:, S.Y] - log.truth.at("y", rows.t)) / rows.sigma[:, S.Y]
    return int(np.sum(np.maximum(ex, ey) > 6.0))


# (seed 99 runs weekly, with the slow tests: suite time)
@pytest.mark.parametrize("seed,method", [(84, "isam2"), pytest.param(99, "isam2", marks=pytest.mark.slow),
                                         (91, "fixed-lag")])
def test_weak_fixes_that_once_jumped_are_right_now(seed, method):
    """Seed 84 is the benchmark's; 99 and 91 were found by a scan of seeds
    90-99 after the rule was written: rows beyond 6 sigma, flagged. With
    the start settled from the first fix on (incremental: _settle_start, no
    first gate while unsettled) and the unknown heading's circle at least as
    wide as a row's distance from the fixes' mean (heading.widen_rows) they
    are inside their sigma (84: z 2.4, 71 m off before the heading shows;
    91: z 1.3 at 4.8 m), and nothing is said."""
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import estimate
    from odomgraph.result import status_of
    log = _weak_yard(seed)
    est = estimate(log, method, Schedule(20.0), fit_noise=False)
    rows = est.online if method == "isam2" else est
    assert _far_rows(log, rows) == 0
    assert status_of(est)[0] == "ok", est.flags


def _late_sparse_fix():
    """The paper log (90 s, no slip, seed 12) with fixes only from 35 s on, every 100th (0.2 Hz)."""
    from dataclasses import replace
    from tests.test_late_first_fix import late_fix_log
    log = late_fix_log(12, 35.0)
    g = log.gps
    extra = {"sigma": g.sigma[::100]} if g.sigma is not None else {}
    return log.with_(gps=replace(g, t=g.t[::100], x=g.x[::100], y=g.y[::100], **extra))


def test_causal_rows_far_outside_sigma_are_flagged():
    """isam2's causal rows after a first fix 35 s into the drive, the fixes
    then at 0.2 Hz (a hostile probe of the tenth session): a row 20 m off at
    z 93, revised 4.4 m (48 sigma) by the next: flagged. (The smoothed rows
    are right, 0.5 m at z 2.2.)"""
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import estimate
    from odomgraph.result import status_of
    log = _late_sparse_fix()
    est = estimate(log, "isam2", Schedule(20.0), fit_noise=False, keyframe_hz=5.0)
    assert _far_rows(log, est.online) >= 1                     # the case: a row far outside its sigma
    said = [w for w in est.flags if "landed further from the one before" in w]
    assert len(said) == 1 and status_of(est)[0] == "degraded", est.flags


@pytest.mark.parametrize("seed,method", [(93, "fixed-lag"), pytest.param(94, "isam2", marks=pytest.mark.slow), (95, "ekf")])
def test_weak_fixes_with_honest_rows_say_nothing(seed, method):
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import estimate
    log = _weak_yard(seed)
    est = estimate(log, method, Schedule(20.0), fit_noise=False)
    rows = est.online if method == "isam2" else est
    assert _far_rows(log, rows) == 0
    assert not [w for w in est.warnings if "landed further" in w], est.warnings


def test_calibrate_refuses_a_run_whose_rows_jumped():
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import Method, calibrate
    _, rep = calibrate(_late_sparse_fix(), Schedule(20.0), Method.isam2, tune=False, fit_noise=False,
                       keyframe_hz=5.0)
    assert any("landed further from the one before" in w for w in rep["problems"]), rep["problems"]
