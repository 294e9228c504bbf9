"""Log reading/writing and the bad-input contract: one clear error naming the
file, the line and the problem."""
import numpy as np
import pytest

from odomgraph.errors import LogFormatError
from odomgraph.io.geodesy import latlon_to_local
from odomgraph.io.log import read_log, write_log
from odomgraph.io.robot import Beacon, RobotConfig, load_robot, robot_toml
from tests.conftest import replace_line


def test_roundtrip_preserves_every_sensor(paper_log, paper_log_dir):
    back = read_log(paper_log_dir)
    assert back.robot == paper_log.robot
    assert back.truth_scales == paper_log.truth_scales
    np.testing.assert_array_equal(back.encoders.ticks_left, paper_log.encoders.ticks_left)
    np.testing.assert_allclose(back.encoders.t, paper_log.encoders.t, atol=1e-6)
    np.testing.assert_allclose(back.gps.x, paper_log.gps.x, atol=1e-5)
    np.testing.assert_allclose(back.gyro.omega, paper_log.gyro.omega, atol=1e-7)
    for k in ("x", "y", "theta", "slip_left", "slip_right"):
        np.testing.assert_allclose(back.truth.values[k], paper_log.truth.values[k], atol=1e-12)


def test_robot_toml_roundtrip(tmp_path):
    cfg = RobotConfig(1500.0, 1520.5, 0.42, gps_lever_arm=(0.25, 0.12),
                      beacons=(Beacon("A", 0.0, 1.5), Beacon("B 2", -3.0, 4.0)), gps_origin=(41.5, -81.6))
    p = tmp_path / "robot.toml"
    p.write_text(robot_toml(cfg))
    assert load_robot(p) == cfg


def expect_error(log_dir, *fragments):
    with pytest.raises(LogFormatError) as exc:
        read_log(log_dir)
    msg = str(exc.value)
    assert "\n" not in msg
    for f in fragments:
        assert f in msg, msg
    return msg


def test_missing_encoder_file(log_copy):
    (log_copy / "encoders.csv").unlink()
    expect_error(log_copy, "encoders.csv", "missing", "wheel_speeds.csv")


def test_missing_column(log_copy):
    replace_line(log_copy / "gps.csv", 1, "t,x,why")
    expect_error(log_copy, "gps.csv:1", "missing column(s) y")


def test_time_not_increasing(log_copy):
    p = log_copy / "gyro.csv"
    lines = p.read_text().splitlines()
    t_prev = lines[9].split(",")[0]
    replace_line(p, 11, f"{t_prev},0.1")
    expect_error(log_copy, "gyro.csv:11", "time does not increase")


def test_nan_value(log_copy):
    p = log_copy / "encoders.csv"
    t = p.read_text().splitlines()[4].split(",")[0]
    replace_line(p, 5, f"{t},nan,3")
    expect_error(log_copy, "encoders.csv:5", "ticks_left", "not a finite number")


def test_non_numeric_value(log_copy):
    p = log_copy / "gps.csv"
    t = p.read_text().splitlines()[6].split(",")[0]
    replace_line(p, 7, f"{t},12..5,3.0")
    expect_error(log_copy, "gps.csv:7", "'12..5' is not a number")


def test_wrong_field_count(log_copy):
    replace_line(log_copy / "gyro.csv", 3, "1.0,2.0,3.0")
    expect_error(log_copy, "gyro.csv:3", "expected 2 fields, found 3")


def test_unknown_beacon(log_copy):
    (log_copy / "ranges.csv").write_text("t,beacon,range\n0.1,Z,3.0\n")
    expect_error(log_copy, "ranges.csv:2", "unknown beacon 'Z'")


def test_malformed_toml(log_copy):
    p = log_copy / "robot.toml"
    p.write_text(p.read_text().replace("track_width = 0.6", "track_width = = 0.6"))
    expect_error(log_copy, "robot.toml", "malformed TOML", "line 4")


