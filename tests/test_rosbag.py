"""The rosbag importer: a ROS 2 bag written with rosbags itself from a
simulated log (JointState wheel positions, NavSatFix, Imu), imported back."""
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")

from odomgraph.errors import LogFormatError  # noqa: E402
from odomgraph.estimators.schedule import Schedule  # noqa: E402
from odomgraph.io.importers.rosbag import import_rosbag  # noqa: E402
from odomgraph.io.log import read_log  # noqa: E402
from odomgraph.pipeline import Method, estimate  # noqa: E402
from odomgraph.sim.scenarios import paper  # noqa: E402
from odomgraph.sim.simulate import simulate  # noqa: E402

LAT0, LON0, R_WHEEL = 41.5045, -81.6086, 0.15


def _write_bag(path, log, wheels="joints", imu_axis="z", tf_lever=None, no_fix_every=0, t0=0.0,
               extra_odom=False, storage="sqlite3", imu_tf=False):
    """A ROS 2 bag of ``log``: wheels as JointState positions or as the
    nav_msgs/Odometry twist; the gyro on IMU axis ``imu_axis`` ("-z": upside
    down); optionally /tf_static base_link -> gps with ``tf_lever``, every
    ``no_fix_every``-th fix without a fix (status -1), stamps moved by t0.
    ``wheels="twist"`` writes geometry_msgs/TwistStamped; ``imu_tf`` writes
    the IMU's mounting (yaw axis ``imu_axis``) into /tf_static; ``storage``:
    sqlite3 or mcap."""
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]

    def header(t):
        return Header(stamp=Time(sec=int(t), nanosec=int(round((t - int(t)) * 1e9))), frame_id="base_link")

    a, e2 = 6_378_137.0, 6.69437999014e-3
    s2 = np.sin(np.radians(LAT0)) ** 2
    M, N = a * (1 - e2) / (1 - e2 * s2) ** 1.5, a / np.sqrt(1 - e2 * s2)
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        cg = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
        ci = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        e, r = log.encoders, log.robot
        if wheels == "joints":
            cj = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
            angle_l = np.cumsum(e.ticks_left) / r.ticks_per_meter_left / R_WHEEL
            angle_r = np.cumsum(e.ticks_right) / r.ticks_per_meter_right / R_WHEEL
            for t, al, ar in zip(e.t, angle_l, angle_r):
                msg = T["sensor_msgs/msg/JointState"](header=header(t + t0),
                                                      name=["caster_joint", "left_wheel_joint", "right_wheel_joint"],
                                                      position=np.array([0.3, al, ar]), velocity=np.array([], float),
                                                      effort=np.array([], float))
                w.write(cj, int((t + t0) * 1e9), ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
        elif wheels == "twist":
            ct = w.add_connection("/cmd_vel_measured", "geometry_msgs/msg/TwistStamped", typestore=ts)
            dt = np.diff(e.t)
            vl, vr = e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)
            for t, vi, wi in zip(e.t[1:], 0.5 * (vl + vr), (vr - vl) / r.track_width):
                msg = T["geometry_msgs/msg/TwistStamped"](
                    header=header(t + t0), twist=T["geometry_msgs/msg/Twist"](linear=V3(x=vi, y=0.0, z=0.0),
                                                                             angular=V3(x=0.0, y=0.0, z=wi)))
                w.write(ct, int((t + t0) * 1e9), ts.serialize_cdr(msg, "geometry_msgs/msg/TwistStamped"))
        else:
            topics = ["/diff_drive_controller/odom"] + (["/odometry/filtered"] if extra_odom else [])
            conns = [w.add_connection(tp, "nav_msgs/msg/Odometry", typestore=ts) for tp in topics]
            dt = np.diff(e.t)
            vl, vr = e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)
            v, om = 0.5 * (vl + vr), (vr - vl) / r.track_width
            P, Tw = T["geometry_msgs/msg/PoseWithCovariance"], T["geometry_msgs/msg/TwistWithCovariance"]
            for t, vi, wi in zip(e.t[1:], v, om):
                msg = T["nav_msgs/msg/Odometry"](
                    header=header(t + t0), child_frame_id="base_link",
                    pose=P(pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                                           orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
                           covariance=np.zeros(36)),
                    twist=Tw(twist=T["geometry_msgs/msg/Twist"](linear=V3(x=vi, y=0.0, z=0.0),
                                                               angular=V3(x=0.0, y=0.0, z=wi)),
                             covariance=np.zeros(36)))
                for c in conns:
                    w.write(c, int((t + t0) * 1e9), ts.serialize_cdr(msg, "nav_msgs/msg/Odometry"))
        trs = []
        if tf_lever is not None:
            trs.append(T["geometry_msgs/msg/TransformStamped"](
                header=header(t0), child_frame_id="gps",
                transform=T["geometry_msgs/msg/Transform"](translation=V3(x=tf_lever[0], y=tf_lever[1], z=0.5),
                                                           rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0))))
        if imu_tf:
            # the rotation that takes the IMU's yaw axis onto base_link's z
            h = np.sqrt(0.5)
            q = {"x": Q(x=0.0, y=-h, z=0.0, w=h), "y": Q(x=h, y=0.0, z=0.0, w=h), "z": Q(x=0.0, y=0.0, z=0.0, w=1.0),
                 "-z": Q(x=1.0, y=0.0, z=0.0, w=0.0)}[imu_axis]
            trs.append(T["geometry_msgs/msg/TransformStamped"](
                header=header(t0), child_frame_id="imu_link",
                transform=T["geometry_msgs/msg/Transform"](translation=V3(x=0.1, y=0.0, z=0.2), rotation=q)))
        if trs:
            ct = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)
            w.write(ct, int(t0 * 1e9), ts.serialize_cdr(T["tf2_msgs/msg/TFMessage"](transforms=trs),
                                                        "tf2_msgs/msg/TFMessage"))
        g = log.gps
        for k, (t, x, y) in enumerate(zip(g.t, g.x, g.y)):
            cov = np.zeros(9)
            cov[0] = cov[4] = r.gps_sigma**2
            bad = no_fix_every and k % no_fix_every == 0
            hd = header(t + t0)
            hd.frame_id = "gps"
            msg = T["sensor_msgs/msg/NavSatFix"](
                header=hd, status=T["sensor_msgs/msg/NavSatStatus"](status=-1 if bad else 0, service=1),
                latitude=LAT0 + np.degrees(y / M) + (1.0 if bad else 0.0),
                longitude=LON0 + np.degrees(x / (N * np.cos(np.radians(LAT0)))),
                altitude=200.0, position_covariance=cov, position_covariance_type=2)
            w.write(cg, int((t + t0) * 1e9), ts.serialize_cdr(msg, "sensor_msgs/msg/NavSatFix"))
        sign = -1.0 if imu_axis.startswith("-") else 1.0
        for t, om in zip(log.gyro.t, log.gyro.omega):
            rate = {a: (sign * om if a == imu_axis[-1] else 0.001 * np.sin(7 * t)) for a in "xyz"}
            hd = header(t + t0)
            hd.frame_id = "imu_link"
            msg = T["sensor_msgs/msg/Imu"](header=hd, orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                                           orientation_covariance=np.zeros(9), angular_velocity=V3(**rate),
                                           angular_velocity_covariance=np.zeros(9),
                                           linear_acceleration=V3(x=0.0, y=0.0, z=9.81),
                                           linear_acceleration_covariance=np.zeros(9))
            w.write(ci, int((t + t0) * 1e9), ts.serialize_cdr(msg, "sensor_msgs/msg/Imu"))


