"""Output safety, input validation and clean shutdown (issue 10).

Every case a hostile new user found: the command either gives a correct
result or exits 1 with one line ``odomgraph: error: ...``; no input file is
ever changed, and a refused command leaves nothing behind.
"""
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from odomgraph.cli import app
from odomgraph.io.log import read_log, write_log
from odomgraph.io.outdir import MARKER
from odomgraph.sim.scenarios import paper
from odomgraph.sim.simulate import simulate

runner = CliRunner()
DATA = Path(__file__).parent / "data"
OPTI = DATA / "optiodom"


def run(*args):
    return runner.invoke(app, [str(a) for a in args])


def one_line_error(res, *fragments):
    assert res.exit_code == 1, (res.exit_code, res.output)
    err = res.stderr.strip()
    assert err.count("\n") == 0 and err.startswith("odomgraph: error:"), err
    assert "Traceback" not in res.output and "np.float64" not in err
    for f in fragments:
        assert f in err, err
    return err


def snapshot(d: Path) -> dict[str, str]:
    """Every file under d (relative path -> sha256 of its bytes), and d's own listing."""
    out = {}
    for p in sorted(d.rglob("*")):
        out[p.relative_to(d).as_posix()] = hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
    return out


@pytest.fixture(scope="module")
def short_log(tmp_path_factory):
    """A 30 s paper log on disk (treat as read-only)."""
    d = tmp_path_factory.mktemp("short") / "log"
    write_log(simulate(paper(30.0), 1), d)
    return d


@pytest.fixture
def log_in_project(tmp_path, short_log):
    """A user's project directory: their own files beside a log."""
    proj = tmp_path / "project"
    shutil.copytree(short_log, proj / "log")
    (proj / "notes.txt").write_text("field notes\n")
    (proj / "robot.toml").write_text("# the user's own robot file\n")
    return proj


# ------------------------------------------------------------------ data loss
@pytest.mark.parametrize("args,fragment", [
    (("--checkpoint", "log/gps.csv"), "lies inside the input"),
    (("--checkpoint", "log/robot.toml"), "lies inside the input"),
    (("--checkpoint", "notes.txt"), "is not an odomgraph checkpoint"),
    (("--checkpoint", "ck.pkl", "--history", "log/gyro.csv"), "lies inside the input"),
    (("--checkpoint", "ck.pkl", "--history", "ck.pkl"), "is an input"),
    (("--history", "notes.txt"), "was not written by odomgraph"),
    (("--robot", "log/robot.toml", "--checkpoint", "log/robot.toml"), "is an input"),
])
def test_stream_files_never_replace_an_input_or_a_users_file(log_in_project, monkeypatch, args, fragment):
    """A probe's: ``stream --checkpoint log/gps.csv`` left gps.csv a pickle,
    ``--history log/gyro.csv`` a states table, ``--checkpoint notes.txt``
    overwrote the user's notes; all exited 0."""
    monkeypatch.chdir(log_in_project)
    before = snapshot(log_in_project)
    base = ("stream", "--method", "isam2") + (() if "--robot" in args else ("--replay", "log"))
    res = runner.invoke(app, [*base, *args], input="")
    one_line_error(res, fragment)
    assert snapshot(log_in_project) == before


def test_the_library_checkpoint_never_replaces_a_users_file(tmp_path, short_log):
    """Online.save goes through io.outdir: a user's file (or a NAME.tmp beside
    it) survives, and a checkpoint replaces a checkpoint."""
    from odomgraph.errors import OutputDirError
    from odomgraph.online import Online
    live = Online(read_log(short_log).robot, "ekf")
    (tmp_path / "notes.txt").write_text("field notes\n")
    (tmp_path / "ck.tmp").write_text("mine\n")
    with pytest.raises(OutputDirError, match="not written by odomgraph"):
        live.save(tmp_path / "notes.txt")
    live.save(tmp_path / "ck")
    live.save(tmp_path / "ck")
    assert (tmp_path / "notes.txt").read_text() == "field notes\n" and (tmp_path / "ck.tmp").read_text() == "mine\n"
    assert Online.is_checkpoint(tmp_path / "ck")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ck", "ck.tmp", "notes.txt"]


