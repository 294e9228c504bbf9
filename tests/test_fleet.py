"""Fleets (issue 17): estimate and calibrate over several logs, or a directory
of logs, in one command, on a process pool or a Dask cluster. Each log's
output equals the one-at-a-time command's; a bad log fails alone and says so."""
import csv
import math
import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from odomgraph.cli import app
from odomgraph.estimators.schedule import Schedule
from odomgraph.fleet import log_dirs, output_names, run_fleet
from odomgraph.io.log import write_log
from odomgraph.sim.scenarios import Rates, paper, yard
from odomgraph.sim.simulate import simulate

runner = CliRunner()
#: summary.json keys that measure the run, not the estimate.
TIMING = ("wall_time_s", "updates_per_second", "update_time_ms", "log")


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def robots(tmp_path_factory):
    """A directory of three robots' logs: other seeds, rates and geometry."""
    d = tmp_path_factory.mktemp("fleet") / "robots"
    scenarios = {"r1": paper(40.0), "r2": yard(40.0),
                 "r3": paper(40.0).with_(rates=Rates(encoders=10.0, gyro=50.0, gps=2.0))}
    for k, (name, sc) in enumerate(scenarios.items()):
        write_log(simulate(sc, 70 + k), d / name)
    (d / "notes.txt").write_text("not a log\n")
    return d


def _same_estimate(a: Path, b: Path) -> None:
    assert (a / "states.csv").read_bytes() == (b / "states.csv").read_bytes()
    sa, sb = (json.loads((p / "summary.json").read_text()) for p in (a, b))
    for k in TIMING:
        sa.pop(k, None)
        sb.pop(k, None)
    assert sa == sb


def test_a_directory_of_logs_equals_one_log_at_a_time(tmp_path, robots):
    res = run("estimate", robots, "--method", "batch", "--workers", "2", "-o", tmp_path / "fleet")
    assert res.exit_code == 0, res.output
    for name in ("r1", "r2", "r3"):
        one = tmp_path / f"one-{name}"
        assert run("estimate", robots / name, "--method", "batch", "-o", one).exit_code == 0
        _same_estimate(tmp_path / "fleet" / name, one)
    rows = list(csv.DictReader((tmp_path / "fleet" / "fleet.csv").open()))
    assert [r["name"] for r in rows] == ["r1", "r2", "r3"] and {r["result"] for r in rows} == {"written"}
    s1 = json.loads((tmp_path / "fleet" / "r1" / "summary.json").read_text())
    assert float(rows[0]["scale_track"]) == s1["calibration"]["scale_track"]["value"]     # full precision
    assert "3 of 3 logs done" in res.stdout


def test_a_bad_log_fails_alone_and_says_why(tmp_path, robots):
    logs = tmp_path / "logs"
    shutil.copytree(robots, logs)
    enc = logs / "r2" / "encoders.csv"
    lines = enc.read_text().splitlines()
    lines[5] = "oops,1,2"
    enc.write_text("\n".join(lines) + "\n")
    res = run("estimate", logs / "r1", logs / "r2", logs / "r3", "-o", tmp_path / "out")
    assert res.exit_code == 1 and "Traceback" not in res.output
    err = [ln for ln in res.stderr.splitlines() if ln.startswith("odomgraph: error:")]
    assert len(err) == 1 and "r2:" in err[0] and "encoders.csv:6:" in err[0], res.stderr
    rows = {r["name"]: r for r in csv.DictReader((tmp_path / "out" / "fleet.csv").open())}
    assert rows["r2"]["result"] == "failed" and "encoders.csv" in rows["r2"]["error"]
    assert rows["r1"]["result"] == rows["r3"]["result"] == "written"
    assert (tmp_path / "out" / "r1" / "states.csv").exists() and not (tmp_path / "out" / "r2").exists()


def test_calibrate_a_fleet_writes_each_robots_toml_as_alone(tmp_path, robots):
    res = run("calibrate", robots / "r1", robots / "r2", "--no-tune", "--force", "--workers", "1",
              "-o", tmp_path / "cal")
    assert res.exit_code == 0, res.output
    for name in ("r1", "r2"):
        alone = tmp_path / f"{name}.toml"
        assert run("calibrate", robots / name, "--no-tune", "--force", "-o", alone).exit_code == 0
        assert (tmp_path / "cal" / f"{name}.toml").read_text() == alone.read_text()
    rows = json.loads((tmp_path / "cal" / "fleet.json").read_text())["logs"]
    assert [r["name"] for r in rows] == ["r1", "r2"]
    assert all(r["ticks_per_meter_left"] > 0 and r["track_width"] > 0 for r in rows)


def test_a_fleet_on_a_dask_cluster_equals_the_local_run(tmp_path, robots):
    distributed = pytest.importorskip("dask.distributed")
    sch = Schedule(20.0)
    local = run_fleet([robots], tmp_path / "local", "estimate", "ekf", sch, workers=1)
    # a worker process of its own: the job and its files cross a pickle, as to a remote machine
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        remote = run_fleet([robots], tmp_path / "dask", "estimate", "ekf", sch, client=client)
    assert [r["name"] for r in remote] == [r["name"] for r in local] == ["r1", "r2", "r3"]
    for name in ("r1", "r2", "r3"):
        _same_estimate(tmp_path / "dask" / name, tmp_path / "local" / name)