@pytest.fixture(scope="module")
def bag(tmp_path_factory):
    log = simulate(paper(60).with_(slips=()), 2)
    path = tmp_path_factory.mktemp("bags") / "run"
    _write_bag(path, log)
    return path, log


def test_rosbag_import_matches_the_source_log(bag):
    path, src = bag
    log = import_rosbag(path, "/joint_states", "left_wheel_joint", "right_wheel_joint", R_WHEEL,
                        src.robot.track_width, "/fix", "/imu", gps_lever_arm=src.robot.gps_lever_arm)
    e, r = src.encoders, src.robot
    dt = np.diff(e.t)
    np.testing.assert_allclose(log.wheel_speeds.v_left, e.ticks_left[1:] / (r.ticks_per_meter_left * dt), atol=1e-6)
    np.testing.assert_allclose(log.wheel_speeds.t, 0.5 * (e.t[1:] + e.t[:-1]), atol=1e-6)
    np.testing.assert_allclose(log.gps.x - log.gps.x[0], src.gps.x - src.gps.x[0], atol=2e-3)
    np.testing.assert_allclose(log.gyro.omega, src.gyro.omega, atol=1e-12)
    assert log.robot.gps_sigma == pytest.approx(r.gps_sigma)
    # and an estimator runs on it: the scale factors of the simulation come back
    est = estimate(log, Method.batch, Schedule(None))
    for got, true in zip(est.mean[-1, 8:11], (1.03, 0.98, 1.04)):
        assert got == pytest.approx(true, rel=0.006)


