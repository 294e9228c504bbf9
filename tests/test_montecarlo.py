"""The Monte-Carlo study (paper sec. VI): the vectorised EKF equals the one-run
EKF, sweeps resume without losing work, Dask gives the local pool's results,
and the paper's qualitative findings are checked on our own numbers."""
import json

import numpy as np
import pytest
from typer.testing import CliRunner

from odomgraph.analysis import montecarlo as mc
from odomgraph.analysis.montecarlo import PointSpec, StudySpec, run_point, run_study
from odomgraph.analysis.montecarlo_report import write_outputs
from odomgraph.cli import app
from odomgraph.errors import EstimatorDivergedError, OdomgraphError
from odomgraph.estimators.ekf import EKFOptions, run_ekf
from odomgraph.estimators.ekf_many import run_ekf_many
from odomgraph.estimators.schedule import Hold, Schedule
from odomgraph.io.log import Gyro
from odomgraph.sim.sensor_configs import study_scenario
from odomgraph.sim.simulate import simulate


@pytest.mark.parametrize("config,x,y,hold,gate", [(1, 0.3, 0.02, Hold.consider, None),
                                                  (2, 0.1, 0.05, Hold.pseudo, 16.0),
                                                  (3, 0.1, 0.02, Hold.consider, 9.0)])
def test_vectorised_ekf_equals_one_run_at_a_time(config, x, y, hold, gate):
    sc = study_scenario(config, x, y, duration=40.0)
    logs = [simulate(sc, s, timing_seed=11) for s in range(4)]
    sch, opt = Schedule(20.0, hold), EKFOptions(gate=gate)
    many = run_ekf_many(logs, sch, opt)
    for log, b in zip(logs, many):
        a = run_ekf(log, sch, opt)
        np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.sigma, a.sigma, rtol=0, atol=1e-9)
        np.testing.assert_array_equal(b.t, a.t)
        np.testing.assert_allclose(b.calibration_sigma, a.calibration_sigma, atol=1e-12)
        for k in a.innovations:
            np.testing.assert_allclose(b.innovations[k].nis, a.innovations[k].nis, rtol=1e-6, atol=1e-9)
        assert b.notes == a.notes and b.n_updates == a.n_updates


@pytest.mark.parametrize("span,hold", [((25.0, 27.0), 30.0), ((22.0, 35.0), 30.0), ((22.0, 80.0), 5.0)])
def test_vectorised_ekf_equals_one_run_at_a_time_through_gps_jumps(span, hold):
    """A multipath burst (3.6 m, in some runs only) is held out per run as in
    EKF.run: the same rejections, the same rows."""
    from dataclasses import replace
    sc = study_scenario(1, 0.1, 0.02, duration=40.0)
    logs = [simulate(sc, s, timing_seed=5) for s in range(4)]
    for j in (1, 2):
        g = logs[j].gps
        on = (g.t >= span[0]) & (g.t <= span[1] + j)
        logs[j] = logs[j].with_(gps=replace(g, x=np.where(on, g.x + 3.0, g.x), y=np.where(on, g.y - 2.0, g.y)))
    sch, opt = Schedule(20.0), EKFOptions(jump_hold=hold)
    many = run_ekf_many(logs, sch, opt)
    for j, (log, b) in enumerate(zip(logs, many)):
        a = run_ekf(log, sch, opt)
        np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.sigma, a.sigma, rtol=0, atol=1e-9)
        assert b.rejected == a.rejected and b.recoveries == a.recoveries
        assert b.held_out.keys() == a.held_out.keys()
        for k in a.held_out:
            np.testing.assert_array_equal(b.held_out[k], a.held_out[k])
        if span[1] - span[0] > opt.jump_hold:     # a new level: not held out for ever
            if j in (1, 2):           # fixes are used again within the hold (P grows, or the hold ends)
                used = a.innovations["gps"].t
                assert np.any(used > span[0] + opt.jump_hold), used
                assert a.held_out["gps"].max() <= span[0] + opt.jump_hold + 1.0
                assert any("did not come back in 5 s; re-acquiring it" in r for r in a.recoveries), a.recoveries
            continue
        if j in (1, 2):    # the burst is rejected whole, and the path stays within its sigma
            n_burst = int(np.sum((log.gps.t >= span[0]) & (log.gps.t <= span[1] + j)))
            assert a.rejected.get("gps", 0) >= n_burst - 2
            err = np.hypot(a.mean[:, 0] - log.truth.at("x", a.t), a.mean[:, 1] - log.truth.at("y", a.t))
            assert np.all(err <= 4.0 * np.hypot(a.sigma[:, 0], a.sigma[:, 1]) + 0.01)


