"""A filter's rows at a measurement's time are its prediction.

A probe's log with GPS at 0.2 Hz (5 s of dead reckoning between fixes, 18
accepted, fewer than noise.MIN_COUNT innovations): the fixes lay 16x
further from the EKF's rows than the 0.02 m GPS sigma claimed, the run
widened the sigma 16x (its rows then held), and ``calibrate --method ekf``
wrote 0.317 m to robot.toml as the GPS's sigma; batch measured the sensor
right. Now such a scale is marked as measured from predictions
(analysis.noise.measured_from): the widening stays this run's, is said, and
is not written back. Dense fixes with a sigma configured 4x too small are
still measured from the innovations and written.

Logs here: other scenarios, seeds and rates than the probe's (the yard at
0.2 Hz, seed 3).
"""
from __future__ import annotations

import numpy as np
import pytest

from odomgraph.pipeline import Method, Schedule, calibrate, estimate
from odomgraph.sim.scenarios import Rates, paper, yard
from odomgraph.sim.simulate import simulate


def _log(sc, seed: int, gps_hz: float, sigma_factor: float = 1.0):
    sc = sc.with_(rates=Rates(encoders=sc.rates.encoders, gyro=sc.rates.gyro, gps=gps_hz, truth=25.0))
    log = simulate(sc, seed)
    return log.with_(robot=log.robot.with_(gps_sigma=log.robot.gps_sigma * sigma_factor))


@pytest.mark.parametrize("sc, seed, hz", [pytest.param(yard(120.0), 5, 0.2, marks=pytest.mark.slow), (paper(120.0), 4, 0.2)],
                         ids=["yard-0.2Hz", "paper-0.2Hz"])
def test_sparse_fixes_widening_is_not_written_back(sc, seed, hz, tmp_path):
    log = _log(sc, seed, hz)
    est = estimate(log, Method.ekf, Schedule(20.0))
    g = est.noise_scales["gps"]
    # the run widened the fixes (its rows need it: the dead reckoning
    # between them is what scatters) and says why it is not the sensor
    assert g["applied"] > 10.0
    assert g["from"] == "predictions"
    assert any("calibrate does not write it back" in w for w in est.warnings)
    assert not any(w.startswith("gps:") and "(calibrate writes it back)" in w for w in est.warnings)
    robot, report = calibrate(log, Schedule(60.0), Method.ekf, tune=False)
    assert robot.gps_sigma == log.robot.gps_sigma
    assert any(w.startswith("gps: sigma not written") for w in report["warnings"])


def test_dense_fixes_too_small_sigma_still_written():
    # 10 Hz fixes, robot.toml's sigma a quarter of the simulated one
    log = _log(paper(90.0), 12, 10.0, 0.25)
    est = estimate(log, Method.ekf, Schedule(20.0))
    g = est.noise_scales["gps"]
    assert g["from"] == "innovations"
    assert 2.5 < g["applied"] < 6.0
    robot, report = calibrate(log, Schedule(20.0), Method.ekf, tune=False)
    assert robot.gps_sigma == pytest.approx(log.robot.gps_sigma * g["applied"], rel=0.05)
    assert not any(w.startswith("gps: sigma not written") for w in report["warnings"])


def test_smoother_measures_residuals():
    log = _log(yard(60.0), 7, 5.0, 0.25)
    est = estimate(log, Method.batch, Schedule(20.0))
    assert est.noise_scales["gps"]["from"] == "residuals"
    assert est.noise_scales["gps"]["applied"] > 2.0
    assert np.isfinite(est.mean).all()


def test_process_noise_kept_unless_beaten_beyond_chance():
    from odomgraph.pipeline import _beats
    rng = np.random.default_rng(3)
    t = np.arange(40.0)
    base = np.abs(rng.normal(0.0, 7.6, 40))
    # 1 % better on average, with errors as scattered as the held-out fixes of a lost filter
    noisy = (t, base * 0.99 + rng.normal(0.0, 1.0, 40))
    assert not _beats(noisy, (t, base))
    assert _beats((t, base * 0.5), (t, base))
    # only the fixes both runs predicted are paired; two are too few to say
    assert not _beats((t[:2], base[:2] * 0.5), (t, base))


@pytest.mark.slow   # (31 s; test_sparse_fixes_widening_is_not_written_back holds the claim on paper at 0.2 Hz)
def test_sparse_fixes_calibrate_keeps_default_process_noise():
    """The EKF on every other 0.2 Hz fix is lost for every candidate (held-out
    errors of 7 m): calibrate wrote 40x the default for 6 % less, and said
    nothing of the filter being lost."""
    from dataclasses import replace
    from odomgraph.pipeline import PROCESS_NOISE_LOST
    log = _log(yard(120.0), 6, 0.2)
    # robot.toml's own process noise (not a candidate's) is what is kept
    mine = replace(log.robot.process, accel=0.33, yaw_accel=0.44)
    log = log.with_(robot=log.robot.with_(process=mine))
    robot, report = calibrate(log, Schedule(60.0), Method.ekf)
    pn = report["process_noise"]
    rms = [r["rms_m"] for r in pn["held_out_rms_m"]]
    assert len(rms) >= 3 and min(rms) > PROCESS_NOISE_LOST * log.robot.gps_sigma
    assert pn["lost_m"] == min(rms)
    assert (robot.process.accel, robot.process.yaw_accel) == (0.33, 0.44)
    assert any(w.startswith("process noise not tuned") for w in report["warnings"])


def test_sigma_set_too_small_is_not_a_lost_estimator():
    """Batch on 1 Hz fixes whose robot.toml sigma is 100x too small: the
    held-out errors are 100 configured sigmas, but the runs measured and
    widened the sigma, and the tuning goes on."""
    from odomgraph.pipeline import PROCESS_NOISE_LOST
    log = _log(paper(90.0), 13, 1.0, 0.01)
    robot, report = calibrate(log, Schedule(20.0), Method.batch)
    pn = report["process_noise"]
    assert min(r["rms_m"] for r in pn["held_out_rms_m"]) > PROCESS_NOISE_LOST * log.robot.gps_sigma
    assert pn["lost_m"] is None
    assert not any(w.startswith("process noise not tuned") for w in report["warnings"])