def test_rosbag_missing_topic(bag):
    path, src = bag
    with pytest.raises(LogFormatError, match=r"topic\(s\) \['/odom'\] not in the bag"):
        import_rosbag(path, "/odom", "l", "r", 0.1, 0.5)


def test_rosbag_cli(bag, tmp_path):
    from typer.testing import CliRunner
    from odomgraph.cli import app
    path, src = bag
    res = CliRunner().invoke(app, ["import", "rosbag", str(path), "--wheel-radius", str(R_WHEEL), "--track-width",
                                   "0.6", "--gps-topic", "/fix", "--imu-topic", "/imu", "--gps-lever-arm", "-0.45,0",
                                   "-o", str(tmp_path / "log")])
    assert res.exit_code == 0, res.output
    text = (tmp_path / "log" / "robot.toml").read_text()
    assert "lever_arm = [-0.45, 0.0]" in text and "origin = [41.5045" in text
    assert sorted(p.name for p in (tmp_path / "log").iterdir() if p.name != ".odomgraph") == ["gps.csv", "gyro.csv", "robot.toml",
                                                                     "wheel_speeds.csv"]
    # the written log holds the bag's numbers
    back = read_log(tmp_path / "log")
    e, r = src.encoders, src.robot
    np.testing.assert_allclose(back.wheel_speeds.v_right, e.ticks_right[1:] / (r.ticks_per_meter_right * np.diff(e.t)),
                               atol=2e-6)
    np.testing.assert_allclose(back.gyro.omega, src.gyro.omega, atol=1e-6)
    assert back.robot.track_width == 0.6


# ------------------------------------------------------- issue 13: real bags
@pytest.fixture(scope="module")
def odom_bag(tmp_path_factory):
    """Odometry wheels, the IMU's yaw on its y axis, a /tf_static GPS frame,
    every 10th fix without a fix, and a real-clock time base (1.7e9 s)."""
    log = simulate(paper(60).with_(slips=()), 3)
    path = tmp_path_factory.mktemp("bags") / "odom"
    _write_bag(path, log, wheels="odometry", imu_axis="y", tf_lever=(-0.45, 0.0), no_fix_every=10, t0=1.7e9)
    return path, log


def test_odometry_bag_imports_without_options(odom_bag):
    path, src = odom_bag
    log = import_rosbag(path, track_width=src.robot.track_width)
    e, r = src.encoders, src.robot
    dt = np.diff(e.t)
    # v -/+ omega b/2 gives the wheel speeds back, stamped on the real clock to 1e-6 s
    np.testing.assert_allclose(log.wheel_speeds.v_left, e.ticks_left[1:] / (r.ticks_per_meter_left * dt), atol=1e-9)
    np.testing.assert_allclose(log.wheel_speeds.t - 1.7e9, e.t[1:], atol=1e-6)
    # the y axis is found and taken, with a warning
    np.testing.assert_allclose(log.gyro.omega, src.gyro.omega, atol=1e-12)
    assert len(log.warnings) == 1 and "IMU's y axis" in log.warnings[0]
    # the lever arm from /tf_static, the no-fix messages dropped and counted
    assert log.robot.gps_lever_arm == (-0.45, 0.0)
    assert len(log.gps.t) == len(src.gps.t) - len(range(0, len(src.gps.t), 10))
    assert any(f"{len(range(0, len(src.gps.t), 10))} messages without a fix" in n for n in log.notes)
    # and it calibrates to the simulation's scale factors
    est = estimate(log, Method.batch, Schedule(None))
    for got, true in zip(est.mean[-1, 8:11], src.truth_scales):
        assert got == pytest.approx(true, rel=0.006)