def test_a_diverging_run_is_reported_and_the_others_go_on():
    sc = study_scenario(1, 0.1, 0.02, duration=40.0)
    logs = [simulate(sc, s, timing_seed=3) for s in range(3)]
    # A gyro reading 3x the yaw rate: the track scale leaves any plausible
    # range within seconds (a GPS jump is re-acquired by the gate, and wheels
    # spinning in the window are caught by the slip check, so neither diverges).
    g = logs[1].gyro
    bad = logs[1].with_(gyro=Gyro(g.t, g.omega * 3.0))
    logs[1] = bad
    out = run_ekf_many(logs, Schedule(20.0))
    with pytest.raises(EstimatorDivergedError) as one:
        run_ekf(bad, Schedule(20.0))
    assert isinstance(out[1], EstimatorDivergedError) and str(out[1]) == str(one.value)
    for j in (0, 2):
        np.testing.assert_allclose(out[j].mean, run_ekf(logs[j], Schedule(20.0)).mean, atol=1e-9)


def test_vectorised_ekf_refuses_logs_with_different_timestamps():
    sc = study_scenario(1, 0.1, 0.02, duration=30.0)
    with pytest.raises(ValueError, match="timestamps differ|start at different times"):
        run_ekf_many([simulate(sc, 1, timing_seed=1), simulate(sc, 2, timing_seed=2)])


SMALL = StudySpec(1, (0.05, 1.0), (0.01, 0.2), runs=3, duration=35.0, seed=4, smoother=True)


@pytest.fixture(scope="module")
def small_study(tmp_path_factory):
    d = tmp_path_factory.mktemp("mc") / "study"
    return d, run_study(SMALL, d, workers=2)


# (low, high) of each grid point's median RMS error, per GPS sigma of SMALL
# (its row i), estimator and quantity, about 2-3x around the values measured
# on SMALL (seed 4; the two gyro sigmas of a row measured alike, both given).
# Scale factors at 0.05 m GPS get no lower bound: their medians over 3 runs
# range over 10x (per run 4e-5 .. 4e-3) and may legitimately be tiny.
MEDIAN_BOUNDS = {
    (0, "ekf"): {"scale_left": (0, 0.002),             # measured 0.00079, 0.00039
                 "scale_right": (0, 0.0025),           # measured 0.00053, 0.0010
                 "scale_track": (0, 0.0035),           # measured 0.00011, 0.0014
                 "slip_left": (0.05, 0.25),            # measured 0.099, 0.107 m/s
                 "slip_right": (0.05, 0.25)},          # measured 0.098, 0.104 m/s
    (0, "batch"): {"scale_left": (0, 0.004),           # measured 0.0012, 0.0016
                   "scale_right": (0, 0.005),          # measured 0.00092, 0.0021
                   "scale_track": (0, 0.005),          # measured 0.0016, 0.0021
                   "slip_left": (0.015, 0.09),         # measured 0.035, 0.036 m/s
                   "slip_right": (0.015, 0.09)},       # measured 0.036, 0.035 m/s
    (1, "ekf"): {"scale_left": (0.03, 0.25),           # measured 0.075, 0.094
                 "scale_right": (0.03, 0.25),          # measured 0.071, 0.086
                 "scale_track": (0.03, 0.25),          # measured 0.073, 0.100
                 "slip_left": (0.08, 0.4),             # measured 0.167, 0.162 m/s
                 "slip_right": (0.08, 0.4)},           # measured 0.164, 0.166 m/s
    (1, "batch"): {"scale_left": (0.012, 0.11),        # measured 0.044, 0.034
                   "scale_right": (0.012, 0.11),       # measured 0.042, 0.035
                   "scale_track": (0.01, 0.11),        # measured 0.043, 0.029
                   "slip_left": (0.06, 0.33),          # measured 0.126, 0.123 m/s
                   "slip_right": (0.06, 0.33)},        # measured 0.127, 0.135 m/s
}


