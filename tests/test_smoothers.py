"""The factor-graph smoothers (batch, iSAM2, fixed-lag) on short logs:
accuracy bounds, consistency, causality of the online estimate, and equality
with the straightforward GTSAM design."""
from dataclasses import replace

import numpy as np
import pytest

from odomgraph import state as S
from odomgraph.analysis.metrics import truth_errors
from odomgraph.estimators.batch import SmootherOptions, run_batch
from odomgraph.estimators.ekf import run_ekf
from odomgraph.estimators.incremental import IncrementalOptions, run_fixed_lag, run_isam2
from odomgraph.estimators.schedule import Schedule
from odomgraph.sim.scenarios import Rates, beacons_around, paper
from odomgraph.sim.simulate import simulate

CONSISTENCY = ("x", "y", "theta", "slip_left", "slip_right", "scale_left", "scale_right", "scale_track")


@pytest.fixture(scope="module")
def log():
    return simulate(paper(), 5)


@pytest.fixture(scope="module")
def runs(log):
    sch = Schedule(20.0)
    return {"ekf": run_ekf(log, sch), "batch": run_batch(log, sch), "isam2": run_isam2(log, sch),
            "fixed-lag": run_fixed_lag(log, sch)}


@pytest.mark.parametrize("method", ["batch", "isam2", "fixed-lag"])
def test_smoother_accuracy_and_consistency(runs, log, method):
    err = truth_errors(runs[method], log)
    ekf = truth_errors(runs["ekf"], log)
    assert err.rms_position_m < 0.02
    assert max(err.rms_slip_mps.values()) < 0.025
    # the smoother beats the paper's filter on slip by a wide margin
    assert max(err.rms_slip_mps.values()) < 0.7 * min(ekf.rms_slip_mps.values())
    for k, true in zip(("left", "right", "track"), log.truth_scales):
        assert abs(err.final_scale_error[k] / true) < 0.004
    for name in CONSISTENCY:
        assert err.coverage_3sigma[name] >= 0.95, (method, name, err.coverage_3sigma[name])
    est = runs[method]
    assert np.all(np.isfinite(est.mean)) and np.all(np.isfinite(est.sigma))
    assert np.all(np.diff(est.t) > 0)
    assert np.all(np.abs(est.mean[:, S.THETA]) <= np.pi)


def test_incremental_solvers_reach_the_batch_solution(runs):
    b = runs["batch"]
    for m in ("isam2", "fixed-lag"):
        e = runs[m]
        np.testing.assert_allclose(e.t, b.t)
        np.testing.assert_allclose(e.mean[-1, S.SCALE], b.mean[-1, S.SCALE], atol=1.5e-3)
        assert np.sqrt(np.mean((e.mean[:, S.SLIP] - b.mean[:, S.SLIP]) ** 2)) < 0.01


def test_isam2_online_is_no_worse_than_the_ekf(runs, log):
    online = truth_errors(replace(runs["isam2"].online, t_switch=runs["isam2"].t_switch), log)
    ekf = truth_errors(runs["ekf"], log)
    for w in ("left", "right"):
        assert online.rms_slip_mps[w] <= 1.05 * ekf.rms_slip_mps[w]
    assert online.rms_position_m <= 1.1 * ekf.rms_position_m
    for name in ("x", "y", "slip_left", "slip_right"):
        assert online.coverage_3sigma[name] >= 0.95


def test_online_estimate_never_uses_future_data(log, runs):
    """Truncate the log at T: every online row available by T is unchanged."""
    T = 55.0
    short = run_isam2(log.truncated(T), Schedule(20.0))
    full = runs["isam2"].online
    # row j describes interval j's midpoint; it was produced when interval j ended
    n = len(short.online.t)
    done = short.online.t + (short.online.t - np.append(log.t_start, short.online.t[:-1])) <= T
    m = min(n - 1, int(np.sum(done)))
    assert m > 200
    np.testing.assert_allclose(short.online.mean[:m], full.mean[:m], atol=1e-9)
    np.testing.assert_allclose(short.online.sigma[:m], full.sigma[:m], atol=1e-9)
    # ...while the smoothed estimate of the same times does change with later data
    assert np.abs(short.mean[:m, S.SLIP] - runs["isam2"].mean[:m, S.SLIP]).max() > 1e-4