def test_imu_axis_can_be_forced_and_an_upside_down_imu_is_flipped(odom_bag, tmp_path):
    path, src = odom_bag
    z = import_rosbag(path, track_width=src.robot.track_width, imu_axis="z")
    assert np.abs(z.gyro.omega).max() < 0.0011 and z.warnings == ()
    src2 = simulate(paper(40).with_(slips=()), 4)
    p2 = tmp_path / "upside"
    _write_bag(p2, src2, wheels="odometry", imu_axis="-z")
    log = import_rosbag(p2, track_width=src2.robot.track_width)
    np.testing.assert_allclose(log.gyro.omega, src2.gyro.omega, atol=1e-12)
    assert "-z axis" in log.warnings[0]


def test_list_shows_topics_picks_and_frames(odom_bag):
    from typer.testing import CliRunner
    from odomgraph.cli import app
    path, src = odom_bag
    r = CliRunner().invoke(app, ["import", "rosbag", str(path), "--list"])
    assert r.exit_code == 0, r.output
    lines = r.output.splitlines()
    row = {ln.split()[0]: ln.split() for ln in lines[1:] if ln.startswith("/")}
    assert row["/diff_drive_controller/odom"][1:3] == ["nav_msgs/msg/Odometry", str(len(src.encoders.t) - 1)]
    assert row["/diff_drive_controller/odom"][-1] == "wheels" and row["/imu"][-1] == "imu"
    assert row["/fix"][-1] == "gps" and row["/tf_static"][-1] == "Hz"
    assert "tf_static: base_link -> gps (-0.450, +0.000, +0.500) m" in lines


def test_a_fused_odometry_is_not_taken_for_the_wheels(tmp_path):
    src = simulate(paper(30).with_(slips=()), 5)
    p = tmp_path / "two"
    _write_bag(p, src, wheels="odometry", extra_odom=True)
    log = import_rosbag(p, track_width=src.robot.track_width)
    assert any("picked /diff_drive_controller/odom" in n for n in log.notes)


def test_joint_names_are_found_and_a_missing_radius_is_said(bag):
    path, src = bag
    log = import_rosbag(path, wheel_radius=R_WHEEL, track_width=src.robot.track_width)
    e, r = src.encoders, src.robot
    np.testing.assert_allclose(log.wheel_speeds.v_left, e.ticks_left[1:] / (r.ticks_per_meter_left * np.diff(e.t)),
                               atol=1e-6)
    with pytest.raises(LogFormatError, match="give a positive --wheel-radius"):
        import_rosbag(path, track_width=0.6)
    with pytest.raises(LogFormatError, match=r"joints 'l'/'r' not in \['caster_joint'"):
        import_rosbag(path, left_joint="l", right_joint="r", wheel_radius=R_WHEEL, track_width=0.6)


JACKAL = Path(__file__).resolve().parent / "data" / "bags" / "jackal-test2.bag"


def test_the_jackal_bag_calibrates_ratio_and_track_and_holds_the_common_scale(tmp_path):
    """The real wheels + IMU bag (nav_msgs/Odometry, no absolute sensor):
    the common scale is not determined and stays nominal. The odometry says
    the robot turned 35.7 rad where the gyro says 4.8 rad (a skid-steer
    robot turns less than its wheels say): the track scale grows, and since
    the 5 % prior holds it far short of what the gyro asks, the result is
    flagged as implausible rather than passed off as a calibration."""
    from odomgraph.pipeline import calibrate
    log = import_rosbag(JACKAL, track_width=0.37)
    assert log.wheel_speeds.t[0] == pytest.approx(47.584) and log.gps is None and log.warnings == ()
    new, rep = calibrate(log, Schedule(None), Method.batch, tune=False)
    assert "scale_common" in rep["unobservable"] and "scale_track" not in rep["unobservable"]
    # ratio and track moved; the common scale did not
    kl, kr, kt = rep["scale"]["left"], rep["scale"]["right"], rep["scale"]["track"]
    assert 0.5 * (kl + kr) == pytest.approx(1.0, abs=1e-3)
    assert kt > 1.05
    assert any("scale_track came out +" in w and "implausible" in w for w in rep["warnings"]), rep["warnings"]
    h = rep["held_out"]
    assert h["kind"] == "gyro" and h["calibrated"] < h["nominal"]
    assert any("scale_common is not determined" in w for w in rep["warnings"])
    assert not any("calibration window" in w for w in rep["warnings"])