def test_logs_are_found_named_and_never_overwritten(tmp_path, robots):
    a, b = tmp_path / "a", tmp_path / "b"
    shutil.copytree(robots / "r1", a / "run1")
    shutil.copytree(robots / "r2", b / "run1")
    found = log_dirs([a, b])
    assert found == [a / "run1", b / "run1"] and output_names(found) == ["a_run1", "b_run1"]
    res = run("estimate", robots, "-o", robots / "r1")
    assert res.exit_code == 1 and "input" in res.stderr and (robots / "r1" / "encoders.csv").exists()
    res = run("estimate", tmp_path / "nothing-here", robots / "r1", "-o", tmp_path / "x")
    assert res.exit_code == 1 and "no such log directory" in res.stderr and not (tmp_path / "x").exists()
    res = run("estimate", robots / "r1", "--workers", "2", "-o", tmp_path / "y")
    assert res.exit_code == 1 and "for a fleet" in res.stderr


def test_a_fleet_where_every_log_fails_writes_nothing(tmp_path, robots):
    bad = tmp_path / "bad"
    for name in ("r1", "r2"):
        shutil.copytree(robots / name, bad / name)
        (bad / name / "encoders.csv").write_text("t,ticks_left,ticks_right\n0,1\n")
    (tmp_path / "out").mkdir()
    res = run("estimate", bad, "-o", tmp_path / "out")
    assert res.exit_code == 1 and "every one of the 2 logs failed" in res.stderr, res.output
    assert list((tmp_path / "out").iterdir()) == []
    res = run("estimate", robots, "--rate", "-3", "-o", tmp_path / "out")     # checked once, before any log
    assert res.exit_code != 0 and not list((tmp_path / "out").iterdir())
    # another estimator's option: one line before any log is read (a second read found it failed every log)
    res = run("estimate", robots, "--method", "ekf", "--keyframe-hz", "2", "-o", tmp_path / "out")
    assert res.exit_code == 1 and not list((tmp_path / "out").iterdir()), res.output
    assert res.stderr.strip() == ("odomgraph: error: keyframe_hz (--keyframe-hz) is an option of batch, isam2, "
                                  "fixed-lag, not of ekf"), res.stderr
    res = run("calibrate", robots / "r1", robots / "r2", "-o", tmp_path / "cal.toml")
    assert res.exit_code == 1 and "a fleet writes a directory" in res.stderr


def test_names_are_unique_hidden_entries_skipped_and_reserved_names_avoided(tmp_path, robots):
    shutil.copytree(robots / "r1", tmp_path / "d" / "Run1")
    shutil.copytree(robots / "r2", tmp_path / "d" / "run1")
    shutil.copytree(robots / "r3", tmp_path / "d" / ".run1.tmp-123-abcd")    # a killed import's temporary
    shutil.copytree(robots / "r3", tmp_path / "e" / "fleet")
    found = log_dirs([tmp_path / "d", tmp_path / "e"])
    assert [p.name for p in found] == ["Run1", "run1", "fleet"]
    names = output_names(found)
    assert names == ["d_Run1", "d_run1_", "log_fleet"]
    assert len({n.casefold() for n in names}) == 3
    import os
    cwd = os.getcwd()
    try:
        os.chdir(robots / "r1")
        assert output_names(log_dirs(["."])) == ["r1"]
    finally:
        os.chdir(cwd)


def test_a_fleet_output_inside_its_directory_of_logs_is_refused(tmp_path, robots):
    """A probe's `estimate fleet -o fleet/out` wrote its output among the logs
    (a single log's inside is refused alike); a calibrate fleet's refusal
    named its temporary file, not the robot's."""
    logs = tmp_path / "logs"
    shutil.copytree(robots, logs)
    before = sorted(p.relative_to(logs).as_posix() for p in logs.rglob("*"))
    res = run("estimate", logs, "-o", logs / "out")
    assert res.exit_code == 1 and "inside the input" in res.stderr and "Traceback" not in res.output, res.output
    assert sorted(p.relative_to(logs).as_posix() for p in logs.rglob("*")) == before
    # r2 with its gyro on another axis: its calibration is refused, named as in the output
    g = (logs / "r2" / "gyro.csv").read_text().splitlines()
    # (a small wobble, not all zeros: a dead gyro is refused as bad input, pipeline._refuse_units)
    (logs / "r2" / "gyro.csv").write_text("\n".join(
        [g[0], *(f"{ln.split(',')[0]},{0.01 * math.sin(17.0 * float(ln.split(',')[0])):.6f}" for ln in g[1:])])
        + "\n")
    res = run("calibrate", logs / "r1", logs / "r2", "--no-tune", "--workers", "1", "-o", tmp_path / "cal")
    rows = {r["name"]: r for r in csv.DictReader((tmp_path / "cal" / "fleet.csv").open())}
    assert rows["r2"]["result"] == "failed", rows["r2"]
    assert rows["r2"]["error"].startswith("r2.toml not written:") and "odomgraph-fleet-" not in rows["r2"]["error"]
