"""Bags a hostile probe (thirty-first session) wrote and the importer got
wrong: a velocity command (/cmd_vel) taken for the wheels, options ignored
for wheels they were not for, tick counters on the receive clock beside
header stamps on another, a GPS on GPS time, an IMU on its boot clock, an
empty IMU topic, a GPS without a fix, a gyro in deg/s, an IMU mounting in
/tf_static that the data contradict, and a truncated mcap. Each is written
here with rosbags from a simulated log (other seeds, lengths, rates, topic
names and offsets than the probe's) and imported; the numbers imported are
compared with the same bag written clean."""
from pathlib import Path

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")

from odomgraph.errors import LogFormatError  # noqa: E402
from odomgraph.io.importers.rosbag import _is_command, import_rosbag, list_topics  # noqa: E402
from odomgraph.sim.scenarios import paper  # noqa: E402
from odomgraph.sim.simulate import simulate  # noqa: E402

LAT0, LON0, T0 = -33.8688, 151.2093, 1_650_000_000


def _bag(path: Path, log, wheels="ticks", wheel_topic="/base/odom", twist=None, fused=None,
         ticks=("/enc/left", "/enc/right"),
         lag=0.0, header_off=None, simtime=False, imu=True, imu_topic="/sensors/imu", imu_scale=1.0, imu_tf=None,
         gps=True, gps_status=0, empty=(), storage="sqlite3", bare_command=None, transport=0.003):
    """A ROS 2 bag of ``log``. ``wheels``: "ticks" (std_msgs/Int32 counters
    ``ticks``, no header), "twist" (TwistStamped on ``wheel_topic``),
    "odom" (nav_msgs/Odometry, pose left at the origin), "joints"
    (JointState left_wheel/right_wheel, radius 0.1 m) or None. ``twist``: a
    TwistStamped topic carrying the wheels' own twist besides (a command's,
    or a driver's); ``fused``: an Odometry topic besides (robot_localization's
    output); ``bare_command``: the twist as a bare geometry_msgs/Twist. Header stamps
    are T0 + t (``simtime``: t) plus ``header_off[role]`` [s] (roles wheels,
    gps, imu); receive times T0 + t + ``lag`` + ``transport`` [s]. The gyro
    (on ``imu_topic``) is the yaw rate times ``imu_scale`` on z; ``imu_tf``:
    the mounting written in /tf_static ("id" or "upside_down"). Every fix has
    status ``gps_status``. ``empty``: (topic, type) listed without messages."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header, V3 = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"], T["geometry_msgs/msg/Vector3"]
    Q, Twist = T["geometry_msgs/msg/Quaternion"], T["geometry_msgs/msg/Twist"]
    header_off = header_off or {}

    def ns(t):
        return int(round(t * 1e9))

    def header(t, role, frame="base_link"):
        n = (0 if simtime else T0 * 1_000_000_000) + ns(t + header_off.get(role, 0.0))
        return Header(stamp=Time(sec=n // 1_000_000_000, nanosec=n % 1_000_000_000), frame_id=frame)

    def at(t):
        return T0 * 1_000_000_000 + ns(t + lag + transport)

    e, r = log.encoders, log.robot
    dt = np.diff(e.t)
    vl, vr = e.ticks_left[1:] / (r.ticks_per_meter_left * dt), e.ticks_right[1:] / (r.ticks_per_meter_right * dt)
    v, om = 0.5 * (vl + vr), (vr - vl) / r.track_width
    out = []          # (receive [ns], topic, message, type)
    if wheels == "ticks":
        for t, a, b in zip(e.t, np.cumsum(e.ticks_left), np.cumsum(e.ticks_right)):
            out.append((at(t), ticks[0], T["std_msgs/msg/Int32"](data=int(a)), "std_msgs/msg/Int32"))
            out.append((at(t) + 1_000_000, ticks[1], T["std_msgs/msg/Int32"](data=int(b)), "std_msgs/msg/Int32"))
    for topic, kind in ((wheel_topic, wheels), (twist, "twist"), (fused, "odom")):
        if topic is None or kind not in ("twist", "odom", "joints"):
            continue
        ang = {"left_wheel": np.cumsum(e.ticks_left) / r.ticks_per_meter_left / 0.1,
               "right_wheel": np.cumsum(e.ticks_right) / r.ticks_per_meter_right / 0.1}
        for k, (t, vi, wi) in enumerate(zip(e.t[1:], v, om)):
            tw = Twist(linear=V3(x=vi, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=wi))
            if kind == "twist":
                msg, ty = T["geometry_msgs/msg/TwistStamped"](header=header(t, "wheels"), twist=tw), \
                    "geometry_msgs/msg/TwistStamped"
            elif kind == "joints":
                msg, ty = T["sensor_msgs/msg/JointState"](
                    header=header(t, "wheels"), name=["left_wheel", "right_wheel"],
                    position=np.array([ang["left_wheel"][k + 1], ang["right_wheel"][k + 1]]),
                    velocity=np.array([], float), effort=np.array([], float)), "sensor_msgs/msg/JointState"
            else:
                P, Tw = T["geometry_msgs/msg/PoseWithCovariance"], T["geometry_msgs/msg/TwistWithCovariance"]
                msg, ty = T["nav_msgs/msg/Odometry"](
                    header=header(t, "wheels", "odom"), child_frame_id="base_link",
                    pose=P(pose=T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                                                             orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0)),
                           covariance=np.zeros(36)),
                    twist=Tw(twist=tw, covariance=np.zeros(36))), "nav_msgs/msg/Odometry"
            out.append((at(t), topic, msg, ty))
    if bare_command is not None:
        for t, vi, wi in zip(e.t[1:], v, om):
            out.append((at(t), bare_command, Twist(linear=V3(x=vi, y=0.0, z=0.0), angular=V3(x=0.0, y=0.0, z=wi)),
                        "geometry_msgs/msg/Twist"))
    if gps:
        m_lat = 111_132.954 - 559.822 * np.cos(2 * np.radians(LAT0))
        m_lon = 111_412.84 * np.cos(np.radians(LAT0))
        for t, x, y in zip(log.gps.t, log.gps.x, log.gps.y):
            cov = np.zeros(9)
            cov[0] = cov[4] = 0.05 ** 2
            out.append((at(t), "/gnss/fix", T["sensor_msgs/msg/NavSatFix"](
                header=header(t, "gps", "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=gps_status, service=1),
                latitude=LAT0 + y / m_lat, longitude=LON0 + x / m_lon, altitude=30.0, position_covariance=cov,
                position_covariance_type=2), "sensor_msgs/msg/NavSatFix"))
    if imu:
        for t, w in zip(log.gyro.t, log.gyro.omega):
            out.append((at(t), imu_topic, T["sensor_msgs/msg/Imu"](
                header=header(t, "imu", "imu_link"), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                orientation_covariance=np.zeros(9),
                angular_velocity=V3(x=0.0005 * np.sin(5 * t), y=0.0005 * np.cos(3 * t), z=imu_scale * w),
                angular_velocity_covariance=np.zeros(9), linear_acceleration=V3(x=0.0, y=0.0, z=9.81),
                linear_acceleration_covariance=np.zeros(9)), "sensor_msgs/msg/Imu"))
    trs = [T["geometry_msgs/msg/TransformStamped"](
        header=header(0.0, "tf"), child_frame_id="gps",
        transform=T["geometry_msgs/msg/Transform"](translation=V3(x=r.gps_lever_arm[0], y=r.gps_lever_arm[1], z=0.6),
                                                   rotation=Q(x=0.0, y=0.0, z=0.0, w=1.0)))]
    if imu_tf is not None:
        q = {"id": Q(x=0.0, y=0.0, z=0.0, w=1.0), "upside_down": Q(x=1.0, y=0.0, z=0.0, w=0.0)}[imu_tf]
        trs.append(T["geometry_msgs/msg/TransformStamped"](
            header=header(0.0, "tf"), child_frame_id="imu_link",
            transform=T["geometry_msgs/msg/Transform"](translation=V3(x=0.0, y=0.0, z=0.3), rotation=q)))
    out.append((at(0.0) - 10**6, "/tf_static", T["tf2_msgs/msg/TFMessage"](transforms=trs), "tf2_msgs/msg/TFMessage"))
    out.sort(key=lambda m: m[0])
    plugin = StoragePlugin.MCAP if storage == "mcap" else StoragePlugin.SQLITE3
    with Writer(path, version=8, storage_plugin=plugin) as w:
        conns = {}
        for _, topic, _, ty in out:
            if topic not in conns:
                conns[topic] = w.add_connection(topic, ty, typestore=ts)
        for topic, ty in empty:
            w.add_connection(topic, ty, typestore=ts)
        for n, topic, msg, ty in out:
            w.write(conns[topic], n, ts.serialize_cdr(msg, ty))
    return path


@pytest.fixture(scope="module")
def sim():
    return simulate(paper(45).with_(slips=()), 17)


def _tpm(log):
    return log.robot.ticks_per_meter_left


# ----------------------------------------------------------------------------------- commands
@pytest.mark.parametrize("topic, says", [("/cmd_vel", True), ("/robot/cmdVel", True), ("/teleop/twist", True),
                                         ("/nav_vel", True), ("/joy2/twist", True), ("/planner/setpoint", True),
                                         ("/cmd_vel_measured", False), ("/wheel/odom", False),
                                         ("/navsat/odom", False), ("/commander_odom", False)])
def test_command_topics_are_told_by_whole_words_of_their_names(topic, says):
    assert _is_command(topic) is says


def test_a_velocity_command_is_never_the_wheels_by_itself(sim, tmp_path):
    """The probe's: Nav2's stamped /cmd_vel the only wheel-like topic,
    picked, and calibrated with status ok (z -34 to +36). Refused, naming
    it; given with --wheel-topic, taken with a warning."""
    p = _bag(tmp_path / "cmd", sim, wheels=None, twist="/robot/cmd_vel", storage="mcap")
    with pytest.raises(LogFormatError) as exc:
        import_rosbag(p, track_width=0.6)
    assert exc.value.problem == ("the bag's only wheel topics are velocity commands ['/robot/cmd_vel']: a command is "
                                 "what was asked of the wheels, not what they did, and calibrates nothing; give "
                                 "--wheel-topic to take one anyway")
    log = import_rosbag(p, wheel_topic="/robot/cmd_vel", track_width=0.6)
    assert len(log.wheel_speeds.t) == len(sim.encoders.t) - 1
    assert log.warnings[0] == ("/robot/cmd_vel: its name says a velocity command, not a wheel measurement: taken as "
                               "the wheels (--wheel-topic), it holds what was asked of them, not their slip, lag or "
                               "scale, and a calibration from it calibrates the command")
    # a bare geometry_msgs/Twist command is named in the no-wheels refusal
    q = _bag(tmp_path / "bare", sim, wheels=None, bare_command="/cmd_vel")
    with pytest.raises(LogFormatError, match=r"in the bag; \['/cmd_vel'\]: velocity commands, not wheel "
                                             r"measurements; --list shows what it has$"):
        import_rosbag(q, track_width=0.6)


def test_tick_counters_beside_a_command_and_a_fused_odometry_are_the_wheels(sim, tmp_path):
    """Tick counters + a stamped command (+ robot_localization's output):
    the probe's importer took the command and ignored --ticks-per-meter.
    The counters are taken, exact to the tick; without --ticks-per-meter,
    the refusal asks for it."""
    p = _bag(tmp_path / "ticks_cmd", sim, twist="/cmd_vel")
    p2 = _bag(tmp_path / "ticks_cmd_fused", sim, twist="/teleop/cmd_vel", fused="/odometry/filtered")
    for path in (p, p2):
        topics, _ = list_topics(path)
        roles = {t.topic: t.role for t in topics}
        assert roles["/enc/left"] == "wheels (left ticks)" and roles["/enc/right"] == "wheels (right ticks)"
        assert [t for t, role in roles.items() if role == "wheels"] == []
    log = import_rosbag(p, track_width=0.6, ticks_per_meter=_tpm(sim))
    assert "wheels: picked the tick counters /enc/left and /enc/right" in log.notes
    np.testing.assert_array_equal(log.encoders.ticks_left[1:], sim.encoders.ticks_left[1:])
    np.testing.assert_array_equal(log.encoders.ticks_right[1:], sim.encoders.ticks_right[1:])
    with pytest.raises(LogFormatError, match=r"tick counters \['/enc/left', '/enc/right'\] need a positive "
                                             r"--ticks-per-meter"):
        import_rosbag(p2, track_width=0.6)
    assert import_rosbag(p2, track_width=0.6, ticks_per_meter=_tpm(sim)).encoders is not None


def test_tick_counters_beside_a_wheel_odometry_are_taken_with_ticks_per_meter(tmp_path):
    """A diff-drive controller's odometry beside the raw counters: without
    --ticks-per-meter the odometry as before, with a note naming the
    counters; with it, the counters (the encoders' own counts)."""
    src = simulate(paper(30).with_(slips=()), 21)
    p = _bag(tmp_path / "both", src, twist="/diff_drive/odom_twist", ticks=("/left_count", "/right_count"))
    odo = import_rosbag(p, track_width=src.robot.track_width)
    assert odo.encoders is None and "wheels: picked /diff_drive/odom_twist" in odo.notes
    assert ("tick counters /left_count and /right_count beside ['/diff_drive/odom_twist']: --ticks-per-meter TPM "
            "takes them (the encoders' own counts) instead") in odo.notes
    enc = import_rosbag(p, track_width=src.robot.track_width, ticks_per_meter=_tpm(src))
    assert ("wheels: picked the tick counters /left_count and /right_count (the encoders' own counts, "
            "--ticks-per-meter given) over ['/diff_drive/odom_twist']") in enc.notes
    assert enc.encoders.ticks_left.sum() == src.encoders.ticks_left[1:].sum()


# ------------------------------------------------------------------------ options that do not apply
@pytest.mark.parametrize("kw, says", [
    ({"ticks_per_meter": (1500.0, 1500.0)}, "--ticks-per-meter is for tick counters, but the wheels picked are "
                                            "/base/odom (Odometry): leave it out, or name the wheels it is for "
                                            "(--tick-topics LEFT,RIGHT)"),
    ({"wheel_radius": 0.12}, "--wheel-radius is for JointState wheels, but the wheels picked are /base/odom "
                             "(Odometry): leave it out, or name the wheels it is for (--wheel-topic)"),
    ({"left_joint": "foo"}, "--left-joint is for JointState wheels, but the wheels picked are /base/odom "
                            "(Odometry): leave it out, or name the wheels it is for (--wheel-topic)"),
    ({"right_joint": "bar"}, "--right-joint is for JointState wheels, but the wheels picked are /base/odom "
                             "(Odometry): leave it out, or name the wheels it is for (--wheel-topic)")])
def test_options_for_other_wheels_are_refused(sim, tmp_path, kw, says):
    p = _bag(tmp_path / "odom", sim, wheels="odom", imu=False)
    with pytest.raises(LogFormatError) as exc:
        import_rosbag(p, track_width=0.6, **kw)
    assert exc.value.problem == says


def test_options_for_other_wheels_are_refused_for_tick_counters_and_joints(sim, tmp_path):
    p = _bag(tmp_path / "ticks", sim, gps=False)
    with pytest.raises(LogFormatError) as exc:
        import_rosbag(p, track_width=0.6, ticks_per_meter=2000.0, wheel_radius=0.1)
    assert exc.value.problem == ("--wheel-radius is for JointState wheels, but the wheels picked are the tick "
                                 "counters ['/enc/left', '/enc/right']: leave it out, or name the wheels it is for "
                                 "(--wheel-topic)")
    j = _bag(tmp_path / "joints", sim, wheels="joints", wheel_topic="/joint_states", gps=False)
    with pytest.raises(LogFormatError) as exc:
        import_rosbag(j, track_width=0.6, wheel_radius=0.1, left_joint="front_left_wheel")
    assert exc.value.problem == ("/joint_states: --left-joint 'front_left_wheel' is not a joint it holds (its joints: "
                                 "['left_wheel', 'right_wheel'])")
    log = import_rosbag(j, track_width=0.6, wheel_radius=0.1, left_joint="left_wheel")
    e, r = sim.encoders, sim.robot
    # (the bag's joint positions from e.t[1] on)
    np.testing.assert_allclose(log.wheel_speeds.v_left,
                               e.ticks_left[2:] / (r.ticks_per_meter_left * np.diff(e.t[1:])), atol=1e-6)


# ---------------------------------------------------------------------------------------- clocks
@pytest.mark.parametrize("lag, seed", [(7.5, 31), (-4.0, 32), (0.6, 33)])
def test_tick_counters_on_the_receive_clock_move_onto_the_header_clock(tmp_path, lag, seed):
    """The bag recorded ``lag`` s off the sensors' header clock: the counters
    (receive times) come out on the header clock, as in a bag recorded on
    it, with a warning that gives the shift."""
    src = simulate(paper(40).with_(slips=()), seed)
    clean = import_rosbag(_bag(tmp_path / "clean", src), track_width=0.6, ticks_per_meter=_tpm(src))
    late = import_rosbag(_bag(tmp_path / "late", src, lag=lag), track_width=0.6, ticks_per_meter=_tpm(src))
    assert clean.warnings == () and late.t_origin == clean.t_origin
    # on the header clock: the clean bag's counters, less their 3 ms of transport (as the header topics')
    np.testing.assert_allclose(late.encoders.t, clean.encoders.t - 0.003, atol=2e-9, rtol=0)
    np.testing.assert_array_equal(late.encoders.ticks_left, clean.encoders.ticks_left)
    np.testing.assert_array_equal(late.gps.t, clean.gps.t)
    shift = f"{abs(lag + 0.003):.4g}"
    assert late.warnings == (
        f"the tick counters ['/enc/left', '/enc/right'] carry the bag's receive times, {shift} s "
        f"{'after' if lag > 0 else 'before'} the header stamps of ['/gnss/fix', '/sensors/imu'] (receive - header of "
        f"/gnss/fix, median): two clocks; the counters are moved {shift} s {'earlier' if lag > 0 else 'later'}, onto "
        "the header clock (--stamps receive puts every topic on the receive clock instead)",)


def test_transport_latency_is_no_clock_offset(sim, tmp_path):
    """Receive times 40 ms after the header stamps (a busy network): no shift,
    no warning; the counters' times are their receive times."""
    log = import_rosbag(_bag(tmp_path / "lat", sim, transport=0.04), track_width=0.6, ticks_per_meter=_tpm(sim))
    assert log.warnings == ()
    np.testing.assert_allclose(log.encoders.t, sim.encoders.t + 0.04 + 0.0005, atol=2e-9)


@pytest.mark.parametrize("off", [18.0, -6.5])
def test_a_header_clock_off_the_others_is_said(tmp_path, off):
    """A GPS stamped on GPS time (18 s ahead of the wheels' and the IMU's
    clock), or 6.5 s behind: a warning naming it and the offset; the other
    topics' rows as in the clean bag."""
    src = simulate(paper(35).with_(slips=()), 41)
    log = import_rosbag(_bag(tmp_path / "gps", src, wheels="twist", header_off={"gps": off}), track_width=0.6)
    leap = " (GPS time runs 18 s ahead of UTC)" if off == 18.0 else ""
    assert log.warnings == (
        f"/gnss/fix: its header stamps are {abs(0.003 - off):.4g} s off its receive times, those of ['/base/odom', "
        f"'/sensors/imu'] 0.003 s (receive - header, medians): its header clock runs {abs(off):.4g} s "
        f"{'ahead of' if off > 0 else 'behind'} theirs{leap}: its rows in the log are that far off the others'; "
        "--stamps receive stamps every topic with the bag's receive times, or --gps-topic '' leaves it out",)
    np.testing.assert_allclose(log.gps.t + (log.t_origin - T0), src.gps.t + off, atol=2e-9)
    # all topics recorded 25 s after their stamps, together: one clock, nothing to say
    same = import_rosbag(_bag(tmp_path / "all", src, wheels="twist", lag=25.0), track_width=0.6)
    assert same.warnings == ()


def test_an_imu_on_its_boot_clock_is_refused_with_the_remedies(sim, tmp_path):
    p = _bag(tmp_path / "boot", sim, wheels="twist", header_off={"imu": -(T0 - 4321.0)})
    with pytest.raises(LogFormatError) as exc:
        import_rosbag(p, track_width=0.6)
    assert exc.value.problem == (
        "/sensors/imu: its header stamps are 1.65e+09 s off its receive times, those of ['/base/odom', '/gnss/fix'] "
        "0.003 s (receive - header, medians): its header clock runs 1.65e+09 s behind theirs, and its times would not "
        "meet theirs (a sensor's own clock?): --stamps receive stamps every topic with the bag's receive times, or "
        "--imu-topic '' leaves it out")
    # either remedy imports
    assert import_rosbag(p, track_width=0.6, imu_topic="").gyro is None
    assert len(import_rosbag(p, track_width=0.6, stamps="receive").gyro.t) == len(sim.gyro.t)


def test_sim_time_headers_beside_wall_clock_tick_counters_are_refused(sim, tmp_path):
    p = _bag(tmp_path / "simtime", sim, simtime=True)
    with pytest.raises(LogFormatError) as exc:
        import_rosbag(p, track_width=0.6, ticks_per_meter=_tpm(sim))
    assert exc.value.problem.startswith("the tick counters ['/enc/left', '/enc/right'] carry the bag's receive times "
                                        "(a wall clock, near 1.65e+09 s) while the header stamps of ['/gnss/fix', "
                                        "'/sensors/imu'] run on a simulated clock (use_sim_time, near ")
    assert exc.value.problem.endswith("no offset puts them on one clock; --stamps receive stamps every topic with "
                                      "the receive times")
    log = import_rosbag(p, track_width=0.6, ticks_per_meter=_tpm(sim), stamps="receive")
    np.testing.assert_allclose(log.encoders.t, sim.encoders.t + 0.0035, atol=2e-9)


# ------------------------------------------------------------------------------ missing sensors
def test_an_empty_imu_topic_and_a_gps_without_a_fix_are_warnings(sim, tmp_path):
    p = _bag(tmp_path / "empty", sim, wheels="twist", imu=False, empty=(("/sensors/imu", "sensor_msgs/msg/Imu"),))
    given = import_rosbag(p, track_width=0.6, imu_topic="/sensors/imu")
    assert given.gyro is None and given.warnings == ("/sensors/imu: the IMU topic holds no messages: no gyro",)
    found = import_rosbag(p, track_width=0.6)
    assert found.gyro is None and found.warnings == ("/sensors/imu: an IMU topic without messages: no gyro",)
    assert import_rosbag(p, track_width=0.6, imu_topic="").warnings == ()
    q = _bag(tmp_path / "nofix", sim, wheels="twist", gps_status=-1)
    log = import_rosbag(q, track_width=0.6)
    n = len(sim.gps.t)
    assert log.gps is None and log.warnings == (
        f"/gnss/fix: none of its {n} messages is usable ({n} without a fix (status < 0)): no GPS",)


# -------------------------------------------------------------------------------------- the gyro
@pytest.mark.parametrize("imu_tf", [None, "id"])
def test_a_gyro_in_degrees_per_second_is_said(tmp_path, imu_tf):
    src = simulate(paper(50).with_(slips=()), 43)
    log = import_rosbag(_bag(tmp_path / "deg", src, wheels="twist", imu_scale=180 / np.pi, imu_tf=imu_tf),
                        track_width=0.6)
    np.testing.assert_allclose(log.gyro.omega, src.gyro.omega * 180 / np.pi, rtol=1e-12)
    said = [w for w in log.warnings if "degrees per second" in w]
    assert len(said) == 1 and said[0].startswith("/sensors/imu: its yaw rate reads ")
    assert said[0].endswith("an IMU in degrees per second (57.3x)? sensor_msgs/Imu is in rad/s")
    clean = import_rosbag(_bag(tmp_path / "rad", src, wheels="twist", imu_tf=imu_tf), track_width=0.6)
    assert not [w for w in clean.warnings if "degrees" in w]
    # the ratio said: 180/pi times the clean gyro's to the wheels' turn rate where they turn (the wheels'
    # scale factors keep that off 1)
    ws = clean.wheel_speeds
    w = np.interp(clean.gyro.t, ws.t, (ws.v_right - ws.v_left) / 0.6)
    turning = np.abs(w) >= 0.1
    expect = 180 / np.pi * float(np.median(clean.gyro.omega[turning] / w[turning]))
    assert 40 <= expect <= 80 and said[0].split("reads ")[1].startswith(f"{expect:.0f}x the wheels' turn rate")


def test_an_imu_mounting_in_tf_static_that_the_data_contradict_is_said(tmp_path):
    """/tf_static says upside down, the IMU is upright: the gyro turns
    against the wheels. Said, naming the frame; an honest mounting is not."""
    src = simulate(paper(40).with_(slips=()), 44)
    log = import_rosbag(_bag(tmp_path / "lies", src, wheels="twist", imu_tf="upside_down"), track_width=0.6)
    np.testing.assert_allclose(log.gyro.omega, -src.gyro.omega, atol=1e-12)
    assert len(log.warnings) == 1 and log.warnings[0].startswith(
        "/sensors/imu: /tf_static's mounting of 'imu_link' (base_link -> imu_link) gives a yaw rate that turns "
        "against the wheels' (correlation -")
    assert log.warnings[0].endswith("the data say the IMU is mounted the other way up; --imu-axis (z or -z) "
                                    "overrides /tf_static")
    corr = float(log.warnings[0].split("correlation ")[1].split(")")[0])
    assert corr < -0.9
    fine = import_rosbag(_bag(tmp_path / "fine", src, wheels="twist", imu_tf="id"), track_width=0.6)
    assert fine.warnings == ()


# --------------------------------------------------------------------------------- truncated mcap
def test_a_truncated_mcap_gets_the_recover_remedy(sim, tmp_path):
    p = _bag(tmp_path / "mc", sim, storage="mcap")
    f = next(p.glob("*.mcap"))
    data = f.read_bytes()
    f.write_bytes(data[: int(len(data) * 0.4)])
    with pytest.raises(LogFormatError) as exc:
        import_rosbag(p, track_width=0.6, ticks_per_meter=_tpm(sim))
    assert exc.value.problem.endswith(
        f"(a recording that was killed?): 'mcap recover {f} -o FIXED.mcap' (the mcap CLI) rescues its messages; put "
        "FIXED.mcap alone in a directory and 'ros2 bag reindex DIR -s mcap' writes its metadata.yaml")