def test_a_stream_checkpoint_replaces_its_own_and_the_history_its_own(log_in_project, monkeypatch):
    monkeypatch.chdir(log_in_project)
    for _ in range(2):                  # the second run replaces both files the first wrote
        res = run("stream", "--replay", "log", "--method", "isam2", "--checkpoint", "ck.pkl", "--history", "h.csv")
        assert res.exit_code == 0, res.output
    from odomgraph.io.estimate import is_states_file
    from odomgraph.online import Online
    assert Online.is_checkpoint(log_in_project / "ck.pkl") and is_states_file(log_in_project / "h.csv")
    res = run("stream", "--replay", "log", "--method", "isam2", "--resume", "ck.pkl", "--checkpoint", "ck.pkl")
    assert res.exit_code == 0, res.output


@pytest.mark.parametrize("command", ["estimate", "compare"])
@pytest.mark.parametrize("where", ["the log", "its parent", "inside the log"])
def test_output_never_replaces_or_enters_an_input(log_in_project, command, where):
    log = log_in_project / "log"
    out = {"the log": log, "its parent": log_in_project, "inside the log": log / "out"}[where]
    before = snapshot(log_in_project)
    one_line_error(run(command, log, "-o", out), "input")
    assert snapshot(log_in_project) == before


@pytest.mark.parametrize("command", ["estimate", "compare"])
def test_a_directory_with_a_users_robot_toml_is_not_ours(tmp_path, short_log, command):
    # A file *named* like one of ours proves nothing: robot.toml, summary.json, ...
    user = tmp_path / "mine"
    user.mkdir()
    for name in ("robot.toml", "summary.json", "report.html", "figure.png", "results.json"):
        (user / name).write_text("the user's\n")
    (user / "thesis.tex").write_text("precious\n")
    before = snapshot(user)
    one_line_error(run(command, short_log, "-o", user), "did not write")
    assert snapshot(user) == before


def test_our_own_output_is_replaced_but_not_a_file_the_user_added(tmp_path, short_log):
    out = tmp_path / "est"
    assert run("estimate", short_log, "-o", out).exit_code == 0
    listed = json.loads((out / MARKER).read_text())["files"]
    assert sorted(listed) == ["states.csv", "summary.json", "trajectory.tum", "truth.tum"]
    assert run("estimate", short_log, "--method", "batch", "-o", out).exit_code == 0      # ours: replaced
    assert json.loads((out / "summary.json").read_text())["method"] == "batch"
    (out / "my-plot.png").write_bytes(b"user data")
    one_line_error(run("estimate", short_log, "-o", out), "my-plot.png")
    assert (out / "my-plot.png").read_bytes() == b"user data"


@pytest.mark.parametrize("command", ["estimate", "compare", "simulate", "import"])
def test_a_log_odomgraph_wrote_is_never_replaced(tmp_path, short_log, command):
    # The probe: import a bag to imp/, then "compare OTHER -o imp" replaced the
    # recording with a report (the marker listed every file, so it looked ours).
    victim = tmp_path / "imp"
    assert run("import", "rosbag", DATA / "bags" / "jackal-test2.bag", "-o", victim,
               "--track-width", "0.43").exit_code == 0
    assert json.loads((victim / MARKER).read_text())["kind"] == "log"
    before = snapshot(victim)
    args = {"estimate": ("estimate", short_log, "-o", victim),
            "compare": ("compare", short_log, "-o", victim),
            "simulate": ("simulate", "-o", victim, "--duration", "10"),
            "import": ("import", "rosbag", DATA / "bags" / "jackal-test2.bag", "-o", victim,
                       "--track-width", "0.5")}[command]
    one_line_error(run(*args), "holds a log", "never replaced")
    assert snapshot(victim) == before


def test_a_file_edited_since_odomgraph_wrote_it_is_the_users(tmp_path, short_log):
    out = tmp_path / "est"
    assert run("estimate", short_log, "-o", out).exit_code == 0
    marker = json.loads((out / MARKER).read_text())
    assert marker["sha256"]["states.csv"] == hashlib.sha256((out / "states.csv").read_bytes()).hexdigest()
    with open(out / "summary.json", "a") as f:
        f.write("\n")                          # one byte added by hand
    before = snapshot(out)
    one_line_error(run("estimate", short_log, "--method", "batch", "-o", out), "summary.json (changed since")
    assert snapshot(out) == before
    # A marker from before the hashes (names only) still lets our own output be replaced.
    (out / "summary.json").write_bytes((out / "summary.json").read_bytes()[:-1])
    del marker["sha256"]
    (out / MARKER).write_text(json.dumps(marker))
    assert run("estimate", short_log, "--method", "batch", "-o", out).exit_code == 0
    assert json.loads((out / "summary.json").read_text())["method"] == "batch"


