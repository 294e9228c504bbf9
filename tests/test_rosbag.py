"""The rosbag importer: a ROS 2 bag written with rosbags itself from a
simulated log (JointState wheel positions, NavSatFix, Imu), imported back."""
from pathlib import Path

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")

from odomgraph import state as S  # noqa: E402
from odomgraph.errors import LogFormatError  # noqa: E402
from odomgraph.estimators.schedule import Schedule  # noqa: E402
from odomgraph.io.importers.rosbag import import_rosbag  # noqa: E402
from odomgraph.io.log import read_log  # noqa: E402
from odomgraph.pipeline import Method, estimate  # noqa: E402
from odomgraph.sim.scenarios import paper, yard  # noqa: E402
from odomgraph.sim.simulate import simulate  # noqa: E402

LAT0, LON0, R_WHEEL = 41.5045, -81.6086, 0.15


def _write_bag(path, log, wheels="joints", imu_axis="z", tf_lever=None, no_fix_every=0, t0=0.0,
               extra_odom=False, storage="sqlite3", imu_tf=False, nan_every=0, odom_twist=None, **wheels_opts):
    """A ROS 2 bag of ``log``: wheels as JointState positions or as the
    nav_msgs/Odometry twist; the gyro on IMU axis ``imu_axis`` ("-z": upside
    down); optionally /tf_static base_link -> gps with ``tf_lever``, every
    ``no_fix_every``-th fix without a fix (status -1), stamps moved by t0.
    ``wheels="twist"`` writes geometry_msgs/TwistStamped; ``imu_tf`` writes
    the IMU's mounting (yaw axis ``imu_axis``) into /tf_static; ``storage``:
    sqlite3 or mcap; ``nan_every``: every so many fixes a NaN latitude (status
    0), IMU samples a NaN yaw rate and odometry twists an infinite speed.
    ``odom_twist`` (odometry wheels): the pose dead-reckoned from the
    wheels as a diff-drive controller does (along the arc) and
    the twist "body" (REP 105), "odom" (in the odom frame), "zero" (a
    driver that fills only the pose), "crab" (a lateral speed of half the
    forward one in the body), "partial" (every 50th twist zero), "reset"
    (only the pose, reset to the origin halfway), "odom_unchecked" (in
    the odom frame, the pose left at the origin), "held" (as "partial", the
    pose updated at every 5th message only), "held_zero" (only that pose),
    "no_wz" (angular.z never filled) or "jitter" (a body twist beside a pose
    with 1 cm of noise); None: the pose at the origin, a body twist."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import StoragePlugin
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore
    ros1 = storage == "ros1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    if ros1:  # rosbags' Noetic store lacks tf2_msgs; a ROS 1 bag carries its definition
        from rosbags.typesys import get_types_from_msg
        ts.register(get_types_from_msg("geometry_msgs/TransformStamped[] transforms", "tf2_msgs/msg/TFMessage"))
    T = ts.types
    Time, Header = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"]
    base = int(t0)
    assert base == t0, "t0 is a whole second, so that stamps are exact"

    def header(t):
        """Stamp t0 + t, written from integers: a float of 1.7e9 + t is 2e-7 s off."""
        sec = int(np.floor(t))
        stamp = Time(sec=base + sec, nanosec=int(round((t - sec) * 1e9)))
        return Header(seq=0, stamp=stamp, frame_id="base_link") if ros1 else Header(stamp=stamp, frame_id="base_link")

    def at(t):  # the bag's receive time [ns], equal to the header stamp
        return base * 1_000_000_000 + int(round(t * 1e9))

    def ser(msg, typ):
        return ts.serialize_ros1(msg, typ) if ros1 else ts.serialize_cdr(msg, typ)

    a, e2 = 6_378_137.0, 6.69437999014e-3
    s2 = np.sin(np.radians(LAT0)) ** 2
    M, N = a * (1 - e2) / (1 - e2 * s2) ** 1.5, a / np.sqrt(1 - e2 * s2)
    V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with (Writer1(path) if ros1 else Writer(path, version=8, storage_plugin=plugin)) as w:
        cg = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
        ci = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        e, r = log.encoders, log.robot
        if wheels == "joints":
            cj = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
            angle_l = np.cumsum(e.ticks_left) / r.ticks_per_meter_left / R_WHEEL
            angle_r = np.cumsum(e.ticks_right) / r.ticks_per_meter_right / R_WHEEL
            for t, al, ar in zip(e.t, angle_l, angle_r):
                msg = T["sensor_msgs/msg/JointState"](header=header(t),
                                                      name=["caster_joint", "left_wheel_joint", "right_wheel_joint"],
                                                      position=np.array([0.3, al, ar]), velocity=np.array([], float),
                                                      effort=np.array([], float))
                w.write(cj, at(t), ser(msg, "sensor_msgs/msg/JointState"))
        elif wheels == "ticks":
            # bare std_msgs/Int16 counters, as a microcontroller publishes them: no header, the
            # right one 3 ms after the left, both wrapping at 2^15 (about 16 m at 2000 ticks/m)
            cl = w.add_connection("/wheel/left_ticks", "std_msgs/msg/Int16", typestore=ts)
            cr = w.add_connection("/wheel/right_ticks", "std_msgs/msg/Int16", typestore=ts)
            wrap = lambda c: ((c + 2**15) % 2**16) - 2**15
            every = 3 if wheels_opts.get("right_every3") else 1
            for k, (t, a, b) in enumerate(zip(e.t, np.cumsum(e.ticks_left), np.cumsum(e.ticks_right))):
                w.write(cl, at(t), ser(T["std_msgs/msg/Int16"](data=int(wrap(int(a)))), "std_msgs/msg/Int16"))
                if k % every == 0:
                    w.write(cr, at(t + 0.003), ser(T["std_msgs/msg/Int16"](data=int(wrap(int(b)))),
                                                   "std_msgs/msg/Int16"))
        elif wheels == "twist":
            ct = w.add_connection("/cmd_vel_measured", "geometry_msgs/msg/TwistStamped", typestore=ts)
            dt = np.diff(e.t)
            vl, vr = e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)
            for t, vi, wi in zip(e.t[1:], 0.5 * (vl + vr), (vr - vl) / r.track_width):
                msg = T["geometry_msgs/msg/TwistStamped"](
                    header=header(t), twist=T["geometry_msgs/msg/Twist"](linear=V3(x=vi, y=0.0, z=0.0),
                                                                             angular=V3(x=0.0, y=0.0, z=wi)))
                w.write(ct, at(t), ser(msg, "geometry_msgs/msg/TwistStamped"))
        else:
            topics = ["/diff_drive_controller/odom"] + (["/odometry/filtered"] if extra_odom else [])
            conns = [w.add_connection(tp, "nav_msgs/msg/Odometry", typestore=ts) for tp in topics]
            dt = np.diff(e.t)
            vl, vr = e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)
            v, om = 0.5 * (vl + vr), (vr - vl) / r.track_width
            P, Tw = T["geometry_msgs/msg/PoseWithCovariance"], T["geometry_msgs/msg/TwistWithCovariance"]
            px = py = th = 0.0
            held = (0.0, 0.0, 0.0)
            jit = np.random.default_rng(5)
            for k, (t, vi, wi) in enumerate(zip(e.t[1:], v, om)):
                if nan_every and k % nan_every == 5:
                    vi = np.inf
                lin = (vi, 0.0)
                if odom_twist is not None:
                    if odom_twist == "reset" and k == len(v) // 2:
                        px = py = th = 0.0          # the driver restarts: its pose from the origin again
                    # as diff_drive_controller integrates: along the arc (second-order Runge-Kutta
                    # below 1e-6 rad/s)
                    if abs(wi) < 1e-6:
                        px += vi * dt[k] * np.cos(th + 0.5 * wi * dt[k])
                        py += vi * dt[k] * np.sin(th + 0.5 * wi * dt[k])
                    else:
                        px += vi / wi * (np.sin(th + wi * dt[k]) - np.sin(th))
                        py -= vi / wi * (np.cos(th + wi * dt[k]) - np.cos(th))
                    th += wi * dt[k]
                    lin = {"odom": (vi * np.cos(th), vi * np.sin(th)), "crab": (vi, 0.5 * vi)}.get(odom_twist, lin)
                    if (odom_twist in ("zero", "reset", "held_zero")
                            or (odom_twist in ("partial", "held") and k % 50 == 7)):
                        lin, wi = (0.0, 0.0), 0.0
                    if odom_twist == "no_wz":
                        wi = 0.0
                out = (px, py, th)
                if odom_twist == "odom_unchecked":
                    lin, out = (vi * np.cos(th), vi * np.sin(th)), (0.0, 0.0, 0.0)
                if odom_twist in ("held", "held_zero"):
                    # the pose republished at every message, updated at every 5th
                    held = out if k % 5 == 4 else held
                    out = held
                if odom_twist == "jitter":
                    # a fused pose: 1 cm and 5 mrad of noise at every message, stops included
                    out = (px + 0.01 * jit.standard_normal(), py + 0.01 * jit.standard_normal(),
                           th + 0.005 * jit.standard_normal())
                Pt = T["geometry_msgs/msg/Point"](x=out[0], y=out[1], z=0.0)
                msg = T["nav_msgs/msg/Odometry"](
                    header=header(t), child_frame_id="base_link",
                    pose=P(pose=T["geometry_msgs/msg/Pose"](position=Pt, orientation=Q(x=0.0, y=0.0, z=np.sin(0.5 * out[2]),
                                                                                       w=np.cos(0.5 * out[2]))),
                           covariance=np.zeros(36)),
                    twist=Tw(twist=T["geometry_msgs/msg/Twist"](linear=V3(x=lin[0], y=lin[1], z=0.0),
                                                               angular=V3(x=0.0, y=0.0, z=wi)),
                             covariance=np.zeros(36)))
                for c in conns:
                    w.write(c, at(t), ser(msg, "nav_msgs/msg/Odometry"))
        trs = []
        if tf_lever is not None:
            trs.append(T["geometry_msgs/msg/TransformStamped"](
                header=header(0.0), child_frame_id="gps",
                transform=T["geometry_msgs/msg/Transform"](translation=V3(x=tf_lever[0], y=tf_lever[1], z=0.5),
                                                           rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0))))
        if imu_tf:
            # the rotation that takes the IMU's yaw axis onto base_link's z
            h = np.sqrt(0.5)
            q = {"x": Q(x=0.0, y=-h, z=0.0, w=h), "y": Q(x=h, y=0.0, z=0.0, w=h), "z": Q(x=0.0, y=0.0, z=0.0, w=1.0),
                 "-z": Q(x=1.0, y=0.0, z=0.0, w=0.0)}[imu_axis]
            trs.append(T["geometry_msgs/msg/TransformStamped"](
                header=header(0.0), child_frame_id="imu_link",
                transform=T["geometry_msgs/msg/Transform"](translation=V3(x=0.1, y=0.0, z=0.2), rotation=q)))
        if trs:
            ct = w.add_connection("/tf_static", "tf2_msgs/msg/TFMessage", typestore=ts)
            w.write(ct, at(0.0), ser(T["tf2_msgs/msg/TFMessage"](transforms=trs),
                                                        "tf2_msgs/msg/TFMessage"))
        g = log.gps
        for k, (t, x, y) in enumerate(zip(g.t, g.x, g.y)):
            cov = np.zeros(9)
            cov[0] = cov[4] = r.gps_sigma**2
            bad = no_fix_every and k % no_fix_every == 0
            hd = header(t)
            hd.frame_id = "gps"
            msg = T["sensor_msgs/msg/NavSatFix"](
                header=hd, status=T["sensor_msgs/msg/NavSatStatus"](status=-1 if bad else 0, service=1),
                latitude=(np.nan if nan_every and k % nan_every == 3 else
                          LAT0 + np.degrees(y / M) + (1.0 if bad else 0.0)),
                longitude=LON0 + np.degrees(x / (N * np.cos(np.radians(LAT0)))),
                altitude=200.0, position_covariance=cov, position_covariance_type=2)
            w.write(cg, at(t), ser(msg, "sensor_msgs/msg/NavSatFix"))
        sign = -1.0 if imu_axis.startswith("-") else 1.0
        for k, (t, om) in enumerate(zip(log.gyro.t, log.gyro.omega)):
            rate = {a: (sign * om if a == imu_axis[-1] else 0.001 * np.sin(7 * t)) for a in "xyz"}
            if nan_every and k % nan_every == 7:
                rate[imu_axis[-1]] = np.nan
            hd = header(t)
            hd.frame_id = "imu_link"
            msg = T["sensor_msgs/msg/Imu"](header=hd, orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                                           orientation_covariance=np.zeros(9), angular_velocity=V3(**rate),
                                           angular_velocity_covariance=np.zeros(9),
                                           linear_acceleration=V3(x=0.0, y=0.0, z=9.81),
                                           linear_acceleration_covariance=np.zeros(9))
            w.write(ci, at(t), ser(msg, "sensor_msgs/msg/Imu"))


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
    assert sorted(p.name for p in (tmp_path / "log").iterdir() if p.name != ".odomgraph") == ["gps.csv", "gyro.csv", "import.json",
                                                                     "robot.toml", "wheel_speeds.csv"]
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
    # v -/+ omega b/2 gives the wheel speeds back, stamped on the real clock
    # (counted from its first whole second) to the nanosecond the bag holds
    np.testing.assert_allclose(log.wheel_speeds.v_left, e.ticks_left[1:] / (r.ticks_per_meter_left * dt), atol=1e-9)
    assert log.t_origin == 1_700_000_000
    np.testing.assert_allclose(log.wheel_speeds.t, e.t[1:], atol=1e-9, rtol=0)
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


@pytest.mark.parametrize("storage", ["ros1", "sqlite3"])
def test_non_finite_messages_are_dropped_counted_and_said(tmp_path, storage):
    """A probe's ROS 1 bag: NavSatFix messages with a NaN latitude (status
    0) and Imu messages with a NaN yaw rate were written into gps.csv and
    gyro.csv as nan rows, the IMU axis check read no correlation, and the
    log could not be estimated; an infinite odometry speed printed numpy
    warnings. Here every 40th of each (other offsets, another seed)."""
    log = simulate(paper(60).with_(slips=()), 8)
    path = tmp_path / ("nan.bag" if storage == "ros1" else "nan")
    _write_bag(path, log, wheels="odometry", imu_axis="y", storage=storage, nan_every=40, tf_lever=log.robot.gps_lever_arm)
    import warnings as pywarnings
    with pywarnings.catch_warnings():
        pywarnings.simplefilter("error")                # no numpy RuntimeWarning on the way
        got = import_rosbag(path, track_width=log.robot.track_width)
    n = lambda total, off: len(range(off, total, 40))
    assert len(got.gps.t) == len(log.gps.t) - n(len(log.gps.t), 3)
    assert len(got.gyro.t) == len(log.gyro.t) - n(len(log.gyro.t), 7)
    assert len(got.wheel_speeds.t) == len(log.encoders.t) - 1 - n(len(log.encoders.t) - 1, 5)
    for arr in (got.gps.x, got.gps.y, got.gyro.omega, got.wheel_speeds.v_left, got.wheel_speeds.v_right):
        assert np.all(np.isfinite(arr))
    said = {line.split(":")[0]: int(line.split(": ")[1].split()[0]) for line in got.notes if "not a finite" in line}
    assert said == {"/fix": n(len(log.gps.t), 3), "/imu": n(len(log.gyro.t), 7),
                    "/diff_drive_controller/odom": n(len(log.encoders.t) - 1, 5)}
    assert not [w for w in got.warnings if "no IMU axis" in w]           # the y axis still found
    est = estimate(got, Method.batch, Schedule(None))
    for k, true in zip(est.mean[-1, S.SCALE], log.truth_scales):
        assert k == pytest.approx(true, rel=0.01)


def test_imu_axis_can_be_forced_and_an_upside_down_imu_is_flipped(odom_bag, tmp_path):
    path, src = odom_bag
    z = import_rosbag(path, track_width=src.robot.track_width, imu_axis="z")
    assert np.abs(z.gyro.omega).max() < 0.0011 and z.warnings == ()
    src2 = simulate(paper(40).with_(slips=()), 4)
    p2 = tmp_path / "upside"
    _write_bag(p2, src2, wheels="odometry", imu_axis="-z")
    log = import_rosbag(p2, track_width=src2.robot.track_width)
    np.testing.assert_allclose(log.gyro.omega, src2.gyro.omega, atol=1e-12)
    assert any("-z axis" in w for w in log.warnings) and any("lever arm is unknown" in w for w in log.warnings)


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


@pytest.mark.parametrize("twist", ["body", "odom", "zero", "crab", "partial", "reset", "odom_unchecked", "held",
                                   "held_zero", "no_wz", "jitter"])
def test_an_odometry_twist_in_the_odom_frame_or_a_pose_alone_gives_the_body_speeds(tmp_path, twist):
    """REP 105 puts Odometry's twist in child_frame_id. A driver that fills
    only the pose (every twist zero) imported as a robot standing still, and
    one that writes the twist in the odom frame as speeds scaled by the
    cosine of the heading. The pose, dead-reckoned as a diff-drive controller
    does, gives the body's speeds back (another scenario and seed than the
    other odometry bags), also where only some twists are zero, and leaves a
    pose reset out; a twist with a lateral speed no heading explains, or
    one whose frame a pose that never moves cannot tell, is a warning."""
    src = simulate(yard(60.0), 17)
    e, r = src.encoders, src.robot
    dt = np.diff(e.t)
    vl, vr = e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)
    _write_bag(tmp_path / twist, src, wheels="odometry", odom_twist=twist, tf_lever=r.gps_lever_arm)
    log = import_rosbag(tmp_path / twist, track_width=r.track_width)
    ws = log.wheel_speeds
    if twist == "body":
        # a clean bag: its own speeds, not a word (a probe: the sim's genuine 1-tick zeros as the
        # robot starts were taken for placeholders)
        np.testing.assert_allclose(ws.v_left, vl, atol=1e-12)
        assert not any("twist" in n and "pose" in n for n in log.notes) and log.warnings == ()
    elif twist == "odom":
        np.testing.assert_allclose(ws.t, e.t[1:], atol=1e-9, rtol=0)
        np.testing.assert_allclose(ws.v_left, vl, atol=1e-9)
        np.testing.assert_allclose(ws.v_right, vr, atol=1e-9)
        assert any("twist is in the odom frame" in n for n in log.notes)
    elif twist in ("zero", "reset"):
        # one row per interval between messages, at its midpoint: the twist of the later message where
        # the pose moved over it and over the one before (its own update interval), else the mean over
        # the update that holds it (a stop, or creeping by single ticks), never a spike
        mids = 0.5 * (e.t[1:-1] + e.t[2:])
        j = np.clip(np.searchsorted(mids, ws.t - 1e-9), 0, mids.size - 1)
        assert np.all(np.abs(mids[j] - ws.t) < 1e-9) and ws.t.size >= mids.size - (1 if twist == "reset" else 0)
        mv = np.abs(vl) + np.abs(vr) > 0
        exact = (mv[1:] & mv[:-1])[j]
        np.testing.assert_allclose(ws.v_left[exact], vl[1:][j[exact]], atol=1e-6)
        np.testing.assert_allclose(ws.v_right[exact], vr[1:][j[exact]], atol=1e-6)
        assert exact.sum() > 0.9 * ws.t.size
        for got, want in ((ws.v_left, vl), (ws.v_right, vr)):
            assert np.abs(got).max() <= np.abs(want).max() + 1e-6
        # the rows that are no single interval (a pose unchanged for a few messages: quantised creeping)
        # keep the distance: each wheel's path within 1 %
        for got, want in ((ws.v_left, vl), (ws.v_right, vr)):
            assert np.trapezoid(got, ws.t) == pytest.approx(np.sum(want * dt), rel=0.01)
        if twist == "zero":
            assert any("every twist is zero while the pose's wheels travel" in n for n in log.notes)
        else:
            assert any("1 pose jump(s) (a driver resetting it?) left out" in n for n in log.notes)
            assert not any("sideways" in w for w in log.warnings)
    elif twist == "partial":
        # a probe: 2 % of the twists zero while the pose moved gave scale factors z -18 with no word.
        # Message m's twist is interval m's mean (e.t[m], e.t[m + 1]); a placeholder's row comes from the
        # pose's step over that interval, at its midpoint
        m = np.arange(len(vl))
        # (a twist of 0 where the robot stands: its pose does not move either)
        ph = (m % 50 == 7) & (np.abs(vl) + np.abs(vr) > 0)
        np.testing.assert_allclose(ws.t, e.t[1:], atol=1e-9, rtol=0)
        np.testing.assert_allclose(ws.v_left, vl, atol=1e-6)
        np.testing.assert_allclose(ws.v_right, vr, atol=1e-6)
        assert any(f"{int(ph.sum())} messages with a zero twist while the pose moved as the twists either side say: "
                   f"{int(ph.sum())} of those" in n for n in log.notes), log.notes
    elif twist == "held":
        # a probe: the pose's step from the message before read 5x the speed, or 0: track z -9, status ok.
        # A placeholder's row is the mean over the pose update that brings its motion (5 messages)
        m = np.arange(len(vl))
        ph = (m % 50 == 7) & (np.abs(vl) + np.abs(vr) > 0)
        np.testing.assert_allclose(ws.t, e.t[1:], atol=1e-9, rtol=0)
        # (a twist of 0 at the edge of a real stop may take the pose's mean over its update: a few rows)
        assert np.sum(np.abs(ws.v_left - vl)[~ph] > 1e-9) <= 0.005 * vl.size
        assert np.sqrt(np.mean((ws.v_left - vl) ** 2)) < 0.01
        assert np.sqrt(np.mean((ws.v_left - vl)[ph] ** 2)) < 0.05
        assert any("messages repeat the pose before them" in n for n in log.notes)
    elif twist == "held_zero":
        for got, want in ((ws.v_left, vl), (ws.v_right, vr)):
            assert np.trapezoid(got, ws.t) == pytest.approx(np.sum(want * dt), rel=0.01)
        assert np.abs(ws.v_left).max() < 1.5 * np.abs(vl).max()
    elif twist == "no_wz":
        # a probe: the track 0.515, z -59 (the estimate flagged it; the import, holding the pose's turns, did not)
        assert any("angular.z is zero in every message while the pose turns" in n for n in log.notes)
        assert ws.t.size == vl.size - 1        # the first message: no pose update before it
        # (a pose unchanged over a few messages, creeping by single ticks: the mean turn over them)
        for got, want in ((ws.v_left, vl[1:]), (ws.v_right, vr[1:])):
            assert np.sqrt(np.mean((got - want) ** 2)) < 2e-3 and np.abs(got - want).max() < 0.05
    elif twist == "jitter":
        # the pose's noise does not replace a twist of 0 at a real stop
        assert np.sum((vl == 0) & (vr == 0)) > 50
        np.testing.assert_allclose(ws.v_left, vl, atol=1e-12)
        assert not any("zero twist while the pose moved" in n for n in log.notes)
    elif twist == "crab":
        np.testing.assert_allclose(ws.v_left, vl, atol=1e-9)
        assert sum("lateral speed" in w and "only its forward speed" in w for w in log.warnings) == 1
        return
    else:
        # the yard turns every way: its odom-frame twist's lateral speed is most of it, said as such
        # (test_a_twist_whose_frame_cannot_be_checked_is_said: one heading near x)
        assert sum("linear.x is used" in w for w in log.warnings) == 1
        return
    assert not any("lateral speed" in w for w in log.warnings)
    est = estimate(log, Method.batch, Schedule(None))
    for got, true, sd in zip(est.mean[-1, 8:11], src.truth_scales, est.sigma[-1, 8:11]):
        assert abs(got - true) < 3.5 * sd


def _twist_rows(n=1200, hz=20.0, heading=0.1, spin=False, seed=3):
    """A body moving (or pivoting, ``spin``) with a weaving speed: times
    (n,) [s], forward speed [m/s], yaw rate [rad/s], and the pose (x, y,
    yaw) dead-reckoned from them; the heading stays within ``heading`` rad
    of the x axis."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / hz
    v = np.zeros(n) if spin else 0.8 + 0.3 * np.sin(0.3 * t) + 0.01 * rng.standard_normal(n)
    yaw = (1.2 * t) if spin else heading * np.sin(0.2 * t)
    om = np.gradient(yaw, t)
    x, y = np.cumsum(v * np.cos(yaw)) / hz, np.cumsum(v * np.sin(yaw)) / hz
    return t, v, om, x, y, yaw


