"""Bags a hostile probe (sixteenth session) wrote and the importer got
wrong: JointState joints in another order per message or another
publisher's joints on the topic, one fix's NaN covariance, fixes at
latitude 0 / longitude 0, an IMU without angular velocity, repeated header
stamps, placeholder joint positions, a run that turns too little to tell
the IMU's axis, and non-finite options. Each is written here with rosbags
from a simulated log (other seeds and lengths than the probe's) and
imported; the numbers imported are compared with the clean bag's."""
from pathlib import Path

import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")

from odomgraph.errors import LogFormatError  # noqa: E402
from odomgraph.io.importers.rosbag import import_rosbag  # noqa: E402
from odomgraph.sim.scenarios import paper  # noqa: E402
from odomgraph.sim.simulate import simulate  # noqa: E402

LAT0, LON0, R_WHEEL = 47.3769, 8.5417, 0.12
JOINTS = ["left_wheel_joint", "right_wheel_joint"]


def _bag(path: Path, log, order=lambda k: JOINTS, arm_every=0, fix=None, imu_cov=0.0, imu_rate=None,
         stamp=lambda t: t, positions=True, velocities=False, wrap=False, arm_names=("arm_shoulder", "arm_elbow"), fix_stamp=None,
         arm_position=(0.1, 0.2), restart=None, sides=None):
    """A ROS 2 bag of ``log``: JointState wheels (joint names per message
    from ``order(k)``; every ``arm_every``-th message an arm's JointState on
    the same topic; ``wrap``: positions modulo 2 pi), NavSatFix (``fix(k, lat, lon, cov)`` may change a fix),
    Imu with angular_velocity_covariance[0] = ``imu_cov`` and the yaw rate
    ``imu_rate(t, omega)`` (default: omega on z); header stamps ``stamp(t)``.
    ``sides``: {joint name: (wheel joint it copies, offset [rad] (N,))}, the
    joints a skid-steer base publishes (``order`` names them)."""
    from rosbags.rosbag2 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_HUMBLE)
    T = ts.types
    Time, Header, V3 = T["builtin_interfaces/msg/Time"], T["std_msgs/msg/Header"], T["geometry_msgs/msg/Vector3"]
    Q = T["geometry_msgs/msg/Quaternion"]

    def header(t, frame="base_link"):
        t = fix_stamp(t) if frame == "gps" and fix_stamp is not None else stamp(t)
        sec = int(np.floor(t))
        return Header(stamp=Time(sec=sec, nanosec=int(round((t - sec) * 1e9))), frame_id=frame)

    def at(t):
        return int(round((t + 100.0) * 1e9))

    e, r = log.encoders, log.robot
    angles = {"left_wheel_joint": np.cumsum(e.ticks_left) / r.ticks_per_meter_left / R_WHEEL,
              "right_wheel_joint": np.cumsum(e.ticks_right) / r.ticks_per_meter_right / R_WHEEL}
    if sides is not None:
        angles.update({k: angles[src] + off for k, (src, off) in sides.items()})
    if wrap:
        angles = {k: (v + np.pi) % (2 * np.pi) - np.pi for k, v in angles.items()}
    if restart is not None:
        # the driver silent over (t0, t1), its positions counting from 0 again at t1
        k1 = int(np.searchsorted(e.t, restart[1]))
        angles = {k: np.concatenate([v[:k1], v[k1:] - v[k1]]) for k, v in angles.items()}
    dt = np.diff(e.t, prepend=e.t[0] - 0.05)
    rates = {"left_wheel_joint": e.ticks_left / r.ticks_per_meter_left / R_WHEEL / dt,
             "right_wheel_joint": e.ticks_right / r.ticks_per_meter_right / R_WHEEL / dt}
    m_lat = 111_132.954 - 559.822 * np.cos(2 * np.radians(LAT0))
    m_lon = 111_412.84 * np.cos(np.radians(LAT0))
    with Writer(path, version=8) as w:
        cj = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        cg = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
        ci = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        JS = T["sensor_msgs/msg/JointState"]
        for k, t in enumerate(e.t):
            if restart is not None and restart[0] < t < restart[1]:
                continue
            names = order(k)
            pos = np.array([angles[n][k] if n in angles else 0.3 for n in names]) if positions else np.zeros(len(names))
            msg = JS(header=header(t), name=list(names), position=pos,
                     velocity=(np.array([rates[n][k] if n in rates else 0.0 for n in names]) if velocities
                               else np.array([], float)),
                     effort=np.array([], float))
            w.write(cj, at(t), ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
            if arm_every and k % arm_every == 0:
                # before the wheels' message of the same time: another publisher may come first
                arm = JS(header=header(t - 0.001), name=list(arm_names), position=np.array(arm_position, float),
                         velocity=np.array([], float), effort=np.array([], float))
                w.write(cj, at(t - 0.001), ts.serialize_cdr(arm, "sensor_msgs/msg/JointState"))
        g = log.gps
        for k, (t, x, y) in enumerate(zip(g.t, g.x, g.y)):
            lat, lon, cov = LAT0 + y / m_lat, LON0 + x / m_lon, np.diag([r.gps_sigma**2] * 3).ravel()
            if fix is not None:
                lat, lon, cov = fix(k, lat, lon, cov)
            msg = T["sensor_msgs/msg/NavSatFix"](
                header=header(t, "gps"), status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                latitude=lat, longitude=lon, altitude=200.0, position_covariance=np.asarray(cov, float),
                position_covariance_type=2)
            w.write(cg, at(t), ts.serialize_cdr(msg, "sensor_msgs/msg/NavSatFix"))
        for t, om in zip(log.gyro.t, log.gyro.omega):
            wz = om if imu_rate is None else imu_rate(t, om)
            cov = np.zeros(9)
            cov[0] = imu_cov
            msg = T["sensor_msgs/msg/Imu"](
                header=header(t, "imu"), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=np.zeros(9),
                angular_velocity=V3(x=0.0, y=0.0, z=wz if imu_cov != -1.0 else 0.0), angular_velocity_covariance=cov,
                linear_acceleration=V3(x=0.0, y=0.0, z=9.81), linear_acceleration_covariance=np.zeros(9))
            w.write(ci, at(t), ts.serialize_cdr(msg, "sensor_msgs/msg/Imu"))
    return path


@pytest.fixture(scope="module")
def sim():
    return simulate(paper(25.0), 41)


@pytest.fixture(scope="module")
def clean(sim, tmp_path_factory):
    return import_rosbag(_bag(tmp_path_factory.mktemp("clean") / "b", sim), track_width=0.6, wheel_radius=R_WHEEL)


def _imp(path, **kw):
    return import_rosbag(path, **{"track_width": 0.6, "wheel_radius": R_WHEEL, **kw})


def test_joints_are_looked_up_by_name_in_every_message(sim, clean, tmp_path):
    """A driver that orders its joints differently per message, and an arm
    publishing on the same topic: the wheel speeds equal the clean bag's
    (they were swapped in half the rows, up to 56 m/s off, without a word;
    with the arm the bag could not be imported at all)."""
    flip = _imp(_bag(tmp_path / "flip", sim, order=lambda k: JOINTS[::-1] if k % 2 else JOINTS))
    np.testing.assert_array_equal(flip.wheel_speeds.v_left, clean.wheel_speeds.v_left)
    np.testing.assert_array_equal(flip.wheel_speeds.v_right, clean.wheel_speeds.v_right)
    arm = _imp(_bag(tmp_path / "arm", sim, order=lambda k: ["caster", *JOINTS] if k > 100 else JOINTS, arm_every=3))
    np.testing.assert_array_equal(arm.wheel_speeds.v_left, clean.wheel_speeds.v_left)
    n_arm = len(range(0, len(sim.encoders.t), 3))
    assert any(f"{n_arm} messages without the wheel joints" in n and "another publisher" in n for n in arm.notes)
    # a gripper whose joints say left and right, publishing first (a review): the wheels' joints still win
    grip = _imp(_bag(tmp_path / "grip", sim, arm_every=2, arm_names=("gripper_left_finger", "gripper_right_finger")))
    np.testing.assert_array_equal(grip.wheel_speeds.v_left, clean.wheel_speeds.v_left)
    given = _imp(tmp_path / "arm", left_joint="left_wheel_joint", right_joint="right_wheel_joint")
    np.testing.assert_array_equal(given.wheel_speeds.v_right, clean.wheel_speeds.v_right)
    with pytest.raises(LogFormatError, match="joints 'l'/'r' not in"):
        _imp(tmp_path / "arm", left_joint="l", right_joint="r")


@pytest.mark.parametrize("wrap", [False, True])
def test_a_skid_steer_s_four_wheel_joints_are_averaged_per_side(sim, clean, tmp_path, wrap):
    """A Husky/Jackal/Warthog publishes front_ and rear_ wheel joints: the
    import refused them ("cannot tell which joints"), though a diff-drive
    controller takes each side's mean. Here the rear wheels turn with the
    front ones plus an encoder's own noise (0.003 rad), in another order per
    message; reported modulo 2 pi too (each joint unwrapped before the mean:
    the mean of two angles either side of the wrap is half a turn off). The
    speeds equal the clean bag's to the noise; three joints on one side and
    one on the other stay refused."""
    rng = np.random.default_rng(23)
    n = len(sim.encoders.t)
    four = {f"{end}_{side}_wheel": (f"{side}_wheel_joint", (0.0 if end == "front" else rng.normal(0.0, 0.003, n)))
            for end in ("front", "rear") for side in ("left", "right")}
    names = list(four)
    log = _imp(_bag(tmp_path / "four", sim, sides=four, wrap=wrap,
                    order=lambda k: names[::-1] if k % 3 else ["caster_joint", *names]))
    assert any("2 wheel joints a side (front_left_wheel, rear_left_wheel | front_right_wheel, rear_right_wheel)" in m
               for m in log.notes), log.notes
    # the mean of two angles one with 0.003 rad noise: speed noise <= 4 sigma x 0.5 x sqrt(2) / dt x radius
    tol = 4 * 0.5 * np.sqrt(2) * 0.003 / np.diff(sim.encoders.t).min() * R_WHEEL
    np.testing.assert_allclose(log.wheel_speeds.v_left, clean.wheel_speeds.v_left, atol=tol)
    np.testing.assert_allclose(log.wheel_speeds.v_right, clean.wheel_speeds.v_right, atol=tol)
    assert np.sqrt(np.mean((log.wheel_speeds.v_left - clean.wheel_speeds.v_left) ** 2)) < tol / 3
    assert (sum("wraps at a full turn" in m for m in log.notes) == 4) == wrap
    # the rear wheels missing from a tenth of the messages: the four still taken, those messages skipped
    gaps = _imp(_bag(tmp_path / "gaps", sim, sides=four, wrap=wrap,
                     order=lambda k: ["front_left_wheel", "front_right_wheel"] if k % 10 == 3 else names))
    assert any("2 wheel joints a side" in m for m in gaps.notes)
    n_gap = len(range(3, len(sim.encoders.t), 10))
    assert any(f"{n_gap} messages without the wheel joints" in m for m in gaps.notes), gaps.notes
    # a caster named like a wheel is no driven wheel (a second read: it was averaged in); steering joints
    # make a car-like base, refused
    caster = {**four, "left_caster_wheel_joint": ("left_wheel_joint", 0.0)}
    log_c = _imp(_bag(tmp_path / "caster", sim, sides=caster, wrap=wrap, order=lambda k: list(caster)))
    np.testing.assert_allclose(log_c.wheel_speeds.v_left, log.wheel_speeds.v_left, atol=1e-12)
    steer = {**four, "front_left_steering_joint": ("left_wheel_joint", 0.0)}
    with pytest.raises(LogFormatError, match="steering joints beside wheels .* a car-like base"):
        _imp(_bag(tmp_path / "steer", sim, sides=steer, order=lambda k: list(steer)))
    three = {**four, "middle_left_wheel": ("left_wheel_joint", 0.0)}
    with pytest.raises(LogFormatError, match="cannot tell which joints are the left and right wheels"):
        _imp(_bag(tmp_path / "three", sim, sides=three, order=lambda k: list(three)))
    if wrap:
        return
    # a motor behind a 20:1 gearbox named like its wheel is no second wheel: refused, not averaged in
    e, r = sim.encoders, sim.robot
    motor = {n: ("left_wheel_joint" if "left" in n else "right_wheel_joint",
                 19.0 * np.cumsum(e.ticks_left if "left" in n else e.ticks_right)
                 / (r.ticks_per_meter_left if "left" in n else r.ticks_per_meter_right) / R_WHEEL)
             for n in ("left_wheel_motor", "right_wheel_motor")}
    with pytest.raises(LogFormatError, match=r"turn unlike one another over the run \(left_wheel_joint 0.05, "
                                             r"left_wheel_motor 1 of the most\)"):
        _imp(_bag(tmp_path / "motor", sim, sides=motor, order=lambda k: [*JOINTS, *motor]))


def test_wheels_that_never_move_are_said(sim, tmp_path):
    """A driver that fills its wheel positions with zeros and no velocities
    beside a GPS that moves: imported without a word before (a probe's
    all-zero Odometry, the same); every estimate then reads a robot
    standing still, so the import says so."""
    log = _imp(_bag(tmp_path / "still", sim, positions=False))
    assert sum("the wheels never move in its" in w for w in log.warnings) == 1
    assert not any("never move" in w for w in _imp(_bag(tmp_path / "moves", sim)).warnings)


def test_placeholder_positions_give_way_to_velocities(sim, tmp_path):
    """JointState positions that stay 0 beside real velocities: the wheels
    stood still before; now the velocities are used, and said."""
    log = _imp(_bag(tmp_path / "zero", sim, positions=False, velocities=True))
    e, r = sim.encoders, sim.robot
    dt = np.diff(e.t, prepend=e.t[0] - 0.05)
    np.testing.assert_allclose(log.wheel_speeds.v_left, e.ticks_left / r.ticks_per_meter_left / dt, atol=1e-12)
    assert any("positions never change while the velocities do" in n for n in log.notes)


def test_fixes_without_a_covariance_or_a_position(sim, clean, tmp_path):
    """RTK fixes at 2 cm with one NaN covariance kept every other fix's sigma
    (all fell back to 5 cm before); fixes at latitude 0, longitude 0 with
    status 0 (a receiver before its first fix) are dropped, not made the
    projection origin 6000 km away."""
    def rtk(k, lat, lon, cov):
        c = np.diag([0.02**2, 0.02**2, 0.05**2]).ravel()
        return lat, lon, np.full(9, np.nan) if k == 7 else c
    log = _imp(_bag(tmp_path / "nan", sim, fix=rtk))
    # the others keep their 2 cm; the one without takes the largest known, at least the 5 cm default
    assert log.gps.sigma is not None and log.gps.sigma[7] == pytest.approx(0.05)
    assert np.all(np.delete(log.gps.sigma, 7) == pytest.approx(0.02)) and log.robot.gps_sigma == pytest.approx(0.02)
    assert any("1 of" in n and "no usable covariance" in n for n in log.notes)

    def null(k, lat, lon, cov):
        return (0.0, 0.0, cov) if k < 6 else (lat, lon, cov)
    log = _imp(_bag(tmp_path / "null", sim, fix=null))
    assert len(log.gps.t) == len(clean.gps.t) - 6
    # the origin is the first fix kept: metres from the clean bag's, not 6000 km
    assert log.robot.gps_origin == pytest.approx(clean.robot.gps_origin, abs=1e-3)
    assert np.hypot(log.gps.x, log.gps.y).max() < 100.0
    assert any("6 fixes at latitude 0, longitude 0" in n for n in log.notes)


def test_an_imu_without_angular_velocity_is_no_gyro(sim, tmp_path):
    """REP 145's "not provided" (covariance -1) and an IMU whose rates are all
    exactly zero gave a gyro that read 0 rad/s (scale factors 15-19 sigma
    off, calibrate wrote them); now there is no gyro, and a warning."""
    log = _imp(_bag(tmp_path / "orient", sim, imu_cov=-1.0))
    assert log.gyro is None and any("REP 145" in w and "no gyro" in w for w in log.warnings)
    log = _imp(_bag(tmp_path / "zeros", sim, imu_rate=lambda t, om: 0.0))
    assert log.gyro is None and any("exactly zero" in w for w in log.warnings)


def test_repeated_header_stamps_are_counted(sim, tmp_path):
    """Header stamps of a coarse clock (0.5 s steps) dropped 90 % of the
    messages without a word, and equal stamps on every message made a
    one-row log; both now point at --stamps receive."""
    coarse = _imp(_bag(tmp_path / "coarse", sim, stamp=lambda t: np.floor(t * 2.0) / 2.0))
    assert any("repeat an earlier stamp" in n and "--stamps receive" in n for n in coarse.notes)
    fine = _imp(tmp_path / "coarse", stamps="receive")
    assert len(fine.wheel_speeds.t) > 5 * len(coarse.wheel_speeds.t)
    with pytest.raises(LogFormatError, match="same header stamp; --stamps receive"):
        _imp(_bag(tmp_path / "equal", sim, stamp=lambda t: 5.0))
    # a GPS driver that never sets its stamp: left out, with a warning (it was one fix)
    log = _imp(_bag(tmp_path / "gps-equal", sim, fix_stamp=lambda t: 5.0))
    assert log.gps is None and any("/fix: all" in w and "same header stamp: left out" in w for w in log.warnings)


def test_too_little_turning_to_tell_the_imu_axis_is_said(tmp_path):
    """A run that hardly turns cannot show which IMU axis is yaw, or its
    sign: an upside-down IMU was taken as upright in silence (a probe: the
    estimators then blamed the lever arm)."""
    from odomgraph.sim.scenarios import Segment
    sc = paper(25.0).with_(prologue=(Segment(25.0, 1.0, 0.01),), loop=(), slips=())
    log = _imp(_bag(tmp_path / "straight", simulate(sc, 43), imu_rate=lambda t, om: -om))
    assert any("turns too little to tell the IMU's yaw axis" in w and "--imu-axis" in w for w in log.warnings)


@pytest.mark.parametrize("kw, says", [({"wheel_radius": float("nan")}, "--wheel-radius must be a positive, finite"),
                                      ({"wheel_radius": float("inf")}, "--wheel-radius must be a positive, finite"),
                                      ({"track_width": float("nan")}, "positive, finite --track-width")])
def test_non_finite_options_are_refused(sim, tmp_path, kw, says):
    """--wheel-radius nan wrote a wheel_speeds.csv of NaN and took the gyro
    from the wrong axis (exit 0)."""
    path = _bag(tmp_path / "b", sim)
    with pytest.raises(LogFormatError, match=says):
        _imp(path, **kw)


def test_wrapped_wheel_angles_are_unwrapped(sim, clean, tmp_path):
    """A driver reporting the wheel angle modulo 2 pi: 58 rows off by up to
    22 m/s before; now equal to the clean bag's speeds (to the rounding of
    the wrap), and said."""
    log = _imp(_bag(tmp_path / "wrap", sim, wrap=True))
    np.testing.assert_allclose(log.wheel_speeds.v_left, clean.wheel_speeds.v_left, atol=1e-9)
    np.testing.assert_allclose(log.wheel_speeds.v_right, clean.wheel_speeds.v_right, atol=1e-9)
    assert any("wraps at a full turn" in n for n in log.notes)


@pytest.mark.parametrize("msgtype", ["std_msgs/msg/Int32", "std_msgs/msg/Int64"])
def test_a_16_bit_counter_in_a_wider_message_is_unwrapped(sim, tmp_path, msgtype):
    """A 16-bit encoder counter published as Int32 or Int64 (a bridge's
    habit) wrapped at 65536 ticks and was read as two steps of about 65000
    ticks; now its ticks equal the simulation's."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS1_NOETIC)
    e = sim.encoders
    tpm = 20_000.0                                   # fine ticks: 65536 of them are 3.3 m, so the log wraps
    left = np.cumsum(np.rint(e.ticks_left / sim.robot.ticks_per_meter_left * tpm)).astype(np.int64)
    right = np.cumsum(np.rint(e.ticks_right / sim.robot.ticks_per_meter_right * tpm)).astype(np.int64)
    assert max(left[-1], right[-1]) > 2 * 65536
    path = tmp_path / "ticks.bag"
    with Writer(path) as w:
        cl = w.add_connection("/left_ticks", msgtype, typestore=ts)
        cr = w.add_connection("/right_ticks", msgtype, typestore=ts)
        for t, a, b in zip(e.t, left % 65536, right % 65536):
            for c, v in ((cl, a), (cr, b)):
                w.write(c, int(round((t + 100.0) * 1e9)), ts.serialize_ros1(ts.types[msgtype](data=int(v)), msgtype))
    log = import_rosbag(path, track_width=0.6, ticks_per_meter=tpm, tick_topics=("/left_ticks", "/right_ticks"))
    np.testing.assert_array_equal(np.cumsum(log.encoders.ticks_left), left - left[0])
    np.testing.assert_array_equal(np.cumsum(log.encoders.ticks_right), right - right[0])
    assert any("wraps at 16 bits inside its" in n for n in log.notes)


def test_a_wide_counter_that_jumps_is_not_taken_for_a_wrap(tmp_path):
    """An Int32 counter that stays inside 16 bits and jumps once by 50000
    (a reset or a gap, not a wrap: it does not cross the range's ends) is
    left as it is; a 32-bit counter in an Int64 that wraps is unwrapped at 32."""
    from odomgraph.io.importers.rosbag import _unwrap_counts
    jump = np.concatenate([np.arange(0, 10001, 500), np.arange(60000, 65001, 500)])
    notes = []
    np.testing.assert_array_equal(_unwrap_counts(jump, 32, notes, "t"), jump)
    assert notes == []
    wide = np.arange(0, 20 * 2**28, 2**28) % 2**32              # 2^28 ticks a message: a 32-bit wrap at 16
    out = _unwrap_counts(wide, None, notes, "t")
    np.testing.assert_array_equal(out, np.arange(0, 20 * 2**28, 2**28))
    assert notes == ["t: the counter wraps at 32 bits inside its 64-bit message: unwrapped"]


def test_the_import_s_warnings_stay_with_the_log(sim, tmp_path):
    """An import's warnings were printed once and lost: estimate and
    calibrate, run later on the log, trusted an IMU the import had left out
    without a word. import.json keeps where the log came from and what the
    import said; every estimate's summary and every calibration repeats the
    warnings."""
    import json
    from typer.testing import CliRunner
    from odomgraph.cli import app
    from odomgraph.io.log import read_log
    bag = _bag(tmp_path / "orient", sim, imu_cov=-1.0)
    run = CliRunner().invoke
    res = run(app, ["import", "rosbag", str(bag), "--wheel-radius", str(R_WHEEL), "--track-width", "0.6",
                    "-o", str(tmp_path / "log")])
    assert res.exit_code == 0, res.output
    prov = json.loads((tmp_path / "log" / "import.json").read_text())
    assert prov["importer"] == "rosbag" and prov["source"] == str(bag.resolve())
    assert prov["options"]["track_width"] == 0.6 and prov["options"]["wheel_radius"] == R_WHEEL
    assert len(prov["warnings"]) == 2 and "REP 145" in prov["warnings"][0] and "--gps-lever-arm" in prov["warnings"][1]
    assert prov["notes"][:4] == ["imported from bag orient", "wheels: picked /joint_states", "imu: picked /imu",
                                 "gps: picked /fix"]
    log = read_log(tmp_path / "log")
    assert log.warnings == tuple(f"import: {w}" for w in prov["warnings"]) and log.provenance == prov
    res = run(app, ["estimate", str(tmp_path / "log"), "--method", "ekf", "-o", str(tmp_path / "est")])
    assert res.exit_code == 0, res.output
    summary = json.loads((tmp_path / "est" / "summary.json").read_text())
    assert summary["warnings"][:2] == [f"import: {w}" for w in prov["warnings"]]
    assert summary["import"] == {"importer": "rosbag", "source": str(bag.resolve()), "odomgraph": prov["odomgraph"]}
    from odomgraph.pipeline import calibrate
    _, report = calibrate(log)
    assert report["warnings"][:2] == [f"import: {w}" for w in prov["warnings"]]
    # and the stream replaying the log says them after its summary (it said none)
    res = run(app, ["stream", "--replay", str(tmp_path / "log"), "--method", "ekf"])
    assert res.exit_code == 0, res.stderr
    said = [ln for ln in res.stderr.splitlines() if ln.startswith("odomgraph: warning: import: ")]
    assert said == [f"odomgraph: warning: import: {' '.join(w.split())}" for w in prov["warnings"]]
    # a damaged record is ignored, said
    (tmp_path / "log" / "import.json").write_text("[1, 2]")
    assert read_log(tmp_path / "log").warnings == ("import.json: not an import record (not a JSON object); ignored",)
    (tmp_path / "log" / "import.json").unlink()
    (tmp_path / "log" / "import.json").mkdir()
    assert read_log(tmp_path / "log").warnings == ("import.json: not an import record (is not a file); ignored",)


def test_unset_header_stamps_are_dropped_on_a_real_clock(sim, tmp_path):
    """A probe: two JointState messages stamped 0 s (a driver publishing
    before its clock is set) in a bag on a real clock made the log "span
    8.5e+08 s, more than a year", and the message named neither the topic nor
    the stamps; five such IMU messages did the same to gyro.csv. Now they are
    dropped with a note naming the topic, and the rest import as the clean
    bag's. On a simulated clock (use_sim_time, from 0) a stamp of 0 s is kept."""
    T0 = 1_700_000_000.0
    e = sim.encoders
    real = _imp(_bag(tmp_path / "real", sim, stamp=lambda t: T0 + t))
    # the first two wheel messages and every other sensor's before them are unset
    unset = _imp(_bag(tmp_path / "unset", sim, stamp=lambda t: 0.0 if t < e.t[2] else T0 + t))
    n_fix, n_imu = int((sim.gps.t < e.t[2]).sum()), int((sim.gyro.t < e.t[2]).sum())
    assert any(f"/joint_states: 2 of {len(e.t)} messages with an unset header stamp (0 s) dropped" in n
               for n in unset.notes)
    assert any(f"/imu: {n_imu} of {len(sim.gyro.t)} messages with an unset" in n for n in unset.notes)
    assert (n_fix == 0) == (not any(n.startswith("/fix:") and "unset" in n for n in unset.notes))
    assert unset.t_origin == real.t_origin
    # the speeds of the intervals between set stamps are the real-clock bag's, to the bit
    np.testing.assert_array_equal(unset.wheel_speeds.t, real.wheel_speeds.t[2:])
    np.testing.assert_array_equal(unset.wheel_speeds.v_left, real.wheel_speeds.v_left[2:])
    np.testing.assert_array_equal(unset.gyro.t, real.gyro.t[n_imu:])
    # a simulated clock from 0: the message at 0 s is a reading like any other
    simclock = _imp(_bag(tmp_path / "sim", sim, stamp=lambda t: t - e.t[0]))
    assert len(simclock.wheel_speeds.t) == len(e.t) - 1 and not any("unset" in n for n in simclock.notes)
    # every wheel message unset on a real clock: the equal-stamp refusal, with its hint
    with pytest.raises(LogFormatError, match="same header stamp; --stamps receive"):
        _imp(_bag(tmp_path / "all", sim, stamp=lambda t: 0.0 if t < 100.0 else T0 + t,
                  fix_stamp=lambda t: T0 + t))


def test_wheel_topics_are_refused_by_whole_words_of_their_names():
    """NOT_WHEELS matched substrings: "/volksbot/odom" was refused as visual
    odometry ("vo"). Whole words, trailing digits dropped."""
    from odomgraph.io.importers.rosbag import _not_wheels
    for fused in ("/odometry/filtered", "/ekf_odom", "/ekf2/odom", "/odom_fused", "/vo", "/camera/vio/odom",
                  "/rtabmap/visual_odometry", "/odometry/gps", "/global_odom", "/SLAM/odom"):
        assert _not_wheels(fused), fused
    for fused in ("/odomFiltered", "/ekfOdom", "/vioOdom", "/globalOdom"):        # camelCase words
        assert _not_wheels(fused), fused
    for wheels in ("/volksbot/odom", "/odom", "/wheel/odom", "/diff_drive_controller/odom", "/mobile_base/odom",
                   "/voyager/odom", "/ekfbot/odom", "/rover2/wheel_odom", "/volksbotOdom", "/wheelOdom"):
        assert not _not_wheels(wheels), wheels


def test_tf_static_chains_and_namespaced_frames_are_followed():
    """/tf_static was read only as a direct base_link -> frame transform: an
    antenna under base_link -> mast -> gps, or robot1/base_link ->
    robot1/gps, gave a lever arm of (0, 0) with "no /tf_static for frame"
    (a probe: batch and EKF z 5.5, degraded, blaming the lever arm). The
    chain is composed, a namespace is a base frame's too; a loop or a chain
    that never reaches a base frame gives none."""
    from odomgraph.io.importers.rosbag import _in_base, _lever_from_tf, _rotation
    s = np.sqrt(0.5)
    yaw180, roll180, yaw90 = _rotation(0, 0, 1, 0), _rotation(1, 0, 0, 0), _rotation(0, 0, s, s)
    eye = np.eye(3)
    frames = {("base_footprint", "base_link"): ((0.0, 0.0, 0.1), eye),
              ("base_link", "mast"): ((0.1, 0.0, 0.3), yaw180),       # the mast's x points backwards
              ("mast", "gps"): ((0.45, 0.05, 0.2), eye),
              ("base_link", "imu_mount"): ((0.0, 0.0, 0.1), roll180),
              ("imu_mount", "imu_link"): ((0.0, 0.0, 0.0), yaw90),
              ("robot1/base_link", "robot1/gps"): ((-0.3, 0.2, 0.5), eye),
              ("odom", "orphan"): ((1.0, 0.0, 0.0), eye),
              ("a", "b"): ((0.0, 0.0, 0.0), eye), ("b", "a"): ((0.0, 0.0, 0.0), eye)}
    notes = []
    # base_link first: the chain stops at the first base frame up from the antenna
    assert _lever_from_tf(frames, "gps", notes) == pytest.approx((0.1 - 0.45, -0.05))
    assert notes[-1] == "GPS lever arm (-0.350, -0.050) m from /tf_static base_link -> mast -> gps"
    assert _lever_from_tf(frames, "robot1/gps", notes) == pytest.approx((-0.3, 0.2))
    chain, _, R = _in_base(frames, "imu_link")
    # the IMU upside down: the robot's up is the IMU's -z
    assert chain == ["base_link", "imu_mount", "imu_link"] and R[2] == pytest.approx([0.0, 0.0, -1.0])
    assert _in_base(frames, "orphan") is None and _in_base(frames, "a") is None and _in_base(frames, "nowhere") is None
    assert _lever_from_tf(frames, "orphan", notes) == (0.0, 0.0) and "not in /tf_static" in notes[-1]


def test_a_joint_state_publisher_beside_the_driver_is_skipped(sim, clean, tmp_path):
    """joint_state_publisher sending every joint at 0 on /joint_states beside
    the wheel driver was interleaved with it: wheels jumping to 0 and back
    (a probe: batch 1.76 at z +26 blaming an encoder counting backwards, or a
    refusal naming a 1003 m/s wheel). Its messages are skipped with a note,
    and the wheels equal the clean bag's; a robot that stands still all
    along (both publishers constant) is left as it is."""
    jsp = ("caster_joint", *JOINTS)
    log = _imp(_bag(tmp_path / "jsp", sim, arm_every=2, arm_names=jsp, arm_position=(0.0, 0.0, 0.0)))
    np.testing.assert_array_equal(log.wheel_speeds.v_left, clean.wheel_speeds.v_left)
    np.testing.assert_array_equal(log.wheel_speeds.v_right, clean.wheel_speeds.v_right)
    k = (len(sim.encoders.t) + 1) // 2
    assert any(n.startswith(f"/joint_states: {k} messages from another publisher") for n in log.notes)
    # a driver that publishes velocities only, beside the publisher's positions: its velocities are used
    vel = _imp(_bag(tmp_path / "jspv", sim, positions=False, velocities=True, arm_every=3, arm_names=jsp,
                    arm_position=(0.0, 0.0, 0.0)))
    assert len(vel.wheel_speeds.t) == len(sim.encoders.t) and np.ptp(vel.wheel_speeds.v_left) > 0.5


def test_a_wheel_driver_restart_is_left_out_not_taken_as_a_backward_drive(sim, clean, tmp_path):
    """A wheel driver restarting (3 s without messages, then positions from
    0 again) was imported as one -9 m/s row lasting 3 s, without a word, and
    the estimators blamed an encoder counting backwards (a probe). The
    interval across the restart is left out with a note; the rest equal the
    clean bag's. A robot driving back through 0 is not a restart."""
    e = sim.encoders
    log = _imp(_bag(tmp_path / "restart", sim, restart=(12.0, 15.0)))
    k0, k1 = int(np.searchsorted(e.t, 12.0)), int(np.searchsorted(e.t, 15.0))
    assert any("began again near 0 (a driver restart) 1 time(s), at t = " f"{e.t[k0 - 1]:.2f}-{e.t[k1]:.2f} s" in n
               for n in log.notes)
    ws, ref = log.wheel_speeds, clean.wheel_speeds
    assert len(ws.t) == len(ref.t) - (k1 - k0) - 1 and np.all(np.abs(ws.v_left) < 3.0)
    np.testing.assert_array_equal(ws.v_left[:k0 - 1], ref.v_left[:k0 - 1])
    np.testing.assert_array_equal(ws.v_right[k0 - 1:], ref.v_right[k1:])
    from odomgraph.io.importers.rosbag import _restarts
    back = np.concatenate([np.linspace(40.0, -5.0, 400), np.linspace(-5.0, 3.0, 50)])
    assert not _restarts(back, 0.5 * back).any()
    # each guard on its own: a big step that does not land near 0, one from near 0, one as small as the rest
    steady = np.linspace(0.0, 300.0, 301)
    assert _restarts(np.r_[steady, 0.2, 1.2], np.r_[steady, 0.1, 1.1]).sum() == 1
    assert not _restarts(np.r_[steady, 50.0, 51.0], np.r_[steady, 0.1, 1.1]).any()
    assert not _restarts(np.r_[np.linspace(0.0, 6.0, 301), 0.2, 0.22], np.r_[steady[:301] / 50, 0.1, 0.12]).any()
    fast = np.arange(0.0, 40.0, 8.0)                    # steps of 8 rad: a step back to 0 of 32 is only 4 of them
    assert not _restarts(np.r_[fast, 0.5], np.r_[fast, 0.4]).any()


def test_a_clock_stepping_back_is_said_and_a_big_step_refused(sim, tmp_path):
    """A system clock stepping back (chrony) under the header stamps: 0.1-0.3
    s imported silently with rows at 50-141 m/s, 1 s was refused for "a
    wheel speed of 2468 m/s" with no word of the clock (a probe). Now each
    topic's step is said with the --stamps receive hint; a wheel topic
    stepping back 0.5 s or more is refused with it; receive stamps import."""
    T0 = 1_700_000_000.0
    small = _imp(_bag(tmp_path / "small", sim, stamp=lambda t: T0 + t - (0.15 if t > 12.0 else 0.0)))
    for topic in ("/joint_states", "/fix", "/imu"):
        line = next(w for w in small.warnings if w.startswith(f"{topic}: its header stamps step back 1 time(s)"))
        assert "by about 0.15 s" in line and line.endswith("--stamps receive uses the bag's receive times")
    with pytest.raises(LogFormatError, match=r"/joint_states: its header stamps step back 1 time\(s\), by about 1 s"):
        _imp(_bag(tmp_path / "big", sim, stamp=lambda t: T0 + t - (1.0 if t > 12.0 else 0.0)))
    rx = _imp(tmp_path / "big", stamps="receive")
    assert not any("step back" in w for w in rx.warnings) and np.abs(rx.wheel_speeds.v_left).max() < 3.0
    # jitter that keeps the stamps in order is nothing
    rng = np.random.default_rng(3)
    calm = _imp(_bag(tmp_path / "calm", sim, stamp=lambda t: T0 + t + 0.004 * rng.random()))
    assert not any("step back" in w for w in calm.warnings)


def test_a_driver_that_never_sets_its_stamps_beside_joint_state_publisher_is_refused(sim, tmp_path):
    """The wheel driver leaves every header stamp at 0 while a
    joint_state_publisher on the same topic sets its own: the driver's
    messages were dropped as "unset among others", and the publisher's
    zeros became a robot that never moved (a second read). Each publisher
    is judged on its own: the driver's all-unset stamps are refused with
    the --stamps receive hint, which imports the wheels."""
    T0 = 1_700_000_000.0
    grid = set(np.round(sim.encoders.t, 9))
    jsp = ("caster_joint", *JOINTS)
    path = _bag(tmp_path / "b", sim, arm_every=2, arm_names=jsp, arm_position=(0.0, 0.0, 0.0),
                stamp=lambda t: 0.0 if round(t, 9) in grid else T0 + t)
    with pytest.raises(LogFormatError, match="same header stamp; --stamps receive"):
        _imp(path)
    rx = _imp(path, stamps="receive")
    assert np.abs(rx.wheel_speeds.v_left).max() > 0.5