def test_calibrate_refuses_a_users_file_before_any_work(tmp_path, short_log, monkeypatch):
    """A probe waited 8 s of calibration for the refusal."""
    import odomgraph.pipeline as P
    from odomgraph.errors import OutputDirError
    user = tmp_path / "robot.toml"
    user.write_text("# hand-tuned\n")
    monkeypatch.setattr(P, "calibrate", lambda *a, **k: pytest.fail("calibrated before refusing"))
    with pytest.raises(OutputDirError, match="not written by odomgraph"):
        P.calibrate_to_file(read_log(short_log), user)
    assert user.read_text() == "# hand-tuned\n"


def test_calibrate_never_overwrites_the_logs_robot_toml_or_a_users_file(tmp_path, short_log):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    before = snapshot(log)
    one_line_error(run("calibrate", log, "--no-tune", "-o", log / "robot.toml"), "input")
    user = tmp_path / "robot.toml"
    user.write_text("# hand-tuned\n")
    one_line_error(run("calibrate", log, "--no-tune", "-o", user), "not written by odomgraph")
    assert user.read_text() == "# hand-tuned\n" and snapshot(log) == before
    mine = tmp_path / "cal.toml"
    assert run("calibrate", log, "--no-tune", "-o", mine).exit_code == 0
    assert run("calibrate", log, "--no-tune", "-o", mine).exit_code == 0     # its own output: replaced
    assert oct(mine.stat().st_mode & 0o777) == oct(0o666 & ~_umask())


def test_import_refuses_an_output_that_holds_its_source(tmp_path):
    src = tmp_path / "session"
    shutil.copytree(OPTI, src)
    before = snapshot(src)
    one_line_error(run("import", "optiodom", src / "231220200029_run-01.csv", "-o", src), "input")
    assert snapshot(src) == before


# --------------------------------------------- outputs that cannot be written
def test_unwritable_outputs_are_one_line(tmp_path, short_log, monkeypatch):
    f = tmp_path / "a-file"
    f.write_text("x")
    one_line_error(run("estimate", short_log, "-o", f / "out"), "is a file")
    one_line_error(run("estimate", short_log, "-o", "/proc/odomgraph-cannot-write-here"), "cannot")
    monkeypatch.chdir(tmp_path)
    one_line_error(run("estimate", short_log, "-o", "."), "current directory")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a-file"]


def test_a_full_disk_is_one_line_and_leaves_nothing(tmp_path, short_log, monkeypatch):
    import errno
    import odomgraph.io.estimate as est_io

    def full(*a, **k):
        raise OSError(errno.ENOSPC, "No space left on device")
    monkeypatch.setattr(est_io, "write_states", full)
    one_line_error(run("estimate", short_log, "-o", tmp_path / "out"), "No space left on device")
    assert list(tmp_path.iterdir()) == []


def _umask():
    m = os.umask(0)
    os.umask(m)
    return m


@pytest.mark.parametrize("mask", [0o022, 0o027])
def test_outputs_follow_the_umask(tmp_path, short_log, mask):
    old = os.umask(mask)
    try:
        out = tmp_path / "est"
        assert run("estimate", short_log, "-o", out).exit_code == 0
    finally:
        os.umask(old)
    assert out.stat().st_mode & 0o777 == 0o777 & ~mask
    assert (out / "states.csv").stat().st_mode & 0o777 == 0o666 & ~mask


def test_temporaries_of_a_killed_run_are_removed_by_the_next(tmp_path, short_log):
    # What a run killed by SIGKILL leaves: a hidden .NAME.tmp-PID-XXXX with our
    # marker and a partial states.csv, under a PID that no longer exists.
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = tmp_path / f".est.tmp-{dead.pid}-abcd1234"
    stale.mkdir()
    (stale / MARKER).write_text('{"files": []}')
    (stale / "states.csv").write_text("t,x\n0.0,")
    live = tmp_path / f".est.tmp-{os.getpid()}-live0001"       # a concurrent run: left alone
    live.mkdir()
    (live / MARKER).write_text('{"files": []}')
    assert run("estimate", short_log, "-o", tmp_path / "est").exit_code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [live.name, "est"]