def test_a_twist_whose_frame_cannot_be_checked_is_said():
    """An odom-frame twist heading within 6 degrees of x beside a pose left
    at the origin: its lateral speed is a tenth of the forward one, under
    the 20 % that makes a twist not a diff drive's, and linear.x is the
    speed times cos(heading), 0.5 % short (a probe's: 2 %, scale factors z
    -9, with no word). Said; a body twist with no lateral speed is not."""
    from odomgraph.io.importers.rosbag import _body_twist
    t, v, om, x, y, yaw = _twist_rows()
    notes, warnings = [], []
    zero = np.zeros_like(t)
    _body_twist("/odom", t, v * np.cos(yaw), v * np.sin(yaw), om, zero, zero, zero, 0.5, notes, warnings)
    assert len(warnings) == 1 and "the pose does not move, so the twist's frame cannot be checked" in warnings[0]
    warnings.clear()
    _body_twist("/odom", t, v, zero, om, zero, zero, zero, 0.5, notes, warnings)
    assert warnings == [] and notes == []
    # with the pose the driver integrated, the same twist is rotated into the body
    tt, fwd, w = _body_twist("/odom", t, v * np.cos(yaw), v * np.sin(yaw), om, x, y, yaw, 0.5, notes, warnings)
    np.testing.assert_allclose(fwd, v, atol=1e-12)
    assert warnings == [] and any("the twist is in the odom frame" in n for n in notes)