def test_invalid_robot_value(log_copy):
    p = log_copy / "robot.toml"
    p.write_text(p.read_text().replace("track_width = 0.6", "track_width = -0.6"))
    expect_error(log_copy, "robot.toml", "[wheels.track_width] must be positive")


def test_missing_robot_key(log_copy):
    p = log_copy / "robot.toml"
    p.write_text(p.read_text().replace("ticks_per_meter_left = 2000.0\n", ""))
    expect_error(log_copy, "robot.toml", "[wheels.ticks_per_meter_left] is missing")


def test_comments_and_extra_columns_are_allowed(log_copy, paper_log_dir, paper_log):
    p = log_copy / "gyro.csv"
    lines = p.read_text().splitlines()
    assert lines[0] == "t,omega"
    # extra columns before, between and after the known ones (found by name, not
    # position), each with values of its own that no known column holds
    rows = [ln.split(",") for ln in lines[1:]]
    body = ["temperature,t,status,omega,note"] + [f"{20 + 0.01 * k:.2f},{t},{k % 7},{w},x{k}"
                                                 for k, (t, w) in enumerate(rows)]
    p.write_text("# gyro from the IMU\n" + "\n".join(body[:5]) + "\n# a comment mid-file\n\n"
                 + "\n".join(body[5:]) + "\n# and one at the end\n")
    log = read_log(log_copy)
    assert log.gyro.t.size == len(lines) - 1
    # the values are the file's, column by column, the extra columns ignored
    ref = np.array([[float(v) for v in r] for r in rows])
    np.testing.assert_array_equal(log.gyro.t, ref[:, 0])
    np.testing.assert_array_equal(log.gyro.omega, ref[:, 1])
    # ...exactly what the same log reads without them, and the source data to half
    # the last digit written (stamps with 6 decimals, yaw rates with 7: measured
    # 4.9993e-7 s and 4.996e-8 rad/s at most)
    plain = read_log(paper_log_dir)
    np.testing.assert_array_equal(log.gyro.t, plain.gyro.t)
    np.testing.assert_array_equal(log.gyro.omega, plain.gyro.omega)
    np.testing.assert_allclose(log.gyro.t, paper_log.gyro.t, rtol=0, atol=5.0001e-7)
    np.testing.assert_allclose(log.gyro.omega, paper_log.gyro.omega, rtol=0, atol=5.0001e-8)
    # and the other sensors are untouched
    np.testing.assert_array_equal(log.encoders.ticks_left, plain.encoders.ticks_left)
    np.testing.assert_array_equal(log.gps.x, plain.gps.x)


def test_latlon_gps_is_projected(tmp_path, paper_log):
    # Write the GPS as lat/lon around Cleveland and read it back: local
    # east/north from the first fix must match the original x/y offsets.
    lat0, lon0 = 41.5045, -81.6086
    g = paper_log.gps
    # WGS84 meridional (M) and normal (N) radii of curvature at lat0.
    a, e2, s2 = 6_378_137.0, 6.69437999014e-3, np.sin(np.radians(lat0)) ** 2
    M, N = a * (1 - e2) / (1 - e2 * s2) ** 1.5, a / np.sqrt(1 - e2 * s2)
    dlat = np.degrees(g.y / M)
    dlon = np.degrees(g.x / (N * np.cos(np.radians(lat0))))
    write_log(paper_log, tmp_path / "log")
    rows = "\n".join(f"{t:.6f},{lat0 + a:.10f},{lon0 + b:.10f}" for t, a, b in zip(g.t, dlat, dlon))
    (tmp_path / "log" / "gps.csv").write_text("t,lat,lon\n" + rows + "\n")
    back = read_log(tmp_path / "log")
    np.testing.assert_allclose(back.gps.x, g.x - g.x[0], atol=2e-3)
    np.testing.assert_allclose(back.gps.y, g.y - g.y[0], atol=2e-3)