def test_sigterm_during_estimate_leaves_no_temporary(tmp_path):
    log = tmp_path / "log"
    write_log(simulate(paper(900.0), 2), log)        # about 15 s of work
    proc = subprocess.Popen([sys.executable, "-m", "odomgraph.cli", "estimate", str(log), "--method", "batch",
                             "-o", str(tmp_path / "out")], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(3.0)              # reading the log and starting the EKF
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert err.strip() == "odomgraph: interrupted; nothing was written"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["log"]


# ----------------------------------------------------------- bad time stamps
def _scale_times(log_dir: Path, factor: float, offset: float = 0.0, files=None):
    for p in sorted(log_dir.glob("*.csv")):
        if files and p.name not in files:
            continue
        lines = p.read_text().splitlines()
        out = [lines[0]] + [f"{float(ln.split(',')[0]) * factor + offset!r}," + ln.split(",", 1)[1]
                            for ln in lines[1:]]
        p.write_text("\n".join(out) + "\n")


@pytest.mark.parametrize("factor,offset,unit", [(1e3, 0.0, "milliseconds"), (1e9, 1.7e18, "nanoseconds"),
                                                (1e3, 1.7e12, "milliseconds"), (1e6, 0.0, "microseconds"),
                                                (1e6, 4e7, "microseconds")])
def test_time_stamps_in_another_unit_are_refused_with_the_unit_named(tmp_path, short_log, factor, offset, unit):
    # The probe: a 90 s log in microseconds spans 9e7, which was called
    # milliseconds (25 h); the 0.05 s sample interval says microseconds.
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    _scale_times(log, factor, offset)
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), unit)
    assert not (tmp_path / "out").exists()


def test_a_long_span_is_named_by_its_sample_interval():
    from odomgraph.io.log import MAX_DURATION, _unit_guess
    assert _unit_guess(8.995e7, 1.0, MAX_DURATION, 5.0e4) == "; it looks like microseconds"   # 90 s at 20 Hz
    assert _unit_guess(8.995e7, 1.0, MAX_DURATION, 50.0) == "; it looks like milliseconds"    # 25 h at 20 Hz


def test_one_absurd_stamp_is_refused(tmp_path, short_log):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    p = log / "gps.csv"
    lines = p.read_text().splitlines()
    lines[-1] = "1e300," + lines[-1].split(",", 1)[1]
    p.write_text("\n".join(lines) + "\n")
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), "gps.csv", "1e+300 is not seconds")


def test_a_file_on_another_clock_is_refused(tmp_path, short_log):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    _scale_times(log, 1.0, 1.7e9, files=("gps.csv",))       # GPS in epoch seconds, the rest from 0
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), "gps.csv", "share one clock")


def test_epoch_seconds_are_seconds(tmp_path, short_log):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    _scale_times(log, 1.0, 1.7e9)
    assert run("estimate", log, "-o", tmp_path / "out").exit_code == 0


# ------------------------------------------------------------ bad robot.toml
@pytest.mark.parametrize("edit,fragments", [
    (("lever_arm", "lever_armm"), ("unknown key in [gps] 'lever_armm'", "did you mean 'lever_arm'")),
    (("[gyro]", "[gyros]"), ("unknown table 'gyros'", "did you mean 'gyro'")),
    (("sigma = 0.01", "sigma = 0.0"), ("[gyro.sigma] must be positive",)),
])
def test_robot_toml_keys_are_checked(tmp_path, short_log, edit, fragments):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    p = log / "robot.toml"
    assert edit[0] in p.read_text()
    p.write_text(p.read_text().replace(edit[0], edit[1], 1))
    err = one_line_error(run("estimate", log, "-o", tmp_path / "out"), "robot.toml:", *fragments)
    assert not (tmp_path / "out").exists(), err


@pytest.mark.parametrize("table", [
    "[initial]\nx = 0.0\ny = 0.0\ntheta = 0.0\nsigma = [0.0, 0.1, 0.1]\n",
    "[process]\naccel = 0.0\n",
    "[process]\ninitial_scale_sigma = -0.05\n",
    "[process]\nslip_differential = 0\n",
])
def test_zero_or_negative_sigma_and_process_noise_are_refused(tmp_path, short_log, table):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    (log / "robot.toml").write_text((log / "robot.toml").read_text() + "\n" + table)
    for method in ("batch", "isam2"):
        one_line_error(run("estimate", log, "--method", method, "-o", tmp_path / "out"), "must be positive")
    one_line_error(run("compare", log, "-o", tmp_path / "rep"), "must be positive")


