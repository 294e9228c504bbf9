"""Issue 12's cases at the top of the issue, each on a simulated log the
estimators were not designed around: every one ends in a result within its
sigma or a flagged one, never a silent wrong one."""
from dataclasses import replace

import numpy as np
import pytest

from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import Method, calibrate, estimate, warnings_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import Rates, Segment, paper, yard

NAMES = ("scale_left", "scale_right", "scale_track")


def _honest(est, log, n_sigma=4.0):
    """Each scale factor within n_sigma of the truth. One the log does not
    determine carries its prior sigma (and is flagged), so this holds too."""
    cal = est.calibration
    for name, true in zip(NAMES, log.truth_scales):
        v, s = cal[name]["value"], cal[name]["sigma"]
        assert abs(v - true) <= n_sigma * s, (name, v, s, true, est.unobservable())


@pytest.mark.parametrize("n_fixes", [0, 1, 2])
@pytest.mark.parametrize("method", ["ekf", "batch"])
def test_a_log_with_almost_no_fixes_flags_the_common_scale(n_fixes, method):
    sc = yard(60.0).with_(slips=(), write_initial=True)
    log = inject(sc, Faults(), 21 + n_fixes)
    g = log.gps
    keep = np.linspace(0, len(g.t) - 1, n_fixes).astype(int) if n_fixes else np.array([], int)
    log = log.with_(gps=replace(g, t=g.t[keep], x=g.x[keep], y=g.y[keep]))
    est = estimate(log, method, Schedule(20.0))
    # a gyro is there, so ratio and track may be determined; the common scale is not
    assert "scale_common" in est.unobservable(), est.unobservable()
    assert any("scale_common is not determined" in w for w in warnings_of(est, log))
    _honest(est, log)


def test_wheels_and_imu_calibrate_ratio_and_track_and_hold_the_common_scale():
    sc = paper(90.0).with_(slips=(), write_initial=True)
    log = inject(sc, Faults(), 31).with_(gps=None)
    new, rep = calibrate(log, Schedule(None), Method.batch, tune=False)
    assert "scale_common" in rep["unobservable"]
    kl, kr, kt = (rep["scale"][w] for w in ("left", "right", "track"))
    tl, tr, tt = sc.scales
    # the common scale stays at nominal; the ratio and the track are found
    assert 0.5 * (kl + kr) == pytest.approx(1.0, abs=1e-3)
    assert kr / kl == pytest.approx(tr / tl, rel=0.01)
    assert kt / (0.5 * (kl + kr)) == pytest.approx(tt / (0.5 * (tl + tr)), rel=0.02)
    assert rep["held_out"]["kind"] == "gyro" and rep["held_out"]["passed"]
    assert any("scale_common is not determined" in w for w in rep["warnings"])


@pytest.mark.parametrize("method", ["ekf", "batch"])
def test_a_slow_robot_is_honest(method):
    """0.03 m/s: in 20 s the robot covers 0.6 m against 0.05 m fixes, and it
    does not turn before 32 s. The EKF calibrates in the 20 s window only, so
    the track is not determined there, and it says so; batch uses the whole
    log and determines all three."""
    slow = (Segment(2.0, 0.0, 0.0), Segment(30.0, 0.03, 0.0), Segment(20.0, 0.0, 0.3), Segment(30.0, 0.03, 0.02))
    sc = paper(80.0).with_(slips=(), prologue=slow, loop=(Segment(20.0, 0.03, 0.05), Segment(20.0, 0.03, -0.05)),
                           rates=Rates(encoders=20.0, gyro=25.0, gps=5.0))
    log = inject(sc, Faults(), 41)
    est = estimate(log, method, Schedule(20.0))
    _honest(est, log)
    said = " ".join(warnings_of(est, log))
    track = est.calibration["scale_track"]
    if method == "ekf":
        assert not track["observable"] and "scale_track is not determined" in said
        assert track["sigma"] == pytest.approx(log.robot.process.initial_scale_sigma, rel=0.01)
    else:
        assert all(v["observable"] for v in est.calibration.values()) and track["sigma"] < 0.02


@pytest.mark.parametrize("method,which,seed", [("ekf", "yard", 51), ("batch", "paper", 52), ("isam2", "paper", 53)])
def test_a_gps_sigma_configured_too_small_is_measured_and_widened(method, which, seed):
    """The car-log case: robot.toml says 0.05 m where the receiver scatters
    0.25 m. Taken at face value the position sigma covered the truth 3.5 %
    of the time on a real car log; the noise scale is measured from the data
    (analysis.noise), reported, and the sigma widened."""
    from odomgraph.analysis.metrics import truth_errors
    sc = (paper if which == "paper" else yard)(45.0).with_(slips=())
    real = sc.robot.with_(gps_sigma=0.25)
    log = inject(sc.with_(robot=real), Faults(), seed)
    told = log.with_(robot=log.robot.with_(gps_sigma=0.05))
    est = estimate(told, method, Schedule(20.0))
    f = est.noise_scales["gps"]
    # post-fit residuals err low (module doc), innovations do not: 3.5-6 for a true 5
    assert 3.5 < f["applied"] < 6.0, f
    assert any("gps: the data scatter" in w for w in est.warnings)
    cov = truth_errors(est, told).coverage_3sigma
    assert min(cov["x"], cov["y"]) >= 0.9, cov
    _honest(est, told)
    # the same log told the truth is left alone
    ok = estimate(log, method, Schedule(20.0))
    assert ok.noise_scales["gps"]["applied"] == 1.0 and 0.7 < ok.noise_scales["gps"]["measured"] < 1.3
