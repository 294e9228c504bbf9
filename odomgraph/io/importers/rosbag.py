"""ROS 1 / ROS 2 bags, read with the ``rosbags`` package (no ROS install needed).

Topics are chosen by the caller:

* wheels: ``sensor_msgs/JointState``; positions [rad] are differenced and
  converted with the wheel radius (speeds stamped at the interval midpoint),
  or velocities [rad/s] are used directly when there are no positions;
* GPS: ``sensor_msgs/NavSatFix`` -> lat/lon projected to a local east/north
  frame at the first fix (fixes with status < 0, i.e. no fix, are dropped);
* gyro: ``sensor_msgs/Imu`` angular_velocity.z.

Times are the messages' header stamps, the clock the sensors share.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odomgraph.errors import LogFormatError
from odomgraph.io.geodesy import latlon_to_local
from odomgraph.io.log import Gps, Gyro, Log, WheelSpeeds
from odomgraph.io.robot import RobotConfig


def _stamp(msg) -> float:
    return msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec


def _increasing(t: np.ndarray, *cols):
    order = np.argsort(t, kind="stable")
    t = t[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    return (t[keep], *(c[order][keep] for c in cols))


def import_rosbag(bag: Path | str, wheel_topic: str, left_joint: str, right_joint: str, wheel_radius: float,
                  track_width: float, gps_topic: str | None = None, imu_topic: str | None = None,
                  gyro_sigma: float = 0.01, encoder_sigma=(0.005, 0.01),
                  gps_lever_arm=(0.0, 0.0)) -> Log:
    """Import wheel joints (and optionally GPS and gyro) from a bag; see the module doc.

    The antenna's lever arm (robot frame [m]) is not in NavSatFix (ROS keeps it
    in TF), so it is given here; a wrong one makes the estimators report
    divergence on the GPS."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise LogFormatError(bag, "reading bags needs the 'rosbags' package: pip install 'odomgraph[rosbag]'") from None
    bag = Path(bag)
    if not bag.exists():
        raise LogFormatError(bag, "bag does not exist")
    if wheel_radius <= 0 or track_width <= 0:
        raise LogFormatError(bag, "--wheel-radius and --track-width must be positive")
    wanted = {t for t in (wheel_topic, gps_topic, imu_topic) if t}
    joints, fixes, rates = [], [], []
    try:
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            present = {c.topic for c in reader.connections}
            missing = wanted - present
            if missing:
                raise LogFormatError(bag, f"topic(s) {sorted(missing)} not in the bag (it has {sorted(present)})")
            conns = [c for c in reader.connections if c.topic in wanted]
            for conn, _t, raw in reader.messages(connections=conns):
                msg = reader.deserialize(raw, conn.msgtype)
                if conn.topic == wheel_topic:
                    names = list(msg.name)
                    if left_joint not in names or right_joint not in names:
                        raise LogFormatError(bag, f"{wheel_topic}: joints {left_joint!r}/{right_joint!r} not in "
                                                  f"{names}")
                    il, ir = names.index(left_joint), names.index(right_joint)
                    pos = np.asarray(msg.position, float)
                    vel = np.asarray(msg.velocity, float)
                    joints.append((_stamp(msg), *(pos[[il, ir]] if pos.size else (np.nan, np.nan)),
                                   *(vel[[il, ir]] if vel.size else (np.nan, np.nan))))
                elif conn.topic == gps_topic:
                    if msg.status.status >= 0:
                        cov = np.asarray(msg.position_covariance, float)
                        sig = float(np.sqrt(0.5 * (cov[0] + cov[4]))) if msg.position_covariance_type > 0 else np.nan
                        fixes.append((_stamp(msg), msg.latitude, msg.longitude, sig))
                else:
                    rates.append((_stamp(msg), msg.angular_velocity.z))
    except LogFormatError:
        raise
    except Exception as exc:  # rosbags raises its own types for unreadable bags
        raise LogFormatError(bag, f"cannot read the bag: {exc}") from None
    if len(joints) < 2:
        raise LogFormatError(bag, f"{wheel_topic}: fewer than two JointState messages")
    j = np.array(joints)
    t, pl, pr, vl, vr = _increasing(j[:, 0], j[:, 1], j[:, 2], j[:, 3], j[:, 4])
    if np.all(np.isfinite(pl)) and np.all(np.isfinite(pr)):
        dt = np.diff(t)
        ws = WheelSpeeds(0.5 * (t[1:] + t[:-1]), np.diff(pl) * wheel_radius / dt, np.diff(pr) * wheel_radius / dt)
    elif np.all(np.isfinite(vl)) and np.all(np.isfinite(vr)):
        ws = WheelSpeeds(t, vl * wheel_radius, vr * wheel_radius)
    else:
        raise LogFormatError(bag, f"{wheel_topic}: JointState has neither positions nor velocities for the wheels")
    gps = None
    origin = None
    gps_sigma = 0.05
    if fixes:
        f = np.array(fixes)
        tf, lat, lon, sig = _increasing(f[:, 0], f[:, 1], f[:, 2], f[:, 3])
        origin = (float(lat[0]), float(lon[0]))
        x, y = latlon_to_local(lat, lon, *origin)
        if np.all(np.isfinite(sig)) and np.all(sig > 0):
            gps = Gps(tf, x, y, sig)
            gps_sigma = float(np.median(sig))
        else:
            gps = Gps(tf, x, y)
    gyro = None
    if rates:
        g = np.array(rates)
        tg, om = _increasing(g[:, 0], g[:, 1])
        gyro = Gyro(tg, om)
    robot = RobotConfig(ticks_per_meter_left=1.0, ticks_per_meter_right=1.0, track_width=track_width,
                        encoder_sigma=tuple(encoder_sigma), gps_sigma=gps_sigma, gps_origin=origin,
                        gps_lever_arm=tuple(float(v) for v in gps_lever_arm),
                        gyro_sigma=gyro_sigma)
    return Log(robot=robot, wheel_speeds=ws, gps=gps, gyro=gyro, notes=(f"imported from bag {bag.name}",))