def test_a_byte_order_mark_is_read_as_what_it_is(tmp_path, short_log):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    for name in ("robot.toml", "encoders.csv", "gps.csv", "gyro.csv"):
        p = log / name
        p.write_bytes(b"\xef\xbb\xbf" + p.read_bytes())
    a, b = read_log(short_log), read_log(log)
    assert a.robot == b.robot
    np.testing.assert_array_equal(a.gps.x, b.gps.x)
    np.testing.assert_array_equal(a.encoders.ticks_left, b.encoders.ticks_left)


def test_a_latin1_byte_names_its_line(tmp_path, short_log):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    p = log / "gps.csv"
    lines = p.read_bytes().split(b"\n")
    lines[5] = lines[5] + b" \xe9"
    p.write_bytes(b"\n".join(lines))
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), "gps.csv:6", "not UTF-8", "0xe9")


def test_both_wheel_files_are_refused(tmp_path, short_log):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    (log / "wheel_speeds.csv").write_text("t,v_left,v_right\n0.0,0,0\n0.1,0,0\n")
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), "both encoders.csv and wheel_speeds.csv")


def _edited(tmp_path, short_log, name, text):
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    (log / name).write_text(text(log / name))
    return log


def test_a_sensor_file_that_is_a_directory_is_refused(tmp_path, short_log):
    """A probe's gyro.csv that was a directory was taken for no gyro, status ok."""
    log = tmp_path / "log"
    shutil.copytree(short_log, log)
    (log / "gyro.csv").unlink()
    (log / "gyro.csv").mkdir()
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), "gyro.csv: is not a file")


def test_gps_with_both_coordinate_forms_is_refused_at_its_header(tmp_path, short_log):
    """A probe's gps.csv with x,y and lat,lon columns used lat,lon silently."""
    def both(p):
        lines = p.read_text().splitlines()
        return "\n".join(["# exported", lines[0] + ",lat,lon"] + [ln + ",47.0,8.0" for ln in lines[1:]]) + "\n"
    log = _edited(tmp_path, short_log, "gps.csv", both)
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), "gps.csv:2: has both x,y and lat,lon columns")


def test_fractional_ticks_are_refused_at_their_line(tmp_path, short_log):
    def frac(p):
        lines = p.read_text().splitlines()
        t, a, b = lines[7].split(",")
        lines[7] = f"{t},{int(float(a))}.25,{b}"
        return "\n".join(lines) + "\n"
    log = _edited(tmp_path, short_log, "encoders.csv", frac)
    one_line_error(run("estimate", log, "-o", tmp_path / "out"), "encoders.csv:8: ticks_left", "not a whole number")


def test_equal_range_stamps_are_allowed_and_the_message_prints_plain_numbers(tmp_path):
    from odomgraph.sim.scenarios import Rates
    from odomgraph.sim.simulate import beacons_around_path
    sc = paper(30.0)
    sc = sc.with_(rates=Rates(encoders=20, gyro=25, gps=0, ranges=5), robot=sc.robot.with_(
        beacons=beacons_around_path(sc)))
    log = tmp_path / "log"
    write_log(simulate(sc, 0), log)
    p = log / "ranges.csv"
    lines = p.read_text().splitlines()
    t = [ln.split(",")[0] for ln in lines[1:]]
    # three beacons read at one instant: every third row shares the stamp of the one before
    body = [f"{t[i - (i % 3)]},{ln.split(',', 1)[1]}" for i, ln in enumerate(lines[1:])]
    p.write_text("\n".join([lines[0], *body]) + "\n")
    log_read = read_log(log)
    assert np.sum(np.diff(log_read.ranges.t) == 0) > 50
    assert run("estimate", log, "-o", tmp_path / "out").exit_code == 0
    body[10] = f"{float(t[0]) - 1.0},{lines[11].split(',', 1)[1]}"
    p.write_text("\n".join([lines[0], *body]) + "\n")
    err = one_line_error(run("estimate", log, "-o", tmp_path / "out2"), "ranges.csv:12", "time decreases")
    assert "(t = " in err