@pytest.mark.parametrize("storage", ["sqlite3", "mcap"])
@pytest.mark.parametrize("wheels,imu_axis,imu_tf", [("joints", "x", True), ("odometry", "y", False),
                                                     ("twist", "x", False), ("twist", "-z", True)])
def test_every_format_wheel_type_and_imu_mounting_calibrates_back(tmp_path, storage, wheels, imu_axis, imu_tf):
    """ROS 2 sqlite3 and mcap (ROS 1 .bag: the Jackal test); JointState,
    Odometry and TwistStamped wheels; the IMU's yaw on another axis, found
    through /tf_static or from the data. Each calibrates back to 0.5 %."""
    seed = {"joints": 6, "odometry": 7, "twist": 8}[wheels]
    src = simulate(paper(60).with_(slips=()), seed)
    p = tmp_path / f"{wheels}-{storage}"
    _write_bag(p, src, wheels=wheels, imu_axis=imu_axis, imu_tf=imu_tf, storage=storage, tf_lever=(-0.45, 0.0),
               no_fix_every=15)
    log = import_rosbag(p, wheel_radius=R_WHEEL, track_width=src.robot.track_width)
    np.testing.assert_allclose(log.gyro.omega, src.gyro.omega, atol=1e-9)
    if imu_tf:
        assert log.warnings == () and any("through /tf_static" in n for n in log.notes)
    else:
        assert len(log.warnings) == 1 and f"IMU's {imu_axis} axis" in log.warnings[0]
    assert log.robot.gps_lever_arm == (-0.45, 0.0)
    est = estimate(log, Method.batch, Schedule(None))
    for got, true in zip(est.mean[-1, 8:11], src.truth_scales):
        assert got == pytest.approx(true, rel=0.005)


def test_receive_stamps_are_an_option(odom_bag):
    path, src = odom_bag
    hdr = import_rosbag(path, track_width=src.robot.track_width)
    rx = import_rosbag(path, track_width=src.robot.track_width, stamps="receive")
    # the test bag records each message at its header stamp (to the nanosecond)
    np.testing.assert_allclose(rx.wheel_speeds.t, hdr.wheel_speeds.t, atol=2e-6, rtol=0)
    with pytest.raises(LogFormatError, match="--stamps must be header or receive"):
        import_rosbag(path, track_width=0.6, stamps="arrival")


def test_a_real_clock_gives_the_same_estimates(tmp_path):
    """Bags on a real clock start near 1.7e9 s, where a float64 stamp is
    quantised to 2.4e-7 s, so each interval moves by up to that much: about
    5e-6 of a 20 Hz interval. Every estimator's states agree to 1e-5 (measured
    1.7e-6 to 6.4e-6; the EKF's velocities see each interval directly), and
    the written states.csv keeps the microseconds."""
    from odomgraph.io.estimate import write_estimate
    from odomgraph.pipeline import summary
    log = simulate(paper(40).with_(slips=()), 3)
    t0 = 1.7e9

    def shift(x):
        return replace(x, t=x.t + t0)
    big = log.with_(encoders=shift(log.encoders), gps=shift(log.gps), gyro=shift(log.gyro), truth=shift(log.truth))
    for m in Method:
        a, b = estimate(log, m, Schedule(20.0)), estimate(big, m, Schedule(20.0))
        assert a.mean.shape == b.mean.shape
        np.testing.assert_allclose(b.t - t0, a.t, atol=5e-7, rtol=0)
        np.testing.assert_allclose(b.mean, a.mean, atol=1e-5, rtol=0)
        np.testing.assert_allclose(b.sigma, a.sigma, atol=1e-5, rtol=0)
    d = write_estimate(b, tmp_path / "est", summary(b, big, Schedule(20.0)))
    row = (d / "states.csv").read_text().splitlines()[1].split(",")
    assert abs(float(row[0]) - b.t[0]) < 1e-6