def test_a_pose_only_driver_pivoting_in_place_gives_its_yaw_rate():
    """A pose-only driver (every twist zero) whose robot pivots in place (a
    track calibration run): the pose moves no metre, but its wheels travel
    track / 2 x the turn; the yaw rate comes from the pose (a probe: imported
    as standing still, the track left at its prior). A pose whose yaw stays
    0 while the robot drives a weave is said (its steps go sideways), and a
    NaN pose is left out, not the whole pose."""
    from odomgraph.io.importers.rosbag import _body_twist
    t, v, om, x, y, yaw = _twist_rows(spin=True)
    zero = np.zeros_like(t)
    notes, warnings = [], []
    tt, fwd, w = _body_twist("/odom", t, zero, zero, zero, x, y, yaw, 0.5, notes, warnings)
    np.testing.assert_allclose(w, 1.2, atol=1e-9)
    np.testing.assert_allclose(fwd, 0.0, atol=1e-12)
    assert warnings == [] and "every twist is zero while the pose's wheels travel" in notes[0]
    t, v, om, x, y, yaw = _twist_rows(heading=0.8)
    notes = []
    _body_twist("/odom", t, zero, zero, zero, x, y, zero, 0.5, notes, warnings)
    assert len(warnings) == 1 and "the pose steps sideways to its own heading" in warnings[0]
    x[100], warnings = np.nan, []
    tt, fwd, w = _body_twist("/odom", t, zero, zero, zero, x, y, yaw, 0.5, notes, warnings)
    assert warnings == [] and tt.size == t.size - 2 and any("1 messages with a pose that is not" in n for n in notes)
    assert np.all(np.isfinite(fwd)) and np.abs(fwd - np.interp(tt, t, v)).max() < 0.05