# ---------------------------------------------------------------- bad options
@pytest.mark.parametrize("args,fragment", [
    (("--method", "batch", "--keyframe-hz", "0"), "--keyframe-hz"),
    (("--method", "batch", "--keyframe-hz", "-5"), "--keyframe-hz"),
    (("--method", "fixed-lag", "--lag", "-3"), "--lag"),
    (("--method", "fixed-lag", "--lag", "0"), "--lag"),
    (("--method", "batch", "--slip-cauchy", "-1"), "--slip-cauchy"),
    (("--method", "batch", "--robust", "cauchy", "--robust-k", "0"), "--robust-k"),
    (("--method", "ekf", "--keyframe-hz", "-5"), "--keyframe-hz"),    # checked even where unused
    (("--method", "ekf", "--gate", "nan"), "--gate"),
    (("--method", "bach",), "bach"),
    (("--calibrate-until", "-1"), "--calibrate-until"),
])
def test_option_values_are_checked(tmp_path, short_log, args, fragment):
    one_line_error(run("estimate", short_log, *args, "-o", tmp_path / "out"), fragment)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("args,fragment", [
    (("simulate", "--slip", "left:40:30:0.5"), "start <= end"),
    (("simulate", "--scales", "1,nan,1"), "--scales"),
    (("simulate", "--duration", "-4"), "--duration"),
    (("simulate", "--gps-sigma", "0"), "--gps-sigma"),
    (("simulate", "--encoder-sigma", "0,0"), "encoder_sigma"),
    (("montecarlo", "--config", "1", "--workers", "0"), "--workers"),
    (("montecarlo", "--config", "7"), "--config"),
])
def test_other_commands_check_their_options(tmp_path, args, fragment):
    one_line_error(run(*args, "-o", tmp_path / "out"), fragment)
    assert not (tmp_path / "out").exists()


def test_library_options_are_checked_too(short_log):
    from odomgraph.errors import OptionError
    from odomgraph.estimators.batch import SmootherOptions
    from odomgraph.pipeline import estimate
    with pytest.raises(OptionError, match="keyframe_hz"):
        SmootherOptions(keyframe_hz=-5)
    with pytest.raises(OptionError, match="keyframe_hzz.*did you mean 'keyframe_hz'"):
        estimate(read_log(short_log), "batch", keyframe_hzz=2)
    with pytest.raises(OptionError, match="unknown method 'bach'"):
        estimate(read_log(short_log), "bach")


@pytest.mark.parametrize("method, option, value, takers", [
    ("ekf", "keyframe_hz", 2.0, "batch, isam2, fixed-lag"),
    ("batch", "gate", 10.0, "ekf"),
    ("isam2", "slip_step_k", 2.0, "batch"),
    ("fixed-lag", "velocity_loss", "huber", "batch"),
    ("batch", "lag", 3.0, "isam2, fixed-lag"),
])
def test_another_estimators_option_is_refused_not_dropped(short_log, method, option, value, takers):
    """An option that only other estimators take does nothing here: set, it
    is an error naming whose option it is (it was dropped in silence, so a
    run looked as if it had used it). At its default, or None (the CLI hands
    one set to every method), it is accepted."""
    from odomgraph.errors import OptionError
    from odomgraph.estimators.registry import REGISTRY, options_for
    from odomgraph.pipeline import estimate
    flag = "--" + option.replace("_", "-")
    with pytest.raises(OptionError, match=rf"^{option} \({flag}\) is an option of {takers}, not of {method}$"):
        estimate(read_log(short_log), method, **{option: value})
    taker = REGISTRY[[m for m in REGISTRY if m.value == takers.split(", ")[0]][0]].options_type()
    default = taker.__dataclass_fields__[option].default
    assert options_for(method, {option: default, "pin": ()}) == {"pin": ()}
    assert options_for(method, {option: None}) == {}


def test_a_default_is_recognised_whatever_its_kind():
    """options_for lets another estimator's option through at its default:
    a default_factory's value and an array compare by value (``!=`` against
    a factory field's MISSING refused every value; against an array it
    raised), and a field without a default has no value that passes."""
    from dataclasses import dataclass, field, fields
    from odomgraph.estimators.registry import _is_default

    @dataclass
    class Opts:
        required: float
        pin: tuple = ()
        arm: np.ndarray = field(default_factory=lambda: np.zeros(2))
        names: list = field(default_factory=list)
        k: float | None = None
    f = {x.name: x for x in fields(Opts)}
    assert _is_default((), f["pin"]) and not _is_default(("x",), f["pin"])
    assert _is_default(np.zeros(2), f["arm"]) and not _is_default(np.array([0.0, 0.1]), f["arm"])
    assert not _is_default(np.zeros(3), f["arm"]) and not _is_default([0.0, 0.1], f["arm"])
    assert _is_default([], f["names"]) and not _is_default(["a"], f["names"])
    assert not _is_default(0.0, f["required"])
    assert _is_default(None, f["k"]) and not _is_default(2.0, f["k"])