def test_batch_equals_the_straightforward_gtsam_solution():
    """Our vectorised Gauss-Newton and GTSAM's LM over plain CustomFactors solve
    the same problem to the same answer (schedule only: no robust prior, whose
    IRLS GTSAM's LM treats differently)."""
    import gtsam
    from benchmarks.peers import _values, straightforward_graph
    from odomgraph.estimators import batch as B
    log = simulate(paper(40), 2)
    sch = Schedule(20.0)
    opt = SmootherOptions(slip_cauchy=None, robust="none")
    prob = B.build_problem(log, sch, opt)
    pose, W = B.initial_guess(prob, run_ekf(log, sch))
    ours_pose, ours_W, _, _, _, _ = B.solve(prob, pose, W, opt)
    g = straightforward_graph(prob)
    params = gtsam.LevenbergMarquardtParams()
    params.setRelativeErrorTol(1e-12)
    params.setAbsoluteErrorTol(1e-12)
    res = gtsam.LevenbergMarquardtOptimizer(g, _values(pose, W, range(prob.kf.n)), params).optimize()
    from gtsam.symbol_shorthand import W as WK, X as XK
    ref_scale = np.array([res.atVector(WK(k))[3:6] for k in range(prob.kf.n)])
    ref_xy = np.array([[res.atPose2(XK(k)).x(), res.atPose2(XK(k)).y()] for k in range(prob.kf.n)])
    np.testing.assert_allclose(ours_W[:, 5:8], ref_scale, atol=2e-6)
    np.testing.assert_allclose(ours_pose[:, 0:2], ref_xy, atol=2e-5)


def test_calibrate_until_none_estimates_scale_and_slip_together():
    log = simulate(paper(), 7)
    est = run_batch(log, Schedule(None))
    err = truth_errors(est, log)
    for k, true in zip(("left", "right", "track"), log.truth_scales):
        assert abs(err.final_scale_error[k] / true) < 0.005
    assert max(err.rms_slip_mps.values()) < 0.03
    assert err.coverage_3sigma["scale_left"] > 0.95 and err.coverage_3sigma["scale_right"] > 0.95


@pytest.mark.parametrize("sensors", ["ranges_gyro", "ranges_only", "gps_only"])
def test_smoothers_with_other_sensors(sensors):
    """Issue 5: encoders with ranges only, or with GPS only, work with every smoother."""
    sc = paper(60)
    if sensors == "gps_only":
        sc = sc.with_(rates=Rates(gyro=0, gps=20), slips=())
    else:
        sc = sc.with_(rates=Rates(gyro=25 if sensors == "ranges_gyro" else 0, gps=0, ranges=20),
                      robot=sc.robot.with_(beacons=beacons_around(0, 20, -6, 12), range_sigma=0.05))
        if sensors == "ranges_only":
            sc = sc.with_(slips=())  # without a yaw sensor a differential slip looks like a turn (README)
    log = simulate(sc, 3)
    for run in (run_batch, run_isam2, run_fixed_lag):
        err = truth_errors(run(log, Schedule(20.0)), log)
        assert err.rms_position_m < 0.05, (sensors, run.__name__)
        assert err.coverage_3sigma["x"] > 0.95 and err.coverage_3sigma["y"] > 0.95


def test_segmented_isam2_keeps_the_online_estimate_and_the_smoothed_solution(log, runs):
    """Handing over to a fresh ISAM2 every 30 s (instead of one for the whole
    log) changes nothing causal, and the backward pass recovers the smoothed
    solution to well within its uncertainty."""
    seg = run_isam2(log, Schedule(20.0), IncrementalOptions(segment=30.0))
    one = runs["isam2"]
    assert "4 segment(s)" in seg.notes[0] and "1 segment(s)" in one.notes[0]
    np.testing.assert_allclose(seg.online.mean[:140], one.online.mean[:140], atol=1e-9)  # before the first handoff
    # after it, the handoff prior is a linearisation: agreement within a small fraction of sigma
    z = np.abs(seg.online.mean - one.online.mean) / np.maximum(one.online.sigma, 1e-9)
    assert np.percentile(z[:, [S.X, S.Y, S.SLIP_L, S.SLIP_R]], 99) < 0.5
    z = np.abs(seg.mean - one.mean) / np.maximum(one.sigma, 1e-9)
    assert np.percentile(z[:, [S.X, S.Y, S.SLIP_L, S.SLIP_R, S.SCALE_L, S.SCALE_R, S.SCALE_B]], 99) < 1.0
    err = truth_errors(seg, log)
    assert max(err.rms_slip_mps.values()) < 0.025
    for name in CONSISTENCY:
        assert err.coverage_3sigma[name] >= 0.95