def test_pose_resets_jitter_and_odom_frame_placeholders_from_a_second_read():
    """A second read's inputs (other rates and lengths than the bags above):
    a pose reset while the robot stands (its step was put in the stop's last
    period: a -500 m/s row), in a 60-message bag (the reset its own
    reference: -19.5 m/s), and at 0.15 m/s on a 100 Hz pose (1.5 mm steps
    were not "moving": -450 m/s); a parked robot's jittery pose beside a
    zero twist (57.7 m of travel summed step by step: 0.7 m/s rows); a
    placeholder in an odom-frame twist (rotated twice: 0.07 for 1.0 m/s);
    a pose NaN in most messages (said)."""
    from odomgraph.io.importers.rosbag import _body_twist
    z = lambda t: np.zeros_like(t)
    for hz, x_of in ((50.0, lambda t: np.where(t < 20, 0.5 * t, np.where(t < 30, 10.0, 0.5 * (t - 30)))),
                     (10.0, lambda t: np.where(t < 3, 0.5 * t, 0.5 * (t - 3))),
                     (100.0, lambda t: np.where(t < 30, 0.15 * t, 0.15 * (t - 30)))):
        t = np.arange(0, {50.0: 50, 10.0: 6, 100.0: 60}[hz], 1 / hz)
        notes, warnings = [], []
        tt, fwd, w = _body_twist("/odom", t, z(t), z(t), z(t), x_of(t), z(t), z(t), 0.5, notes, warnings)
        assert fwd.min() >= 0.0 and fwd.max() <= 0.5 + 1e-9, (hz, fwd.min(), fwd.max())
        assert any("1 pose jump(s) (a driver resetting it?) left out" in n for n in notes), (hz, notes)
    rng = np.random.default_rng(9)
    t = np.arange(0, 60, 0.02)
    notes, warnings = [], []
    tt, fwd, w = _body_twist("/odom", t, z(t), z(t), z(t), 0.01 * rng.standard_normal(t.size),
                             0.01 * rng.standard_normal(t.size), 0.005 * rng.standard_normal(t.size), 0.5, notes,
                             warnings)
    assert not np.any(fwd) and not np.any(w) and not any("travel" in n for n in notes)
    # an odom-frame twist with every 50th zeroed: the pose fills those, in the body already
    t, v, om, x, y, yaw = _twist_rows(heading=2.0)
    vx, vy, wz = v * np.cos(yaw), v * np.sin(yaw), om.copy()
    for a in (vx, vy, wz):
        a[7::50] = 0.0
    notes, warnings = [], []
    tt, fwd, w = _body_twist("/odom", t, vx, vy, wz, x, y, yaw, 0.5, notes, warnings)
    assert tt.size == t.size and any("twist is in the odom frame" in n for n in notes)
    assert np.abs(fwd - v)[7::50].max() < 0.02 and np.abs(np.delete(fwd - v, np.s_[7::50])).max() < 1e-9
    # a pose NaN in most messages: not used, and said
    x[: 2 * t.size // 3] = np.nan
    notes = []
    _body_twist("/odom", t, v, z(t), om, x, y, yaw, 0.5, notes, warnings)
    assert any(f"the pose is not a finite number in {2 * t.size // 3} of {t.size} messages: not used" in n
               for n in notes)


def test_irregular_updates_gaps_warm_up_and_jitter_from_a_third_probe():
    """A third probe's inputs, other seeds and rates: a pose-only driver
    whose pose updates at random times (read as stops, each step squeezed
    into one period: 16 m/s rows, z -30), or whose messages stop for 1 s
    while it drives (one 17 m/s row per gap); a twist left zero for the
    first 10 s (kept as a stand: 16 % short); a straight drive whose
    angular.z is rightly 0 beside a pose with 1 mrad of yaw jitter (taken
    as never filled: the jitter's turns into the wheels)."""
    from odomgraph.io.importers.rosbag import _body_twist
    rng = np.random.default_rng(31)
    t, v, om, x, y, yaw = _twist_rows(n=3000, hz=50.0, heading=1.5)
    zero = np.zeros_like(t)
    # the pose republished at every message, updated at random (about every 4th)
    upd = np.flatnonzero(rng.random(t.size) < 0.25)
    last = np.maximum.accumulate(np.where(np.isin(np.arange(t.size), upd), np.arange(t.size), 0))
    notes, warnings = [], []
    tt, fwd, w = _body_twist("/odom", t, zero, zero, zero, x[last], y[last], yaw[last], 0.5, notes, warnings)
    assert np.abs(fwd).max() <= 1.05 * np.abs(v).max()
    assert np.trapezoid(fwd, tt) == pytest.approx(np.trapezoid(v, t), rel=0.01)
    # one row per message interval (a fourth probe: rows at irregular update midpoints beside 100 Hz
    # rows at stops put batch at z -21), and no late update taken for a reset
    # (up to the pose's last update: the messages after it hold no motion yet)
    assert tt.size > t.size - 30
    np.testing.assert_allclose(tt, 0.5 * (t[1:] + t[:-1])[: tt.size], atol=1e-12)
    assert not any("jump" in n for n in notes)
    # 1 s without messages, three times
    keep = ~(((t > 10) & (t < 11)) | ((t > 25) & (t < 26)) | ((t > 40) & (t < 41)))
    notes = []
    tt, fwd, w = _body_twist("/odom", t[keep], zero[keep], zero[keep], zero[keep], x[keep], y[keep], yaw[keep],
                             0.5, notes, [])
    assert np.abs(fwd).max() <= 1.05 * np.abs(v).max() and not any("jump" in n for n in notes)
    # the first 10 s zero, the rest a real body twist
    vx, wz = v.copy(), om.copy()
    vx[t < 10], wz[t < 10] = 0.0, 0.0
    notes = []
    tt, fwd, w = _body_twist("/odom", t, vx, zero, wz, x, y, yaw, 0.5, notes, [])
    # (the first message has no pose update before it: left out)
    assert tt.size == t.size - 1 and np.abs(fwd - v[1:]).max() < 0.01
    assert any("messages with a zero twist while the pose moved" in n and "1 left out" in n for n in notes)
    # a 100 ticks/m encoder at 50 Hz creeping at 0.3 m/s: most intervals 0 or 1 tick, the pose the
    # driver integrates repeating at each genuine zero; none is rebuilt (a fourth probe: 248-563 were,
    # path 106-113 %, z +5, or batch diverged)
    t = np.arange(3000) / 50.0
    ticks = np.diff(np.floor(100.0 * 0.3 * t + 0.3 * np.sin(0.5 * t)), prepend=0.0)
    v = ticks / 100.0 * 50.0
    x = np.cumsum(v) / 50.0
    notes = []
    tt, fwd, w = _body_twist("/odom", t, v, zero, zero, x, zero, zero, 0.5, notes, [])
    assert np.sum(v == 0) > 1000 and notes == []
    np.testing.assert_array_equal(fwd, v)
    # a driver that skips a read in 3 % of its messages: the twist 0 and the pose repeated, the next
    # message catching the pose up (a fifth probe: kept as genuine zeros, path 97 %, z -21); where the
    # next twist carries the missed motion, the zero is right as it is
    t, v, om, x, y, yaw = _twist_rows(n=3000, hz=50.0, heading=1.0)
    stale = np.flatnonzero(rng.random(t.size) < 0.03)
    stale = stale[(stale > 0) & (stale < t.size - 1)]
    stale = stale[np.diff(stale, prepend=-2) > 1]          # single skipped reads
    xs, ys, ths = x.copy(), y.copy(), yaw.copy()
    xs[stale], ys[stale], ths[stale] = x[stale - 1], y[stale - 1], yaw[stale - 1]
    vx, wz = v.copy(), om.copy()
    vx[stale], wz[stale] = 0.0, 0.0
    notes = []
    tt, fwd, w = _body_twist("/odom", t, vx, zero, wz, xs, ys, ths, 0.5, notes, [])
    assert np.abs(fwd - v)[stale].max() < 0.05 and any(f"{stale.size} messages with a zero twist" in n
                                                        for n in notes)
    vc = vx.copy()
    vc[stale + 1] += v[stale]                                # the next twist carries the missed motion
    notes = []
    tt, fwd, w = _body_twist("/odom", t, vc, zero, wz, xs, ys, ths, 0.5, notes, [])
    np.testing.assert_array_equal(fwd, vc)
    assert not any("zero twist" in n for n in notes)
    # the pose republished at 100 Hz and updated at every 10th message, 10 % of the twists zero: the
    # zeros in one update are judged together (a sixth probe: each against the whole, 2-3 in one update
    # were kept, path 95 %, z -19)
    t, v, om, x, y, yaw = _twist_rows(n=3000, hz=100.0, heading=1.0)
    zero = np.zeros_like(t)
    last = (np.arange(t.size) // 10) * 10
    gone = np.flatnonzero(rng.random(t.size) < 0.1)
    gone = gone[(gone > 10) & (gone < t.size - 20)]
    vx, wz = v.copy(), om.copy()
    vx[gone], wz[gone] = 0.0, 0.0
    notes = []
    tt, fwd, w = _body_twist("/odom", t, vx, zero, wz, x[last], y[last], yaw[last], 0.5, notes, [])
    j = np.searchsorted(t, tt)
    assert np.abs(fwd - v[j])[np.isin(j, gone)].max() < 0.2
    assert any(f"{gone.size} messages with a zero twist while the pose moved" in n for n in notes)
    assert np.trapezoid(fwd, tt) == pytest.approx(np.trapezoid(v, t), rel=0.01)
    # the same with a pose updated at every 2nd message and the missed motion carried by the next
    # twist: a zero on an update message is judged with the next update (a seventh probe: filled and
    # counted twice, path 104 %, track z +8.4)
    t, v, om, x, y, yaw = _twist_rows(n=3000, hz=50.0, heading=1.0)
    zero = np.zeros_like(t)
    last = (np.arange(t.size) // 2) * 2
    gone = np.flatnonzero(rng.random(t.size) < 0.1)
    gone = gone[(gone > 4) & (gone < t.size - 6)]
    gone = gone[np.diff(gone, prepend=-3) > 2]
    vc, wz = v.copy(), om.copy()
    vc[gone + 1] += v[gone]
    wz[gone + 1] += om[gone]
    vc[gone], wz[gone] = 0.0, 0.0
    notes = []
    tt, fwd, w = _body_twist("/odom", t, vc, zero, wz, x[last], y[last], yaw[last], 0.5, notes, [])
    assert np.trapezoid(fwd, tt) == pytest.approx(np.trapezoid(vc, t), rel=2e-3)
    assert np.sum(fwd != vc[np.searchsorted(t, tt)]) <= 0.05 * gone.size
    # a pose that updates at every message but stalls for 6-10 messages five times while the robot
    # drives: caught up, not a reset (a fifth probe: taken for jumps, their rows left out, z -4)
    xs, ys, ths = x.copy(), y.copy(), yaw.copy()
    for k0 in (300, 800, 1400, 2000, 2600):
        n_hold = 6 + k0 % 5
        xs[k0:k0 + n_hold], ys[k0:k0 + n_hold], ths[k0:k0 + n_hold] = x[k0 - 1], y[k0 - 1], yaw[k0 - 1]
    notes = []
    tt, fwd, w = _body_twist("/odom", t, zero, zero, zero, xs, ys, ths, 0.5, notes, [])
    assert not any("jump" in n for n in notes) and tt.size == t.size - 1
    assert np.abs(fwd).max() <= 1.05 * np.abs(v).max()
    # a straight drive: angular.z 0 in every message, the pose's yaw jittering by 1 mrad
    t, v, om, x, y, yaw = _twist_rows(n=3000, hz=50.0, heading=0.0)
    notes = []
    tt, fwd, w = _body_twist("/odom", t, v, zero, zero, x, y, 0.001 * rng.standard_normal(t.size), 0.5, notes, [])
    assert notes == [] and not np.any(w)


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


def test_the_jackal_ekf_s_nis_line_blames_the_model_not_the_sigma():
    """The Jackal's EKF encoder NIS is about 9x its dimension, while the
    wheel rows scatter a quarter of robot.toml's sigma from one to the
    next: the line says the sigma does not explain it and names the model (a
    skid-steer's turns), not the usual list of three causes."""
    log = import_rosbag(JACKAL, track_width=0.37)
    est = estimate(log, Method.ekf)
    f = est.noise_scales["encoders"]["measured"]
    assert 0.2 < f < 0.3 and est.noise_scales["encoders"]["applied"] == 1.0
    line = [w for w in est.warnings if w.startswith("encoders: mean NIS")]
    assert len(line) == 1 and f"the rows scatter {f:.2g}x robot.toml's sigma" in line[0]
    assert "which does not explain it: motion the model does not hold (a skid-steer's turns" in line[0]


MOUNTINGS = [("joints", "x", True), ("odometry", "y", False), ("twist", "x", False), ("twist", "-z", True)]


@pytest.mark.parametrize("storage,wheels,imu_axis,imu_tf",
                         [(s, *m) for s in ("sqlite3", "mcap") for m in MOUNTINGS]
                         + [("ros1", "joints", "-z", True), ("ros1", "odometry", "x", False),
                            ("ros1", "twist", "y", True)])
def test_every_format_wheel_type_and_imu_mounting_calibrates_back(tmp_path, storage, wheels, imu_axis, imu_tf):
    """ROS 1 .bag, ROS 2 sqlite3 and mcap, written with rosbags; JointState,
    Odometry and TwistStamped wheels; the IMU's yaw on another axis, found
    through /tf_static or from the data; NavSatFix with covariance and every
    15th fix without a fix. Each calibrates back to 0.5 %."""
    seed = {"joints": 6, "odometry": 7, "twist": 8}[wheels]
    src = simulate(paper(60).with_(slips=()), seed)
    p = tmp_path / (f"{wheels}.bag" if storage == "ros1" else f"{wheels}-{storage}")
    _write_bag(p, src, wheels=wheels, imu_axis=imu_axis, imu_tf=imu_tf, storage=storage, tf_lever=(-0.45, 0.0),
               no_fix_every=15)
    # (--wheel-radius only for JointState wheels: given for others it is refused)
    log = import_rosbag(p, wheel_radius=R_WHEEL if wheels == "joints" else None, track_width=src.robot.track_width)
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


def _same(got, want, path=""):
    """``got`` holds every entry of ``want``: numbers to 1e-9 relative, the rest equal."""
    if isinstance(want, dict):
        for k, v in want.items():
            _same(got[k], v, f"{path}.{k}")
    elif isinstance(want, (list, tuple)):
        assert len(got) == len(want), path
        for k, (g, w) in enumerate(zip(got, want)):
            _same(g, w, f"{path}[{k}]")
    elif isinstance(want, float):
        assert got == pytest.approx(want, rel=1e-9, abs=1e-12), path
    else:
        assert got == want, path


def test_a_real_clock_gives_the_same_estimates(tmp_path):
    """A log on a real clock (stamps near 1.7e9 s, where a float64 keeps only
    0.24 us) reads into whole seconds since its origin, exactly: every
    estimator then gives the same states to 1e-9 relative (measured: at most
    4e-11 m, the EKF; 2e-13 the smoothers), the states.csv it writes holds the absolute stamps, digit
    for digit, and the comparison's metrics are the same."""

    from odomgraph.analysis.compare import comparison_metrics
    from odomgraph.io.log import write_log
    from odomgraph.pipeline import estimate_to_dir
    src = simulate(paper(40).with_(slips=()), 3)
    origin = 1_700_000_000
    write_log(src, tmp_path / "small")
    write_log(src.with_(t_origin=origin), tmp_path / "big")
    a, b = read_log(tmp_path / "small"), read_log(tmp_path / "big")
    first = (tmp_path / "big" / "encoders.csv").read_text().splitlines()[1].split(",")[0]
    assert first == f"{origin + int(src.encoders.t[0])}.{round((src.encoders.t[0] % 1) * 1e6):06d}"
    assert (a.t_origin, b.t_origin) == (0, origin)
    for name in ("encoders", "gps", "gyro", "truth"):
        np.testing.assert_allclose(getattr(b, name).t, getattr(a, name).t, rtol=0, atol=1e-12)
    sched = Schedule(20.0)
    ests = {}
    for m in Method:
        ea, eb = estimate(a, m, sched), estimate(b, m, sched)
        assert eb.t_origin == origin
        np.testing.assert_allclose(eb.t, ea.t, rtol=0, atol=1e-12)
        for got, want in ((eb.mean, ea.mean), (eb.sigma, ea.sigma)):
            # relative to each column's magnitude (a slip of 0 has no relative error of its own)
            rel = np.abs(got - want) / np.maximum(np.abs(want).max(axis=0), 1e-300)
            assert rel.max() <= 1e-9, (m, float(rel.max()))
        ests[m.value] = (ea, eb)
    # the reports: the comparison's metrics, and what estimate writes
    ma = comparison_metrics({k: v[0] for k, v in ests.items()}, a, sched)
    mb = comparison_metrics({k: v[1] for k, v in ests.items()}, b, sched)
    for label, row in ma["estimators"].items():
        _same(mb["estimators"][label], {k: v for k, v in row.items() if k not in ("wall_time_s", "updates_per_second")})
    sa = estimate_to_dir(a, tmp_path / "out-a", Method.isam2, sched)
    sb = estimate_to_dir(b, tmp_path / "out-b", Method.isam2, sched)
    assert (sa["t_origin"], sb["t_origin"]) == (0, origin)
    _same(sb, {k: v for k, v in sa.items() if k not in ("log", "t_origin", "wall_time_s", "updates_per_second",
                                                         "update_time_ms")})
    for f in ("states.csv", "online.csv"):
        ra = (tmp_path / "out-a" / f).read_text().splitlines()[1:]
        rb = (tmp_path / "out-b" / f).read_text().splitlines()[1:]
        for la, lb in zip(ra, rb):
            ta, tb = la.split(",")[0], lb.split(",")[0]
            whole, frac = ta.split(".")
            assert tb == f"{origin + int(whole)}.{frac}"
    first_state = (tmp_path / "out-b" / "states.csv").read_text().splitlines()[1].split(",")[0]
    tum = (tmp_path / "out-b" / "trajectory.tum").read_text().splitlines()
    assert tum[0] == "# odomgraph isam2: t x y z qx qy qz qw" and tum[1].split()[0] == first_state


def test_a_real_clock_bag_keeps_every_nanosecond(tmp_path):
    """The importer takes a bag's stamps as integer nanoseconds: the same
    bag on a real clock imports to the same intervals, exactly."""
    src = simulate(paper(20).with_(slips=()), 4)
    _write_bag(tmp_path / "zero", src, wheels="odometry")
    _write_bag(tmp_path / "real", src, wheels="odometry", t0=1_700_000_000)
    a = import_rosbag(tmp_path / "zero", track_width=src.robot.track_width)
    b = import_rosbag(tmp_path / "real", track_width=src.robot.track_width)
    assert (a.t_origin, b.t_origin) == (0, 1_700_000_000)
    for name in ("wheel_speeds", "gps", "gyro"):
        np.testing.assert_array_equal(getattr(b, name).t, getattr(a, name).t)


@pytest.mark.parametrize("storage", ["ros1", "mcap"])
def test_tick_counters_import_as_encoders_and_calibrate_back(tmp_path, storage):
    """Two std_msgs/Int16 tick counters (no header, wrapping every 65536
    ticks, the right one published 3 ms after the left) are found by their
    names, paired, unwrapped into encoders.csv ticks equal to the simulated
    ones, and calibrate back to 0.5 %."""
    src = simulate(paper(60).with_(slips=()), 9)
    p = tmp_path / ("ticks.bag" if storage == "ros1" else "ticks")
    _write_bag(p, src, wheels="ticks", imu_axis="z", storage=storage, tf_lever=(-0.45, 0.0))
    log = import_rosbag(p, track_width=src.robot.track_width, ticks_per_meter=src.robot.ticks_per_meter_left)
    assert any("tick counters /wheel/left_ticks and /wheel/right_ticks" in n for n in log.notes)
    assert log.wheel_speeds is None and log.encoders is not None
    e = src.encoders
    assert np.abs(np.cumsum(e.ticks_left)).max() > 2**16    # it did wrap, more than once
    np.testing.assert_array_equal(log.encoders.ticks_left[1:], e.ticks_left[1:])
    np.testing.assert_array_equal(log.encoders.ticks_right[1:], e.ticks_right[1:])
    np.testing.assert_allclose(log.encoders.t, e.t + 0.0015, atol=1e-9)   # the pair's mean time
    assert log.robot.ticks_per_meter_left == src.robot.ticks_per_meter_left
    est = estimate(log, Method.batch, Schedule(None))
    for got, true in zip(est.mean[-1, 8:11], src.truth_scales):
        assert got == pytest.approx(true, rel=0.005)
    with pytest.raises(LogFormatError, match="need a positive --ticks-per-meter"):
        import_rosbag(p, track_width=0.6)
    topics, _ = __import__("odomgraph.io.importers.rosbag", fromlist=["list_topics"]).list_topics(p)
    roles = {t.topic: t.role for t in topics}
    assert roles["/wheel/left_ticks"] == "wheels (left ticks)" and roles["/wheel/right_ticks"] == "wheels (right ticks)"


def test_tick_counters_at_different_rates_are_interpolated_not_mispaired(tmp_path):
    """The right counter at a third of the left's rate (found by a probe: each
    left reading paired with a right one up to half a period away gave a
    left ticks/m 23 % off with a tight sigma). Rows go on the sparser
    counter's times, the other count interpolated: it calibrates back."""
    src = simulate(paper(60).with_(slips=()), 10)
    p = tmp_path / "rates.bag"
    _write_bag(p, src, wheels="ticks", storage="ros1", tf_lever=(-0.45, 0.0), right_every3=True)
    log = import_rosbag(p, track_width=src.robot.track_width, ticks_per_meter=src.robot.ticks_per_meter_left)
    assert any("different rates or times" in n and "right counter's times" in n for n in log.notes)
    est = estimate(log, Method.batch, Schedule(None))
    for got, true in zip(est.mean[-1, 8:11], src.truth_scales):
        assert got == pytest.approx(true, rel=0.005)


def test_tick_counter_problems_are_named(tmp_path):
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS1_NOETIC)
    p = tmp_path / "three.bag"
    with Writer(p) as w:
        cs = [w.add_connection(tp, "std_msgs/msg/Int32", typestore=ts)
              for tp in ("/left_ticks", "/left_ticks_raw", "/right_ticks")]
        for k in range(20):
            for c in cs:
                w.write(c, 10**9 + k * 50_000_000, ts.serialize_ros1(ts.types["std_msgs/msg/Int32"](data=k * 10),
                                                                    "std_msgs/msg/Int32"))
    with pytest.raises(LogFormatError, match=r"left \['/left_ticks', '/left_ticks_raw'\], right \['/right_ticks'\]"
                                             r".*give --tick-topics"):
        import_rosbag(p, track_width=0.5, ticks_per_meter=1000)
    # a ROS 1 bag without its .bag suffix is still read (rosbags goes by the name)
    plain = tmp_path / "three"
    plain.write_bytes(p.read_bytes())
    import tempfile
    before = set(Path(tempfile.gettempdir()).glob("odomgraph-bag-*"))
    log = import_rosbag(plain, track_width=0.5, ticks_per_meter=1000, tick_topics=("/left_ticks", "/right_ticks"))
    assert len(log.encoders.t) == 20
    # the *.bag link it was read through is gone with its directory (16 were left in /tmp by a day of tests)
    assert set(Path(tempfile.gettempdir()).glob("odomgraph-bag-*")) == before
    junk = tmp_path / "junk"
    junk.write_text("not a bag\n")
    with pytest.raises(LogFormatError, match="not a ROS 1 bag"):
        import_rosbag(junk, track_width=0.5)


def test_an_unknown_gps_lever_arm_is_a_warning(tmp_path):
    src = simulate(paper(30).with_(slips=()), 11)
    _write_bag(tmp_path / "nolever", src, wheels="odometry")
    log = import_rosbag(tmp_path / "nolever", track_width=src.robot.track_width)
    assert any("lever arm is unknown" in w and "--gps-lever-arm" in w for w in log.warnings)


def test_a_killed_recording_gets_the_reindex_remedy(tmp_path):
    """A ROS 1 bag cut off before its index was written, and a ROS 2
    directory without metadata.yaml (a recording that was killed), each
    gave rosbags' own words only; now the one line names the remedy."""
    src = simulate(paper(12.0), 23)
    _write_bag(tmp_path / "r1.bag", src, storage="ros1")
    data = (tmp_path / "r1.bag").read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: int(len(data) * 0.55)])
    with pytest.raises(LogFormatError, match=r"\(a recording that was killed\?\): 'rosbag reindex .*cut.bag' mends it$"):
        import_rosbag(cut, track_width=0.6, wheel_radius=R_WHEEL)
    b2 = tmp_path / "r2"
    _write_bag(b2, src)
    (b2 / "metadata.yaml").unlink()
    with pytest.raises(LogFormatError, match=r"no metadata.yaml .*'ros2 bag reindex .*r2' writes it$"):
        import_rosbag(b2, track_width=0.6, wheel_radius=R_WHEEL)