def test_another_estimators_option_on_the_command_line(tmp_path, short_log):
    one_line_error(run("estimate", short_log, "--method", "ekf", "--keyframe-hz", "2", "-o", tmp_path / "out"),
                   "keyframe_hz (--keyframe-hz) is an option of batch, isam2, fixed-lag, not of ekf")
    assert not (tmp_path / "out").exists()


def test_usage_errors_are_one_line_too(tmp_path, short_log):
    one_line_error(run("estimate", short_log, "--method", "nope", "-o", tmp_path / "o"), "nope")
    one_line_error(run("estimate", short_log, "--no-such-option", "-o", tmp_path / "o"), "--no-such-option")
    one_line_error(run("estimate", short_log), "--output")


# ------------------------------------------------- importers on garbage input
def test_importers_refuse_garbage_with_one_line(tmp_path):
    src = tmp_path / "session"
    shutil.copytree(OPTI, src)
    meta = next(src.glob("*_metadata.csv"))
    run_csv = src / "231220200029_run-01.csv"
    for garbage, fragment in ((b"\x00\xff\xfe garbage", "not UTF-8"), (b"ngear,abc\n", "ngear"),
                              (meta.read_bytes().replace(b"Li,", b"Li,-"), "'Li' must be a positive")):
        m = tmp_path / "meta.csv"
        m.write_bytes(garbage)
        one_line_error(run("import", "optiodom", run_csv, "--metadata", m, "-o", tmp_path / "o"), fragment)
    one_line_error(run("import", "optiodom", run_csv, "--fix-sigma", "0", "-o", tmp_path / "o"), "--fix-sigma")
    rsf = tmp_path / "x_Input.txt"
    for garbage, fragment in ((b"\x89PNG\r\n\x1a\n\x00\x00", "not UTF-8"), (b"odom2diff 1 2\n", "needs 7 values"),
                              (b"range2 0 1 -1 0 0 1 0\n", "positive variance"), (b"hello 1 2 3\n", "hello")):
        rsf.write_bytes(garbage)
        one_line_error(run("import", "librsf", rsf, "-o", tmp_path / "o"), fragment)
    rsf.write_bytes((DATA / "librsf" / "Indoor_UWB_Input.txt").read_bytes())
    gt = tmp_path / "gt.txt"
    gt.write_bytes(b"point2 1.0 nan 2\n")
    one_line_error(run("import", "librsf", rsf, "--ground-truth", gt, "-o", tmp_path / "o"), "gt.txt:1")
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------ a valid, bare log
@pytest.mark.parametrize("with_initial", [False, True])
@pytest.mark.parametrize("method", ["ekf", "batch", "isam2", "fixed-lag"])
def test_an_encoder_only_log_is_dead_reckoned_with_every_scale_unobservable(tmp_path, method, with_initial):
    sc = paper(40.0).with_(slips=(), write_initial=with_initial, start_pose=(3.0, -2.0, 0.7))
    log = simulate(sc, 5).with_(gps=None, gyro=None)
    d = tmp_path / "log"
    write_log(log, d)
    res = run("estimate", d, "--method", method, "-o", tmp_path / "out")
    assert res.exit_code == 0, res.output
    s = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert set(s["unobservable"]) == {"scale_common", "scale_ratio", "scale_track"}
    for k, c in s["calibration"].items():
        assert c["value"] == pytest.approx(1.0, abs=1e-3) and c["sigma"] == pytest.approx(0.05, rel=1e-3)
        assert c["observable"] is False
    assert any("scale_common is not determined" in w for w in s["warnings"])
    if not with_initial:
        assert any("origin" in w for w in s["warnings"])
    else:
        # dead reckoning from the given pose; the sigma carries the unknown scales
        e = s["errors"]
        assert e["coverage_3sigma"]["x"] > 0.95 and e["coverage_3sigma"]["y"] > 0.95, e
    assert "odomgraph: warning: scale_common" in res.stderr
    data = np.loadtxt(tmp_path / "out" / "states.csv", delimiter=",", skiprows=1)
    assert np.isfinite(data).all()
    assert data[-1, 12 + 9:12 + 12] == pytest.approx(0.05, rel=1e-3)     # sigma_scale_* rows: the prior