def test_robust_gps_survives_gross_outliers(log):
    from odomgraph.io.log import Gps
    g = log.gps
    x = g.x.copy()
    x[::50] += 8.0                       # 2 % gross errors of 8 m (160 sigma)
    bad = log.with_(gps=Gps(g.t, x, g.y))
    plain = truth_errors(run_batch(bad, Schedule(20.0), SmootherOptions(robust="none")), bad)
    clean = truth_errors(run_batch(log, Schedule(20.0)), log)
    assert plain.rms_position_m > 3 * clean.rms_position_m
    # the default loss (Cauchy at 5 sigma), and the textbook 95 %-efficiency Cauchy
    for opt in (SmootherOptions(), SmootherOptions(robust="cauchy", robust_k=2.385)):
        est = run_batch(bad, Schedule(20.0), opt)
        robust = truth_errors(est, bad)
        assert robust.rms_position_m < 1.3 * clean.rms_position_m
        assert max(robust.rms_slip_mps.values()) < 0.03
        assert est.rejected["gps"] == np.sum(g.t[::50] >= est.t[0] - 0.1)      # every outlier in the graph, nothing else


def test_keyframe_fixes_use_the_wheel_travel_inside_the_interval():
    """Nearly noise-free paper log: whatever error is left is model error. With
    fixes placed on the arc at the share of wheel travel done by their time
    (motion.arc_at) the scale factors come out within 0.01 %; placed at the
    share of *time*, as if speed were constant inside the 0.2 s interval, the
    starts and stops biased ticks/m by 0.05-0.06 %."""
    from odomgraph.estimators.batch import build_problem
    sc = paper().with_(gyro_bias=0.0, gyro_bias_walk=0.0, slips=())
    sc = sc.with_(robot=sc.robot.with_(encoder_sigma=(1e-4, 0.0), gps_sigma=2e-3, gyro_sigma=2e-4))
    log = simulate(sc, 0)
    est = run_batch(log, Schedule(20.0))
    err = est.mean[-1, 8:11] / np.array(sc.scales) - 1
    assert np.all(np.abs(err) < 1e-4), err
    kf = build_problem(log, Schedule(20.0), SmootherOptions()).kf
    g = log.gps.t[(log.gps.t >= kf.t[0]) & (log.gps.t < kf.t[-1])]   # the fixes the keyframes hold, in order
    tvw, tau = kf.gps_tau_vw, g - kf.t[kf.gps_k]                    # effective and plain time after t_k
    assert np.all((tvw >= 0) & (tvw <= kf.dt[kf.gps_k][:, None] + 1e-12))
    accel = np.abs(tvw[:, 0] - tau) > 0.01          # fixes inside intervals where the speed changes
    assert 0.02 < accel.mean() < 0.5


def test_fixed_lag_recovers_on_far_off_nominal_parameters():
    """The libRSF cut's wheel speeds are about 2x the true speeds. Fixed-lag's
    linear factors, linearised at predictions made with them, leave the
    ranges; the watch catches it, the window is re-solved, and the smoother
    carries on, saying so (it used to stop, and before that to drift off
    tens of metres)."""
    from pathlib import Path
    from odomgraph.io.importers.librsf import import_librsf
    from odomgraph.pipeline import status_of
    log = import_librsf(Path(__file__).parent / "data" / "librsf" / "Indoor_UWB_Input.txt")
    est = run_fixed_lag(log, Schedule(0.0))
    assert est.recoveries and all("re-solved" in r for r in est.recoveries)
    assert status_of(est)[0] == "recovered"
    assert truth_errors(est, log).rms_position_m < 0.45      # measured 0.30; dead reckoning 1.23 m


def test_wheel_speed_units_shrink_the_poor_gps_scale_bias():
    """With 0.34 m GPS as the only speed reference, plain random walks on the
    speeds inflate ticks/m by ~2 % (benchmarks/speed_shrinkage.py); wheel-speed
    units take a fixed share of that off on every seed, and leave a slip-only
    schedule alone."""
    from odomgraph.sim.sensor_configs import study_scenario
    sc = study_scenario(1, 0.34, 0.005)
    for seed in range(3):
        log = simulate(sc, seed)
        sch = Schedule(sc.calibrate_until)
        ekf = run_ekf(log, sch)
        units = run_batch(log, sch, SmootherOptions(), initial=ekf).mean[-1, S.SCALE] / sc.scales - 1
        plain = run_batch(log, sch, SmootherOptions(wheel_speed_units=False), initial=ekf).mean[-1, S.SCALE] \
            / sc.scales - 1
        assert np.all(plain[:2] > 0.01)                               # the bias is there...
        assert np.all(units[:2] < plain[:2] - 0.003)                  # ...and smaller, ticks/m
        assert units[2] > plain[2] + 0.003                            # and track
    log = simulate(paper(40), 1)
    a = run_batch(log, Schedule(0.0), SmootherOptions())
    b = run_batch(log, Schedule(0.0), SmootherOptions(wheel_speed_units=False))
    np.testing.assert_array_equal(a.mean, b.mean)