def test_latlon_local_frame_is_metric():
    # One thousandth of a degree of latitude is ~111 m north, no east.
    e, n = latlon_to_local(45.001, 7.0, 45.0, 7.0)
    assert abs(e) < 1e-6 and n == pytest.approx(111.1, abs=0.2)
    e, n = latlon_to_local(0.0, 0.001, 0.0, 0.0)
    assert e == pytest.approx(111.32, abs=0.01) and abs(n) < 1e-6


def test_write_log_is_atomic(tmp_path, paper_log, monkeypatch):
    import odomgraph.io.log as logmod
    target = tmp_path / "out"

    def boom(*a, **k):
        raise RuntimeError("disk full")
    monkeypatch.setattr(logmod, "write_table", boom)
    with pytest.raises(RuntimeError):
        write_log(paper_log, target)
    assert not target.exists()
    assert list(tmp_path.iterdir()) == []


def test_truth_is_read_on_first_use_and_its_errors_name_the_line(log_copy, paper_log):
    """An estimator never reads truth.csv (issue 17): read_log checks its
    header only; its rows, and their clock, are read when a scoring tool
    first asks, and a bad row is then refused as any file's is."""
    read_log(log_copy)                                   # the copy reads clean
    replace_line(log_copy / "truth.csv", 40, "1.0,abc,2.0,0,0,0,0,0,0")
    log = read_log(log_copy)
    assert log.truth is not None and not log.truth.loaded
    assert log.encoders is not None and not log.truth.loaded   # the sensors do not touch it
    with pytest.raises(LogFormatError, match=r"truth\.csv:40: column 'x': 'abc' is not a number"):
        log.truth.t


def test_truth_header_is_checked_as_the_log_is_read(log_copy):
    (log_copy / "truth.csv").write_text("t,x\n0.0,1.0\n")
    expect_error(log_copy, "truth.csv", "missing column(s) y")


def test_truth_on_another_clock_is_refused_when_read(log_copy):
    text = (log_copy / "truth.csv").read_text().splitlines()
    rows = [text[0]] + [",".join([f"{float(r.split(',')[0]) * 1000:.3f}", *r.split(",")[1:]]) for r in text[1:]]
    (log_copy / "truth.csv").write_text("\n".join(rows) + "\n")
    log = read_log(log_copy)
    with pytest.raises(LogFormatError, match=r"truth\.csv.*(share one clock|not seconds)"):
        log.truth.values


def test_truth_read_late_equals_truth_written(paper_log, paper_log_dir):
    back = read_log(paper_log_dir)
    np.testing.assert_allclose(back.truth.t, paper_log.truth.t, atol=1e-6)
    assert back.truth.values.keys() == paper_log.truth.values.keys()
    cut = back.truncated(30.0)
    assert cut.truth.t[-1] <= 30.0 and len(cut.truth.values["x"]) == len(cut.truth.t)


def test_a_log_with_its_truth_unread_pickles_with_the_rows(paper_log_dir):
    """A process pool (or a checkpoint) pickles the rows, not the reader."""
    import pickle
    log = read_log(paper_log_dir)
    assert not log.truth.loaded
    back = pickle.loads(pickle.dumps(log))
    assert back.truth.loaded
    np.testing.assert_array_equal(back.truth.t, log.truth.t)


def test_a_log_on_a_real_clock_with_its_truth_is_rebased(paper_log):
    """rebased shifts the truth too (it is not a dataclass since it is read on first use)."""
    from dataclasses import replace as rep
    from odomgraph.io.log import Truth, rebased
    o = 1_700_000_000
    shifted = paper_log.with_(**{k: rep(getattr(paper_log, k), t=getattr(paper_log, k).t + o)
                                 for k in ("encoders", "gps", "gyro")},
                              truth=Truth(paper_log.truth.t + o, paper_log.truth.values))
    back = rebased(shifted)
    assert back.t_origin == o
    np.testing.assert_allclose(back.truth.t, paper_log.truth.t, atol=1e-6)
    cut = back.truncated(30.0)
    assert cut.truth.t[-1] <= 30.0