@pytest.mark.parametrize("run_file", ["231220200141_run-01.csv", "020120212354_run-01.csv",
                                      "231220200029_run-01.csv"])
def test_optiodom_runs_imported_without_fixes_work_with_every_estimator(run_file):
    # The importer's default (--fixes-hz 0) gives encoders and truth only: with
    # the [initial] pose from motion capture, every estimator dead reckons.
    from odomgraph.analysis.deadreckoning import dead_reckon
    from odomgraph.analysis.metrics import truth_errors
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.io.importers.optiodom import import_optiodom
    from odomgraph.pipeline import estimate
    log = import_optiodom(OPTI / run_file)
    assert log.gps is None and log.robot.initial is not None
    i = log.robot.initial
    for method in ("ekf", "batch", "isam2", "fixed-lag"):
        est = estimate(log, method, Schedule(0.0))
        assert np.isfinite(est.mean).all() and np.isfinite(est.sigma).all()
        assert set(est.unobservable()) == {"scale_common", "scale_ratio", "scale_track"}
        assert all(c["sigma"] == pytest.approx(0.05, rel=1e-3) for c in est.calibration.values())
        # It is nominal dead reckoning (within 2 cm of it), and its sigma covers the truth.
        t, p = dead_reckon(log, (1.0, 1.0, 1.0), (log.encoders.t[0], i.x, i.y, i.theta))
        dx = np.interp(est.t, t, p[:, 0]) - est.mean[:, 0]
        dy = np.interp(est.t, t, p[:, 1]) - est.mean[:, 1]
        assert np.sqrt(np.mean(dx**2 + dy**2)) < 0.02, method
        cov = truth_errors(est, log).coverage_3sigma
        assert cov["x"] > 0.95 and cov["y"] > 0.95, (method, cov)


# ------------------------------------------------------------------- messages
def test_a_successful_run_writes_nothing_to_stderr(tmp_path, short_log):
    proc = subprocess.run([sys.executable, "-m", "odomgraph.cli", "estimate", str(short_log), "-o",
                           str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0 and proc.stderr == "", repr(proc.stderr)


def test_version_and_short_help():
    from odomgraph import __version__
    res = run("--version")
    assert res.exit_code == 0 and res.output.strip() == f"odomgraph {__version__}"
    h = run("simulate", "-h")
    assert h.exit_code == 0 and "Length of the log [s]" in h.output     # units survive: no rich markup


# ------------------------------------------------------------ clean shutdown
def _children(pid: int) -> list[int]:
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return True
    return state == "Z"


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="needs /proc to find the workers")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGKILL])
def test_montecarlo_workers_stop_with_their_parent(tmp_path, sig):
    proc = subprocess.Popen([sys.executable, "-m", "odomgraph.cli", "montecarlo", "--config", "1", "--grid", "2",
                             "--runs", "30", "--duration", "60", "--workers", "2", "-o", str(tmp_path / "mc")],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    kids = []
    while time.time() < deadline and len(kids) < 2:
        time.sleep(0.2)
        kids = _children(proc.pid)
    assert len(kids) >= 2, "the pool did not start"
    proc.send_signal(sig)
    proc.wait(timeout=30)
    deadline = time.time() + 10
    while time.time() < deadline and not all(_gone(k) for k in kids):
        time.sleep(0.2)
    assert all(_gone(k) for k in kids), [k for k in kids if not _gone(k)]


def test_the_top_level_api_and_python_m(tmp_path):
    import subprocess
    import sys

    import odomgraph
    from odomgraph.sim.scenarios import paper
    log = odomgraph.simulate(paper(30.0).with_(slips=()), 1)
    a = odomgraph.estimate(log, "ekf", odomgraph.Schedule(20.0))
    b = odomgraph.estimate(log, odomgraph.Method.ekf, odomgraph.Schedule(20.0))
    assert isinstance(a, odomgraph.Estimate) and a.method == "ekf"
    np.testing.assert_array_equal(a.mean, b.mean)
    with pytest.raises(AttributeError, match="no attribute 'estimat'"):
        odomgraph.estimat
    r = subprocess.run([sys.executable, "-m", "odomgraph", "--version"], capture_output=True, text=True)
    assert r.returncode == 0 and r.stdout.strip().endswith(odomgraph.__version__)