def test_point_results_are_deterministic_and_scored(small_study):
    d, res = small_study
    assert [(r.i, r.j) for r in res] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    again = run_point(PointSpec(SMALL, 1, 0))
    assert again.scores == res[2].scores
    for r in res:
        assert set(r.scores) == {"ekf", "batch"} and all(len(v) == 3 for v in r.scores.values())
        assert r.failure_rate("ekf") == 0 and r.failure_rate("batch") == 0
        for est in ("ekf", "batch"):
            med = r.medians(est)
            for q in mc.QUANTITIES:
                lo, hi = MEDIAN_BOUNDS[r.i, est][q]
                assert lo < med[q] < hi, (r.x, r.y, est, q, med[q])
    # GPS at 0.05 m against 1 m: every scale factor's error is far smaller
    # (measured ratio 0.011 EKF, 0.028 batch).
    assert res[0].medians("ekf")["scale_left"] < 0.03 * res[2].medians("ekf")["scale_left"]
    assert res[0].medians("batch")["scale_left"] < 0.07 * res[2].medians("batch")["scale_left"]
    # ...and with good GPS the smoother's slip is far better than the filter's
    # (measured 0.035 against 0.099 m/s, ratio 0.35 on both wheels and both gyros).
    for r in res[:2]:
        for q in ("slip_left", "slip_right"):
            assert r.medians("batch")[q] < 0.5 * r.medians("ekf")[q], (r.y, q)


def test_an_interrupted_sweep_resumes_without_losing_work(small_study, tmp_path, monkeypatch):
    import shutil
    d, res = small_study
    resumed = tmp_path / "study"
    shutil.copytree(d, resumed)
    (resumed / "points" / "c1_x0_y1.json").unlink()                   # never finished
    (resumed / "points" / "c1_x1_y1.json").write_text('{"config": 1, "i"')  # cut off mid-write
    calls = []
    real = mc.run_point
    monkeypatch.setattr(mc, "run_point", lambda p: calls.append(p.key) or real(p))
    seen = []
    out = run_study(SMALL, resumed, workers=1, progress=lambda done, total: seen.append((done, total)))
    assert sorted(calls) == ["c1_x0_y1", "c1_x1_y1"]
    assert seen[0] == (2, 4) and seen[-1] == (4, 4)
    assert [r.scores for r in out] == [r.scores for r in res]
    with pytest.raises(OdomgraphError, match="different study"):
        run_study(StudySpec(1, (0.05, 1.0), (0.01, 0.2), runs=4, duration=35.0, seed=4), resumed)
    (tmp_path / "foreign").mkdir()
    (tmp_path / "foreign" / "notes.txt").write_text("mine")
    with pytest.raises(OdomgraphError, match="not written by odomgraph"):
        run_study(SMALL, tmp_path / "foreign")


def test_dask_local_cluster_gives_the_local_pool_results(small_study, tmp_path):
    distributed = pytest.importorskip("distributed")
    _, res = small_study
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cl, \
            distributed.Client(cl) as client:
        out = run_study(SMALL, tmp_path / "dask", client=client)
    assert [(r.i, r.j, r.scores) for r in out] == [(r.i, r.j, r.scores) for r in res]


def test_outputs_and_cli(small_study, tmp_path):
    d, res = small_study
    files = write_outputs(SMALL, res, d)
    assert sorted(p.name for p in files) == ["heatmap_config1.png", "results.csv", "results.json", "summary.html"]
    lines = (d / "results.csv").read_text().splitlines()
    assert lines[0] == ("config,estimator,gps_sigma,gyro_sigma,runs,failures,failure_rate,median_rms_scale_left,"
                        "median_rms_scale_right,median_rms_scale_track,median_rms_slip_left,median_rms_slip_right")
    assert len(lines) == 1 + 4 * 2
    first = lines[1].split(",")
    assert first[:7] == ["1", "ekf", "0.05", "0.01", "3", "0", "0"]
    assert float(first[7]) == pytest.approx(res[0].medians("ekf")["scale_left"], rel=1e-5)
    j = json.loads((d / "results.json").read_text())
    assert j["study"]["runs"] == 3 and len(j["points"]) == 4
    page = (d / "summary.html").read_text()
    assert "from 1.5 m to 0.05 m GPS" in page and "href='heatmap_config1.png'" in page
    assert all(f"<div id='heat-{k}' class='plot'>" in page for k in range(4))
    # the interactive heatmaps carry the medians (in %) the results table has, and hover says the failures
    from odomgraph.analysis.montecarlo_report import heatmap_specs
    fid, _, fig = heatmap_specs(SMALL, res)[0]
    ekf = fig["data"][0]
    assert ekf["name"] == "ekf" and fid == "heat-0"
    assert ekf["z"][0][0] == pytest.approx(100 * res[0].medians("ekf")["scale_left"], rel=1e-3)
    assert "failed 0% of 3 runs" in ekf["text"][0][0]
    r = CliRunner().invoke(app, ["montecarlo", "--config", "4", "-o", str(tmp_path / "x")])
    assert r.exit_code == 1 and r.output.strip() == "odomgraph: error: --config must be 1, 2 or 3, got 4"


