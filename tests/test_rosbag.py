"""The rosbag importer: a ROS 2 bag written with rosbags itself from a
simulated log (JointState wheel positions, NavSatFix, Imu), imported back."""
import numpy as np
import pytest

rosbags = pytest.importorskip("rosbags")

from odomgraph.errors import LogFormatError  # noqa: E402
from odomgraph.estimators.schedule import Schedule  # noqa: E402
from odomgraph.io.importers.rosbag import import_rosbag  # noqa: E402
from odomgraph.pipeline import Method, estimate  # noqa: E402
from odomgraph.sim.scenarios import paper  # noqa: E402
from odomgraph.sim.simulate import simulate  # noqa: E402

LAT0, LON0, R_WHEEL = 41.5045, -81.6086, 0.15


def _write_bag(path, log):
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
    with Writer(path, version=8) as w:
        cj = w.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ts)
        cg = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
        ci = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        e, r = log.encoders, log.robot
        angle_l = np.cumsum(e.ticks_left) / r.ticks_per_meter_left / R_WHEEL
        angle_r = np.cumsum(e.ticks_right) / r.ticks_per_meter_right / R_WHEEL
        for t, al, ar in zip(e.t, angle_l, angle_r):
            msg = T["sensor_msgs/msg/JointState"](header=header(t), name=["left_wheel_joint", "right_wheel_joint"],
                                                  position=np.array([al, ar]), velocity=np.array([], float),
                                                  effort=np.array([], float))
            w.write(cj, int(t * 1e9), ts.serialize_cdr(msg, "sensor_msgs/msg/JointState"))
        g = log.gps
        for t, x, y in zip(g.t, g.x, g.y):
            cov = np.zeros(9)
            cov[0] = cov[4] = r.gps_sigma**2
            msg = T["sensor_msgs/msg/NavSatFix"](
                header=header(t), status=T["sensor_msgs/msg/NavSatStatus"](status=0, service=1),
                latitude=LAT0 + np.degrees(y / M), longitude=LON0 + np.degrees(x / (N * np.cos(np.radians(LAT0)))),
                altitude=200.0, position_covariance=cov, position_covariance_type=2)
            w.write(cg, int(t * 1e9), ts.serialize_cdr(msg, "sensor_msgs/msg/NavSatFix"))
        V3, Q = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
        for t, om in zip(log.gyro.t, log.gyro.omega):
            msg = T["sensor_msgs/msg/Imu"](header=header(t), orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0),
                                           orientation_covariance=np.zeros(9), angular_velocity=V3(x=0.0, y=0.0, z=om),
                                           angular_velocity_covariance=np.zeros(9),
                                           linear_acceleration=V3(x=0.0, y=0.0, z=9.81),
                                           linear_acceleration_covariance=np.zeros(9))
            w.write(ci, int(t * 1e9), ts.serialize_cdr(msg, "sensor_msgs/msg/Imu"))


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