# ---------------------------------------------------- the paper's findings (EKF)
def _ekf_medians(config, xs, ys, runs=24, quantity="scale_track"):
    spec = StudySpec(config, tuple(xs), tuple(ys), runs=runs, duration=60.0, seed=1, smoother=False)
    res = [run_point(p) for p in spec.points()]
    assert all(r.failure_rate("ekf") == 0 for r in res)
    return np.array([r.medians("ekf")[quantity] for r in res]).reshape(len(xs), len(ys))


def test_config1_track_width_degrades_with_gyro_noise_when_gps_is_poor():
    """Paper: track width degrades once the gyro sigma passes ~0.05 rad/s. Ours:
    it degrades with gyro noise only where GPS is poor; with 0.05 m GPS at 10 Hz
    the lever arm gives heading and gyro noise hardly matters (README)."""
    g = _ekf_medians(1, (0.05, 1.5), (0.005, 0.05, 0.25))
    poor, good = g[1], g[0]
    # measured (seed 1, 24 runs): poor 0.101, 0.102, 0.144; good 0.0019, 0.0025, 0.0030
    assert poor[2] > 1.2 * poor[0] and poor[2] > poor[1]          # measured ratio 1.42
    assert 0.04 < poor[0] < 0.25
    assert good[2] < 2.0 * good[0] and good.max() < 0.004         # measured ratio 1.61


def test_config1_ticks_per_metre_error_follows_gps_noise():
    """Paper: 1.5 m -> 0.05 m GPS improves ticks/m about 2x. Ours: the 20 s
    calibration is GPS-limited, so the error scales with GPS sigma (far more
    than 2x; README)."""
    left = _ekf_medians(1, (0.05, 0.5, 1.5), (0.01,), quantity="scale_left")[:, 0]
    # measured (seed 1, 24 runs): 0.0016, 0.034, 0.112
    assert left[0] < left[1] < left[2]
    assert left[2] / left[0] > 30                                 # measured 72
    assert left[0] < 0.004
    assert 0.05 < left[2] < 0.2  # the paper: "below approximately 5-10 %"


def test_config2_beats_config1_on_track_width():
    """Paper: with a velocity sensor the track-width error is much lower."""
    c1 = _ekf_medians(1, (0.6,), (0.05,))[0, 0]
    c2 = _ekf_medians(2, (0.6,), (0.05,))[0, 0]
    assert c2 < 0.35 * c1                       # measured 0.0087 against 0.054 (ratio 0.16)


def test_vectorised_ekf_equals_one_run_at_a_time_with_a_pinned_common_scale():
    """Wheels and gyro without fixes: the common scale is pinned, and both
    filters keep the encoder gain off it and off the common direction alike
    (ekf.held_directions)."""
    from odomgraph.estimators.ekf import EKF, EKFOptions
    from odomgraph.estimators.ekf_many import run_ekf_many
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.sim.scenarios import yard
    from odomgraph.sim.simulate import simulate
    logs = [simulate(yard(50.0), s, timing_seed=8).with_(gps=None) for s in (81, 82)]
    for log, many in zip(logs, run_ekf_many(logs, Schedule(20.0), EKFOptions())):
        one = EKF(log, Schedule(20.0), EKFOptions()).run()
        assert "scale_common" in one.observability.unobservable
        np.testing.assert_allclose(many.mean, one.mean, rtol=0, atol=1e-9)
