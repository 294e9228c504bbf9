"""ROS 1 / ROS 2 bags (.bag, a rosbag2 directory, sqlite3 or mcap), read with
the ``rosbags`` package (no ROS install needed).

Topics are picked by their type when the choice is unambiguous, or given:

* wheels, one of
  - ``sensor_msgs/JointState``: positions [rad] are differenced and converted
    with the wheel radius (speeds stamped at the interval midpoint), or
    velocities [rad/s] are used when there are no positions. The wheel
    joints are found by name (left/right, "wheel" first); a skid-steer's
    front and rear wheels on a side are averaged, as a diff-drive controller
    does;
  - ``nav_msgs/Odometry`` or ``geometry_msgs/TwistStamped``: the body twist
    (v, omega) becomes per-wheel surface speeds through the nominal track,
    v -/+ omega b/2. This assumes the odometry came from the wheels alone
    (diff_drive_controller's does; robot_localization's filtered output does
    not, and is never picked by itself; nor is a velocity command, /cmd_vel:
    what was asked of the wheels, not what they did);
  - two std_msgs integer tick counters named left/right, when no other topic
    may be the wheels' measurement or --ticks-per-meter is given;
* GPS: ``sensor_msgs/NavSatFix`` -> lat/lon projected to a local east/north
  frame at the first fix; fixes with status < 0 (no fix) are dropped and
  counted; the position covariance, when given, becomes each fix's sigma;
* gyro: ``sensor_msgs/Imu`` angular_velocity on the axis that measures yaw.
  A mounted IMU often reports yaw on another axis (issue 13: a robot's y
  axis correlated 0.86 with its odometry's yaw rate against 0.01 for z), so
  by default the axis and sign that follow the wheels' turn rate are taken,
  with a warning when that is not +z; the mounting in /tf_static
  (base_link -> the IMU's frame) is used when the bag has it.

Times are the messages' header stamps, the clock the sensors share (or the
bag's receive times). Tick counters, without a header, carry the receive
times: when the header topics' receive times run a clock offset after their
stamps, the counters are moved onto the header clock, with a warning; a
header topic on a clock of its own (GPS time, a boot clock) is said, or
refused when its times would not meet the others'. Bags on a real clock start near 1.7e9 s, where a
float64 keeps only 0.24 us: the log counts from the first whole second
(Log.t_origin), taken from the integer nanoseconds, so no interval loses a
digit, and the files written carry the absolute stamps.
"""
from __future__ import annotations

import re
import shutil
import tempfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from odomgraph.errors import LogFormatError
from odomgraph.factors._math import robust_sigma, wrap_angle
from odomgraph.io.csvtable import ORIGIN_ABOVE
from odomgraph.io.geodesy import latlon_to_local
from odomgraph.io.log import Encoders, Gps, Gyro, Log, WheelSpeeds
from odomgraph.io.robot import RobotConfig

WHEEL_TYPES = {"sensor_msgs/msg/JointState": "joints", "nav_msgs/msg/Odometry": "odometry",
               "geometry_msgs/msg/TwistStamped": "twist"}
IMU_TYPE, GPS_TYPE, TF_TYPE = "sensor_msgs/msg/Imu", "sensor_msgs/msg/NavSatFix", "tf2_msgs/msg/TFMessage"
#: Bare integer tick counters (std_msgs), with the width at which they wrap (None: never).
TICK_TYPES = {"std_msgs/msg/Int16": 16, "std_msgs/msg/UInt16": 16, "std_msgs/msg/Int32": 32,
              "std_msgs/msg/UInt32": 32, "std_msgs/msg/Int64": None, "std_msgs/msg/UInt64": None}
#: Words of topic names that are never picked as wheels by themselves: fused, not wheel, odometry.
#: Matched against whole words of the name (a probe: "/volksbot/odom" was refused for "vo").
NOT_WHEELS = ("filtered", "ekf", "fused", "global", "gps", "visual", "vo", "vio", "slam")
#: Words of topic names that say a velocity command: what a planner, a
#: joystick or a teleop node asked for, not what the wheels did (a probe:
#: Nav2's stamped /cmd_vel taken for the wheels calibrated the command, every
#: scale z -34 to +36 with status ok). Never picked by themselves; given with
#: --wheel-topic, a warning. Whole words, as NOT_WHEELS.
COMMAND_WORDS = ("cmd", "command", "commands", "teleop", "joy", "joystick", "keyboard", "setpoint", "reference",
                 "ref", "target", "goal", "nav", "desired", "demand")
#: ...unless a word of the name says it was measured (a controller's feedback
#: published as /cmd_vel_measured).
MEASURED_WORDS = ("measured", "meas", "feedback", "fb", "actual")
#: Velocity messages that no driver publishes as a measurement (no stamp, no
#: frame): named in the refusal when a bag holds only commands.
COMMAND_TYPES = ("geometry_msgs/msg/Twist",)
#: The stamp given to a message whose header stamp is unset (0 s 0 ns) while it is read.
UNSET = -np.inf
AXES = ("x", "y", "z")
#: The robot's own frame, as ROS names it (REP 105).
BASE_FRAMES = ("base_link", "base_footprint")
#: The wheels must turn this much (std of yaw rate [rad/s]) for the IMU axis to be chosen from the data.
MIN_TURN = 0.05


@dataclass(frozen=True)
class Topic:
    """One topic of a bag, as ``--list`` shows it."""
    topic: str
    msgtype: str
    count: int
    rate_hz: float
    role: str | None
    """"wheels", "imu" or "gps" when the importer would pick it, else None."""


@contextmanager
def _reader(bag: Path):
    """An open rosbags reader of ``bag`` (a ROS 1 file or a ROS 2 directory).
    A ROS 1 file not named *.bag is read through a *.bag link in a temporary
    directory, removed when the reader closes."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise LogFormatError(bag, "reading bags needs the 'rosbags' package: pip install 'odomgraph[rosbag]'") from None
    if not bag.exists():
        raise LogFormatError(bag, "bag does not exist")
    tmp = None
    if bag.is_file() and bag.suffix != ".bag":
        with open(bag, "rb") as f:
            head = f.read(13)
        if head != b"#ROSBAG V2.0\n":
            raise LogFormatError(bag, "is a file but not a ROS 1 bag (no '#ROSBAG V2.0' header); a ROS 2 bag is a "
                                      "directory with metadata.yaml")
        tmp = Path(tempfile.mkdtemp(prefix="odomgraph-bag-"))
    try:
        if tmp is not None:
            # rosbags tells ROS 1 from ROS 2 by the name: read it through a *.bag link
            link = tmp / (bag.name + ".bag")
            link.symlink_to(bag.resolve())
            bag = link
        with AnyReader([bag], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            yield reader
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def _unreadable(bag: Path, exc: Exception) -> LogFormatError:
    """rosbags' error for a bag it cannot read, in one line, with the
    remedy when it is a recording that was killed: a ROS 1 bag cut off
    before its index was written, a ROS 2 directory without metadata.yaml,
    an mcap file cut off before its footer ("File end magic is invalid")."""
    text = " ".join(str(exc).split())
    storage = [f for f in bag.iterdir() if f.suffix in (".db3", ".mcap")] if bag.is_dir() else []
    if storage and not (bag / "metadata.yaml").exists():
        return LogFormatError(bag, f"cannot read the bag: no metadata.yaml (a recording that was killed?): "
                                   f"'ros2 bag reindex {bag}"
                                   f"{' -s mcap' if storage[0].suffix == '.mcap' else ''}' writes it")
    if storage and storage[0].suffix == ".mcap" and "magic" in text.lower():
        # a recording killed before it wrote the mcap file's footer (a probe: no remedy said)
        return LogFormatError(bag, f"cannot read the bag: {text} (a recording that was killed?): "
                                   f"'mcap recover {storage[0]} -o FIXED.mcap' (the mcap CLI) rescues its messages; "
                                   f"put FIXED.mcap alone in a directory and 'ros2 bag reindex DIR -s mcap' writes "
                                   "its metadata.yaml")
    if bag.is_file() and type(exc).__module__.startswith("rosbags") and "index" in text.lower():
        return LogFormatError(bag, f"cannot read the bag: {text} (a recording that was killed?): "
                                   f"'rosbag reindex {bag}' mends it")
    return LogFormatError(bag, f"cannot read the bag: {text}")


def _stamp_ns(msg) -> int:
    """The header stamp in integer nanoseconds (exact; a float of 1.7e18 ns is not)."""
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _increasing(t: np.ndarray, *cols):
    order = np.argsort(t, kind="stable")
    t = t[order]
    keep = np.concatenate([[True], np.diff(t) > 0])
    return (t[keep], *(c[order][keep] for c in cols))


def _words(topic: str) -> set[str]:
    """The words of a topic's name: split at "/", "_", "-", the like and
    camelCase, lower case, trailing digits dropped ("ekf2" is "ekf")."""
    spaced = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", topic)       # camelCase: /odomFiltered
    return {w.rstrip("0123456789") for w in re.split(r"[^a-z0-9]+", spaced.lower())}


def _not_wheels(topic: str) -> bool:
    """True when a word of the topic's name says it is not the wheels' own
    odometry (NOT_WHEELS)."""
    return bool(_words(topic) & set(NOT_WHEELS))


def _is_command(topic: str) -> bool:
    """True when a word of the topic's name says a velocity command
    (COMMAND_WORDS: /cmd_vel, /teleop/twist, /nav_vel), and none says it was
    measured (MEASURED_WORDS)."""
    words = _words(topic)
    return bool(words & set(COMMAND_WORDS)) and not words & set(MEASURED_WORDS)


def _commands(conns) -> list[str]:
    """The topics, with messages, that carry velocity commands: of a wheel
    type with a name that says so (_is_command), or bare Twists (COMMAND_TYPES)."""
    return sorted({c.topic for c in conns if c.msgcount > 0 and (
        c.msgtype in COMMAND_TYPES or (c.msgtype in WHEEL_TYPES and _is_command(c.topic)))})


def _drop_unset(topic: str, rows: list, real_clock: bool, notes: list, publisher=None) -> None:
    """Rows whose header stamp was 0 s (stamp UNSET, first element) are
    dropped with a note when the bag runs on a real clock and their
    publisher has others; on a simulated clock (use_sim_time, from 0) 0 s is
    a stamp like any other. When every message of a publisher was unset
    they all take one stamp, so that the equal-stamp checks refuse or leave
    out the sensor with the --stamps receive hint. In place, in order.
    ``publisher(row)`` tells publishers on one topic apart (JointState:
    _publisher): a driver that never sets its stamps beside a
    joint_state_publisher that does must not leave the publisher's zeros
    as the wheels (a second read)."""
    keys = [publisher(r) if publisher is not None else None for r in rows]
    total: dict = {}
    unset: dict = {}
    for r, k in zip(rows, keys):
        total[k] = total.get(k, 0) + 1
        unset[k] = unset.get(k, 0) + (r[0] == UNSET)
    if not any(unset.values()):
        return
    out, dropped = [], 0
    for r, k in zip(rows, keys):
        if r[0] != UNSET:
            out.append(r)
        elif real_clock and unset[k] < total[k]:
            dropped += 1
        else:
            out.append((0.0, *r[1:]))
    rows[:] = out
    if dropped:
        notes.append(f"{topic}: {dropped} of {len(keys)} messages with an unset header stamp (0 s) dropped")


#: Header stamps stepping back more than this many of the topic's periods (at
#: least STEP_BACK_MIN_S) from one message to the next, in the order the bag
#: received them: a clock step (a step back of 0.1 s at 20 Hz is one message
#: stamped 0.05 s before the one received before it).
STEP_BACK_PERIODS = 0.5
STEP_BACK_MIN_S = 0.01
#: A wheel topic stepping back this far [s] is refused: its rows interleave
#: two stretches of time (a probe: 1 s back read as a 2468 m/s wheel).
STEP_BACK_REFUSE_S = 0.5


def _steps_back(bag, topic: str, rows: list, wheels: bool, warnings: list) -> None:
    """Say a topic whose header stamps (rows' first element, in the order
    the bag received them) step back: a system clock stepped (chrony, NTP),
    and sorting by stamp interleaves the rows before and after it (a probe:
    0.1-0.3 s back imported silently, rows at 50-141 m/s that the
    estimators then rejected; 1 s back refused for a 2468 m/s wheel, with
    no word of the clock). A warning with the --stamps receive hint; a
    wheel topic stepping back STEP_BACK_REFUSE_S or more is refused."""
    t = np.array([r[0] for r in rows if r[0] != UNSET], float)
    if t.size < 3:
        return
    d = np.diff(t)
    ahead = d[d > 0]
    period = float(np.median(ahead)) if ahead.size else 0.0
    k = np.flatnonzero(-d > max(STEP_BACK_PERIODS * period, STEP_BACK_MIN_S))
    if not k.size:
        return
    worst = int(k[np.argmax(-d[k])])
    # the clock's step: the stamp fell short of the one before by this, where it should have gained a period
    line = (f"{topic}: its header stamps step back {k.size} time(s), by about {period - d[worst]:.2g} s (after "
            f"t = {t[worst]:.2f} s in the log's clock): a clock step; sorted by stamp, the rows around it "
            "interleave. --stamps receive uses the bag's receive times")
    if wheels and period - d[worst] >= STEP_BACK_REFUSE_S:
        raise LogFormatError(bag, line)
    warnings.append(line)


#: Header-stamped topics whose median (receive - header) lags differ by more
#: than CLOCK_AGREE_S [s], and by more than CLOCK_JITTER_TIMES their lags'
#: jitter (robust sigma), run on different clocks: a GPS receiver publishes
#: its fix within half a second, an IMU within milliseconds (a probe: a GPS
#: stamped on GPS time, 18 s ahead of the others, imported without a word).
CLOCK_AGREE_S = 1.0
CLOCK_JITTER_TIMES = 10.0
#: Receive-stamped topics (tick counters) are moved onto the header clock
#: when the least lag of the header topics is this far [s] or more: beyond
#: what a message takes to reach the recorder (milliseconds on one machine,
#: tens over a network) or a receiver to publish its fix (a probe: a bag
#: recorded 10 s late put the encoders 10 s behind gps.csv and gyro.csv).
CLOCK_SHIFT_S = 0.25
#: GPS time runs this far [s] ahead of UTC (leap seconds since 1980, as of 2017).
GPS_LEAP_S = 18.0


def _header_clocks(bag, clocks: dict[str, np.ndarray], roles: dict[str, str], receive: list[str], span_s: float,
                   warnings: list) -> int:
    """The shift [ns] that takes the receive-stamped topics ``receive`` (the
    tick counters, without a header) onto the header topics' clock, from each
    header topic's median lag (receive - header) [ns] (``clocks``: {topic:
    (N, 2) [receive, header] int64 [ns]}, unset stamps left out; ``roles``:
    {topic: wheels, imu or gps}).

    The clock is the one most header topics agree on (CLOCK_AGREE_S; on a
    tie, the one nearest the receive times). A header topic off it is a
    warning naming it and its offset, or, when its times would not meet the
    others' (off by more than the bag's span ``span_s`` [s]: a sensor's boot
    clock, the GPS epoch), refused with the --stamps receive remedy. The
    receive-stamped topics move by the agreeing topics' least lag (the least
    delayed, an IMU: the clocks' offset) when that is CLOCK_SHIFT_S or more,
    with a warning; header stamps on a simulated clock (use_sim_time, from
    0 s) beside receive times on a wall clock are refused."""
    lags = {t: np.sort(v[:, 0] - v[:, 1]) for t, v in clocks.items() if len(v)}
    if not lags:
        return 0
    med = {t: int(d[d.size // 2]) for t, d in lags.items()}
    sec = {t: 1e-9 * m for t, m in med.items()}
    jitter = {t: 1e-9 * robust_sigma(d - med[t]) for t, d in lags.items()}

    def agree(a: str, b: str) -> bool:
        return abs(sec[a] - sec[b]) <= max(CLOCK_AGREE_S, CLOCK_JITTER_TIMES * (jitter[a] + jitter[b]))
    topics = sorted(lags)
    ref = max(topics, key=lambda t: (sum(agree(t, u) for u in topics), -abs(sec[t])))
    same = [t for t in topics if agree(ref, t)]
    for t in topics:
        if t in same:
            continue
        ahead = sec[ref] - sec[t]      # its header clock less the others' [s]
        role = roles.get(t, "wheels")
        leap = " (GPS time runs 18 s ahead of UTC)" if role == "gps" and abs(ahead - GPS_LEAP_S) < 1.0 else ""
        line = (f"{t}: its header stamps are {abs(sec[t]):.4g} s off its receive times, those of {same} "
                f"{abs(sec[ref]):.2g} s (receive - header, medians): its header clock runs {abs(ahead):.4g} s "
                f"{'ahead of' if ahead > 0 else 'behind'} theirs{leap}")
        remedy = ("--stamps receive stamps every topic with the bag's receive times"
                  + ("" if role == "wheels" else f", or --{role}-topic '' leaves it out"))
        if abs(ahead) > max(span_s, CLOCK_AGREE_S):
            raise LogFormatError(bag, f"{line}, and its times would not meet theirs (a sensor's own clock?): {remedy}")
        warnings.append(f"{line}: its rows in the log are that far off the others'; {remedy}")
    if not receive:
        return 0
    lead = min(same, key=lambda t: abs(med[t]))       # the least delayed: the clocks' offset
    shift = med[lead]
    if abs(shift) < CLOCK_SHIFT_S * 1e9:
        return 0
    rx, hdr = (int(np.median(clocks[lead][:, c])) for c in (0, 1))
    if hdr < ORIGIN_ABOVE * 1e9 <= rx:
        raise LogFormatError(bag, f"the tick counters {receive} carry the bag's receive times (a wall clock, near "
                                  f"{rx * 1e-9:.4g} s) while the header stamps of {same} run on a simulated clock "
                                  f"(use_sim_time, near {hdr * 1e-9:.4g} s): no offset puts them on one clock; "
                                  "--stamps receive stamps every topic with the receive times")
    warnings.append(f"the tick counters {receive} carry the bag's receive times, {abs(shift) * 1e-9:.4g} s "
                    f"{'after' if shift > 0 else 'before'} the header stamps of {same} (receive - header of {lead}, "
                    f"median): two clocks; the counters are moved {abs(shift) * 1e-9:.4g} s "
                    f"{'earlier' if shift > 0 else 'later'}, onto the header clock (--stamps receive puts every "
                    "topic on the receive clock instead)")
    return shift


def _seconds(rows: list, origin_ns: int | None) -> list:
    """Rows whose first element is a stamp in integer nanoseconds (or UNSET)
    with that stamp in seconds since ``origin_ns``, in the same order."""
    return [(r[0] if r[0] == UNSET else 1e-9 * (r[0] - (origin_ns or 0)), *r[1:]) for r in rows]


def _candidates(conns) -> dict[str, list]:
    """{role: [connection, ...]} of the topics each role could take."""
    out = {"wheels": [], "imu": [], "gps": []}
    for c in conns:
        if c.msgcount == 0:     # listed in the bag, never published
            continue
        if c.msgtype in WHEEL_TYPES:
            out["wheels"].append(c)
        elif c.msgtype == IMU_TYPE:
            out["imu"].append(c)
        elif c.msgtype == GPS_TYPE:
            out["gps"].append(c)
    return out


def _tick_candidates(conns) -> tuple[list[str], list[str]]:
    """The integer topics with "left" and with "right" in their names."""
    ints = [c for c in conns if c.msgtype in TICK_TYPES and c.msgcount > 0]
    return (sorted({c.topic for c in ints if "left" in c.topic.lower()}),
            sorted({c.topic for c in ints if "right" in c.topic.lower()}))


def _tick_pair(conns) -> tuple[str, str] | None:
    """(left, right) tick-counter topics: the one integer topic with "left" in
    its name and the one with "right", or None when that is not clear."""
    ls, rs = _tick_candidates(conns)
    return (ls[0], rs[0]) if len(ls) == 1 and len(rs) == 1 else None


def _measured_wheels(cands: dict[str, list]) -> list[str]:
    """The wheel candidates that may be the wheels' own measurement: neither
    fused (_not_wheels) nor a command (_is_command)."""
    return sorted({c.topic for c in cands["wheels"] if not _not_wheels(c.topic) and not _is_command(c.topic)})


def _auto_ticks(bag, conns, cands: dict[str, list], ticks_given: bool, notes: list) -> tuple[str, str] | None:
    """The tick counters taken as the wheels when no wheel topic is named:
    the pair named left/right (_tick_pair) when the bag has no other topic
    that may be the wheels' measurement (commands and fused outputs are
    none), or when --ticks-per-meter is given: raw encoder counts are the
    wheels' own measurement, a twist beside them at best derived from them
    (a probe: the counters and the option passed over for /cmd_vel). Else a
    note names the counters. Integer topics that are no clear pair are
    refused when counters would be taken."""
    measured = _measured_wheels(cands)
    pair = _tick_pair(conns)
    if pair and (ticks_given or not measured):
        notes.append(f"wheels: picked the tick counters {pair[0]} and {pair[1]}"
                     + (f" (the encoders' own counts, --ticks-per-meter given) over {measured}" if measured else ""))
        return pair
    if pair:
        notes.append(f"tick counters {pair[0]} and {pair[1]} beside {measured}: --ticks-per-meter TPM takes them "
                     "(the encoders' own counts) instead")
        return None
    ls, rs = _tick_candidates(conns)
    if (ls or rs) and (ticks_given or not measured):
        raise LogFormatError(bag, f"integer topics that may be tick counters: left {ls or 'none'}, "
                                  f"right {rs or 'none'}; not one of each: give --tick-topics LEFT,RIGHT")
    return None


def _unwrap_counts(c: np.ndarray, bits: int | None, notes: list | None = None, topic: str = "") -> np.ndarray:
    """Cumulative tick counts with the counter's wrap-around removed (a 16-bit
    counter wraps every 65536 ticks: a few metres on a small robot). A
    narrower counter carried in a wider message (a 16-bit encoder in an
    Int32, as microcontroller bridges publish it) is found from its values:
    all inside the narrow range, with jumps that the narrow wrap makes small."""
    c = np.asarray(c, dtype=np.int64)
    if c.size < 2:
        return c
    for narrow in (16, 32):
        if narrow >= (bits or 64):                      # (64 bits: no wrap in any robot's life)
            break
        if c.min() < -(1 << (narrow - 1)) or c.max() > (1 << narrow) - 1:
            continue                                    # beyond the narrow range: wider than it
        d = np.diff(c)
        wrapped = (d + (1 << (narrow - 1))) % (1 << narrow) - (1 << (narrow - 1))
        big = np.abs(d) >= 1 << (narrow - 1)
        # each big step crosses the range's ends (top quarter to bottom quarter or back), as a wrap
        # does; a counter reset or a gap jumps from anywhere (a review: 10000 -> 60000 is no wrap)
        lo = -(1 << (narrow - 1)) if c.min() < 0 else 0        # a signed counter's range, or an unsigned one's
        span = 1 << narrow
        rel_a, rel_b = (c[:-1][big] - lo) / span, (c[1:][big] - lo) / span
        crosses = np.all(((rel_a >= 0.75) & (rel_b < 0.25)) | ((rel_a < 0.25) & (rel_b >= 0.75)))
        # ...and, wrapped, is a step like the others (10000 -> 60000 could be a backward wrap of 15536,
        # but not among steps of 500)
        typical = 8.0 * float(np.median(np.abs(d[~big]))) + 16.0 if (~big).any() else 0.0
        if big.any() and crosses and np.abs(wrapped[big]).max() <= typical and np.abs(wrapped).max() < 1 << (narrow - 2):
            if notes is not None:
                notes.append(f"{topic}: the counter wraps at {narrow} bits inside its {bits or 64}-bit message: "
                             "unwrapped")
            bits = narrow
        break
    if bits is None:
        return c
    full, half = 1 << bits, 1 << (bits - 1)
    d = (np.diff(c) + half) % full - half
    return np.concatenate([[c[0]], c[0] + np.cumsum(d)])


def _encoders_from_ticks(bag, left: tuple, right: tuple, notes: list) -> Encoders:
    """Encoders from two counters ((t, count, bits) each), on the rows of the
    sparser one. Counters published together (each message of one within a
    quarter period of one of the other) pair exactly, stamped at the pair's
    mean time. Otherwise the denser counter's cumulative count is
    interpolated to the sparser one's times and rounded to whole ticks (at
    most half a tick of quantisation per row), and a note says so: pairing
    readings up to half a period apart would give each wheel a different
    interval, and a wrong calibration."""
    tl, cl, bl = left
    tr, cr, br = right
    if len(tl) < 3 or len(tr) < 3:
        raise LogFormatError(bag, "tick topics: fewer than three messages on a wheel")
    cl, cr = _unwrap_counts(cl, bl, notes, "left ticks"), _unwrap_counts(cr, br, notes, "right ticks")
    swap = len(tr) < len(tl)           # rows on the sparser counter
    (ta, ca), (tb, cb) = ((tr, cr), (tl, cl)) if swap else ((tl, cl), (tr, cr))
    quarter = 0.25 * float(min(np.median(np.diff(ta)), np.median(np.diff(tb))))
    j = np.clip(np.searchsorted(tb, ta), 1, len(tb) - 1)
    j = np.where(np.abs(tb[j - 1] - ta) <= np.abs(tb[j] - ta), j - 1, j)
    ok = (np.abs(tb[j] - ta) <= quarter) & np.concatenate([[True], np.diff(j) > 0])
    if ok.mean() >= 0.95 and len(tb) <= 1.05 * len(ta):
        if (~ok).any():
            notes.append(f"tick topics: {int((~ok).sum())} messages without a partner at the same time dropped")
        t, a, b = 0.5 * (ta[ok] + tb[j[ok]]), ca[ok], cb[j[ok]]
    else:
        inside = (ta >= tb[0]) & (ta <= tb[-1])
        t, a = ta[inside], ca[inside]
        b = np.rint(np.interp(t, tb, cb.astype(float))).astype(np.int64)
        notes.append(f"tick topics at different rates or times ({len(tl)} left, {len(tr)} right messages): rows at "
                     f"the {'right' if swap else 'left'} counter's times, the other's count interpolated")
    if len(t) < 3:
        raise LogFormatError(bag, "tick topics: the two counters do not overlap in time")
    left_c, right_c = (b, a) if swap else (a, b)
    return Encoders(t, np.concatenate([[0], np.diff(left_c)]).astype(float),
                    np.concatenate([[0], np.diff(right_c)]).astype(float))


def _pick(cands: dict[str, list]) -> dict[str, str | None]:
    """{role: topic or None}: the one candidate of each role, or None when
    there is none or the choice is ambiguous. Wheel odometry is preferred to
    topics whose names say they are fused, JointState to odometry, and a
    velocity command (_is_command) is never the wheels."""
    picks = {}
    for role, cs in cands.items():
        cs = list(cs)
        if role == "wheels":
            cs = [c for c in cs if not _not_wheels(c.topic) and not _is_command(c.topic)]
            joints = [c for c in cs if WHEEL_TYPES[c.msgtype] == "joints"]
            cs = joints if len(joints) == 1 else cs
        topics = sorted({c.topic for c in cs})
        picks[role] = topics[0] if len(topics) == 1 else None
    return picks


def _options_apply(bag, kind: str, wheels, types: dict, ticks_per_meter, wheel_radius, left_joint,
                   right_joint) -> None:
    """Refuse an option given for other wheels than the ones picked
    (``wheels``: a topic, or the (left, right) tick counters; ``kind``:
    joints, odometry, twist or ticks): ignored, it would be recorded in
    import.json as used (a probe: --ticks-per-meter 2000 and --left-joint
    foo beside TwistStamped wheels, exit 0, the wrong wheels unseen)."""
    picked = (f"the tick counters {list(wheels)}" if kind == "ticks"
              else f"{wheels} ({types[wheels].split('/')[-1]})")
    for name, value, wants in (("--ticks-per-meter", ticks_per_meter, "ticks"),
                               ("--wheel-radius", wheel_radius, "joints"), ("--left-joint", left_joint, "joints"),
                               ("--right-joint", right_joint, "joints")):
        if value is not None and kind != wants:
            raise LogFormatError(bag, f"{name} is for {'tick counters' if wants == 'ticks' else 'JointState wheels'}, "
                                      f"but the wheels picked are {picked}: leave it out, or name the wheels it is for "
                                      f"({'--tick-topics LEFT,RIGHT' if wants == 'ticks' else '--wheel-topic'})")


def list_topics(bag: Path | str) -> tuple[list[Topic], list[str]]:
    """(every topic with its type, count, rate and the role it would be picked
    for; the static transforms found, one "parent -> child (x, y, z)" line each)."""
    bag = Path(bag)
    try:
        with _reader(bag) as reader:
            conns = list(reader.connections)
            cands = _candidates(conns)
            picks = _pick(cands)
            pair = _tick_pair(conns) if not _measured_wheels(cands) else None
            if pair:
                picks["wheels (left ticks)"], picks["wheels (right ticks)"] = pair
            span = max(reader.duration * 1e-9, 1e-9)
            by_topic: dict[str, list] = {}
            for c in conns:
                by_topic.setdefault(c.topic, []).append(c)
            topics = []
            for name, cs in sorted(by_topic.items()):
                n = sum(c.msgcount for c in cs)
                role = next((r for r, t in picks.items() if t == name), None)
                topics.append(Topic(name, cs[0].msgtype, n, n / span, role))
            frames = _static_frames(reader, conns)
    except LogFormatError:
        raise
    except Exception as exc:  # rosbags raises its own types for unreadable bags
        raise _unreadable(bag, exc) from None
    return topics, [f"{p} -> {c} ({x:+.3f}, {y:+.3f}, {z:+.3f}) m" for (p, c), ((x, y, z), _) in sorted(frames.items())]


def _static_frames(reader, conns) -> dict[tuple[str, str], tuple[tuple[float, float, float], np.ndarray]]:
    """{(parent, child): (translation [m], rotation (3, 3) child -> parent)} from /tf_static."""
    out = {}
    tf = [c for c in conns if c.msgtype == TF_TYPE and c.topic == "/tf_static"]
    if not tf:   # messages(connections=[]) would read every message
        return out
    for conn, _t, raw in reader.messages(connections=tf):
        for tr in reader.deserialize(raw, conn.msgtype).transforms:
            v, q = tr.transform.translation, tr.transform.rotation
            out[(tr.header.frame_id.lstrip("/"), tr.child_frame_id.lstrip("/"))] = (
                (v.x, v.y, v.z), _rotation(q.x, q.y, q.z, q.w))
    return out


def _rotation(x: float, y: float, z: float, w: float) -> np.ndarray:
    """(3, 3) rotation matrix of a unit quaternion (x, y, z, w), normalised first."""
    n = np.sqrt(x * x + y * y + z * z + w * w) or 1.0
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _wheel_joints(bag: Path, topic: str, names: list[str], left: str | None,
                  right: str | None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Each side's wheel joints: the given ones, or the names that look like
    wheels (left/right in them), as many on each side: a skid-steer base
    (Husky, Jackal, Warthog) publishes front_ and rear_ wheels, and a
    diff-drive controller takes each side's mean (_side_means)."""
    if left and right:
        if left not in names or right not in names:
            raise LogFormatError(bag, f"{topic}: joints {left!r}/{right!r} not in {names} "
                                      "(--left-joint/--right-joint)")
        return (left,), (right,)
    driven = [n for n in names if not any(w in n.lower() for w in NOT_DRIVEN)]
    wheels = [n for n in driven if "wheel" in n.lower()] or driven
    ls = [n for n in wheels if "left" in n.lower() and "right" not in n.lower()]
    rs = [n for n in wheels if "right" in n.lower() and "left" not in n.lower()]
    if left:
        ls = [left] if left in names else []
    if right:
        rs = [right] if right in names else []
    if len(ls) > 1 and any("steer" in n.lower() for n in names):
        # front wheels that steer roll on longer arcs than the rear ones: no differential drive's mean
        raise LogFormatError(bag, f"{topic}: steering joints beside wheels {ls + rs}: a car-like base is not a "
                                  "differential drive; give --left-joint and --right-joint (its rear wheels)")
    if ls and len(ls) == len(rs) <= MAX_WHEELS_PER_SIDE:
        return tuple(ls), tuple(rs)
    raise LogFormatError(bag, f"{topic}: cannot tell which joints are the left and right wheels among {names}; "
                              "give --left-joint and --right-joint")


#: Most wheel joints taken on one side (a six-wheeled rover's three).
MAX_WHEELS_PER_SIDE = 3
#: Words of joint names that are no driven wheel (a caster rolls where the
#: robot goes, a steering joint turns the wheel; a second read: a
#: left_caster_wheel_joint was averaged into the left side).
NOT_DRIVEN = ("caster", "castor", "swivel", "steer", "idler")


#: The joints taken as one side's wheels turn within this factor of each
#: other over the run (_same_turning): a motor's angle behind a gearbox, named
#: like its wheel, turns 10-50 times as far.
SIDE_AGREE = 1.25


def _same_turning(bag, topic: str, joints: tuple[str, ...], turned: np.ndarray) -> None:
    """Refuse a side's joints whose total turning ``turned`` (k,) [rad] (or
    summed |rate|) differ by more than SIDE_AGREE: they are not wheels on
    one side of a skid-steer base, and their mean would be no wheel's."""
    if len(joints) < 2 or not np.all(np.isfinite(turned)) or turned.max() == 0.0:
        return
    if turned.min() * SIDE_AGREE < turned.max():
        ratio = ", ".join(f"{j} {x / turned.max():.2g}" for j, x in zip(joints, turned))
        raise LogFormatError(bag, f"{topic}: the joints {list(joints)} look like one side's wheels but turn "
                                  f"unlike one another over the run ({ratio} of the most): give --left-joint and "
                                  "--right-joint")


def _side_means(bag, rows: list, sides: tuple[tuple[str, ...], tuple[str, ...]], topic: str, notes: list) -> list:
    """Wheel rows (t, left position, right position, left velocity, right
    velocity) from rows holding each side's joints' values ((t, left
    positions (k,), right positions (k,), left velocities, right
    velocities), k joints a side, empty arrays where the message had none):
    each side's mean, as a diff-drive controller takes it for several wheels
    a side. Positions are unwrapped joint by joint first (_unwrap_angle):
    the mean of two angles reported modulo 2 pi, one just past the wrap, is
    half a turn off."""
    if not rows:
        return []
    if all(len(side) == 1 for side in sides):
        return [(t, *(a[0] if a.size else np.nan for a in vals)) for t, *vals in rows]
    out = []
    cols = []
    for c, side in enumerate(("left", "right")):
        pos = [r[1 + c] for r in rows]
        if all(p.size for p in pos):
            p = np.array(pos)
            p = np.stack([_unwrap_angle(p[:, j], topic, f"{side} ({sides[c][j]})", notes)
                          for j in range(p.shape[1])], axis=1)
            _same_turning(bag, topic, sides[c], np.abs(np.diff(p, axis=0)).sum(axis=0))
            cols.append(p.mean(axis=1))
        else:
            cols.append(np.full(len(rows), np.nan))
    for c in (0, 1):
        vel = [r[3 + c] for r in rows]
        if all(v.size for v in vel):
            v = np.array(vel)
            if np.isnan(cols[c]).all():     # the velocities are the wheels (_wheel_speeds)
                _same_turning(bag, topic, sides[c], np.abs(v).sum(axis=0))
            cols.append(v.mean(axis=1))
        else:
            cols.append(np.full(len(rows), np.nan))
    notes.append(f"{topic}: {len(sides[0])} wheel joints a side ({', '.join(sides[0])} | {', '.join(sides[1])}): "
                 "each side is their mean, as a diff-drive controller takes it")
    for k, r in enumerate(rows):
        out.append((r[0], *(float(col[k]) for col in cols)))
    return out


def _publisher(msg: tuple) -> tuple:
    """What tells two JointState publishers on one topic apart: the names,
    and whether positions and velocities are filled."""
    _, names, pos, vel = msg
    return names, pos.size == len(names), vel.size == len(names)


def _frozen_publishers(msgs: list, joints: tuple[str, ...]) -> set[tuple]:
    """The publishers (_publisher) whose messages hold every wheel joint at
    one value all along, when another publisher's move them: a
    joint_state_publisher beside the wheel driver sends every joint at its
    default (0), and interleaved with the driver's those rows read as
    wheels jumping to 0 and back (a probe: batch 1.76 at z +26, blaming an
    encoder counting backwards; or a refusal naming a 1003 m/s wheel)."""
    values: dict[tuple, list] = {}
    for m in msgs:
        _, names, pos, vel = m
        if all(j in names for j in joints):
            idx = [names.index(j) for j in joints]
            # positions and velocities, where filled: a driver may fill positions with zeros
            values.setdefault(_publisher(m), []).append(np.concatenate(
                [a[idx] if a.size == len(names) else np.zeros(len(idx)) for a in (pos, vel)]))
    if len(values) < 2:
        return set()
    still = {k for k, v in values.items() if not np.any(np.ptp(np.array(v), axis=0) > 0.0)}
    return still if len(still) < len(values) else set()


def _joint_rows(bag, topic: str, msgs: list, left: str | None, right: str | None, notes: list,
                not_finite: dict) -> list[tuple]:
    """Wheel rows (t, left position, right position, left velocity, right
    velocity; NaN where a message has none) from a JointState topic's
    messages ((t, names, positions, velocities) each). The wheel joints are
    the given ones, or the left/right sides found in the most messages,
    joints named "wheel" first: a mobile manipulator's gripper publishing on
    the same topic may come first; several a side are averaged (_side_means).
    Joints are looked up by name in every message (a driver may reorder
    them); messages without them (another publisher's) are skipped and
    counted."""
    if not msgs:
        raise LogFormatError(bag, f"{topic}: no JointState message")
    counts: dict[tuple, int] = {}
    for _, names, _, _ in msgs:
        counts[names] = counts.get(names, 0) + 1
    if left and right:
        sides = ((left,), (right,))
        if not any(left in n and right in n for n in counts):
            raise LogFormatError(bag, f"{topic}: joints {left!r}/{right!r} not in "
                                      f"{sorted({j for n in counts for j in n})} (--left-joint/--right-joint)")
    else:
        held = sorted({j for n in counts for j in n})
        for option, joint in (("--left-joint", left), ("--right-joint", right)):
            if joint and joint not in held:
                raise LogFormatError(bag, f"{topic}: {option} {joint!r} is not a joint it holds (its joints: {held})")
        pairs, error = {}, None
        for names in counts:
            try:
                pair = _wheel_joints(bag, topic, list(names), left, right)
            except LogFormatError as exc:
                error = exc
                continue
            pairs[pair] = sum(c for n, c in counts.items() if all(j in n for j in pair[0] + pair[1]))
        if not pairs:
            raise error
        # joints named "wheel" first; then every wheel a side over a pair that more messages hold (a
        # probe: rear wheels missing from 10 % of the messages made the front pair win, without a word)
        most = max(pairs.values())
        sides = max(pairs, key=lambda pr: (all("wheel" in j.lower() for j in pr[0] + pr[1]),
                                           pairs[pr] >= 0.5 * most, len(pr[0]), pairs[pr]))
    joints = sides[0] + sides[1]
    rows, other = [], 0
    frozen = _frozen_publishers(msgs, joints)
    if frozen:
        n = sum(1 for m in msgs if _publisher(m) in frozen)
        notes.append(f"{topic}: {n} messages from another publisher (its names {list(next(iter(frozen))[0])}) that "
                     f"hold the wheel joints at a constant value (joint_state_publisher's defaults?) skipped")
    empty = np.zeros(0)
    for m in msgs:
        stamp, names, pos, vel = m
        if frozen and _publisher(m) in frozen:
            continue
        if not all(j in names for j in joints):
            other += 1
            continue
        il, ir = [names.index(j) for j in sides[0]], [names.index(j) for j in sides[1]]
        # arrays of another length than the names carry nothing for these joints
        pos = pos if pos.size == len(names) else empty
        vel = vel if vel.size == len(names) else empty
        used = pos[il + ir] if pos.size else (vel[il + ir] if vel.size else np.zeros(2))
        if not np.all(np.isfinite(used)):
            not_finite[topic] = not_finite.get(topic, 0) + 1
            continue
        rows.append((stamp, *(pos[ix] if pos.size else empty for ix in (il, ir)),
                     *(vel[ix] if vel.size else empty for ix in (il, ir))))
    if other:
        notes.append(f"{topic}: {other} messages without the wheel joints {list(joints)} skipped (another publisher "
                     "on the topic, or messages that leave some of the joints out)")
    return _side_means(bag, rows, sides, topic, notes)


def import_rosbag(bag: Path | str, wheel_topic: str | None = None, left_joint: str | None = None,
                  right_joint: str | None = None, wheel_radius: float | None = None, track_width: float | None = None,
                  gps_topic: str | None = None, imu_topic: str | None = None, gyro_sigma: float = 0.01,
                  encoder_sigma=(0.005, 0.01), gps_lever_arm=None, imu_axis: str = "auto",
                  stamps: str = "header", tick_topics: tuple[str, str] | None = None,
                  ticks_per_meter: float | tuple[float, float] | None = None) -> Log:
    """Import wheels (and GPS and gyro when the bag has them) from a bag; see the module doc.

    Topics left None are picked by type when unambiguous ("" turns a sensor
    off). ``wheel_radius`` [m] is needed for JointState wheels only;
    ``track_width`` [m] always. ``gps_lever_arm`` (robot frame [m]) is not in
    NavSatFix: by default it is taken from /tf_static (base_link to the fix's
    frame) when there, else (0, 0) with a note. ``imu_axis``: "auto", or one
    of x, y, z, -x, -y, -z; "auto" takes the robot's vertical axis from
    /tf_static (base_link -> the IMU's frame) when it is there, else the
    axis the data show. ``stamps``: "header" (the sensors' clock) or
    "receive" (the time the bag recorded each message). ``tick_topics``:
    (left, right) std_msgs integer tick counters, picked by name ("left",
    "right") when the bag has no other topic that may be the wheels'
    measurement, or ``ticks_per_meter`` is given (_auto_ticks); they need
    ``ticks_per_meter`` (one value or (left, right)) and, having no header,
    are stamped with the bag's receive times, moved onto the header clock
    when the two differ (_header_clocks). Options for other wheels than the
    ones picked are refused (_options_apply); a velocity command is taken
    only when named, with a warning."""
    bag = Path(bag)
    if track_width is None or not (np.isfinite(track_width) and track_width > 0):
        raise LogFormatError(bag, f"import rosbag needs a positive, finite --track-width (the nominal robot) [m], "
                                  f"got {track_width}")
    if wheel_radius is not None and not (np.isfinite(wheel_radius) and wheel_radius > 0):
        raise LogFormatError(bag, f"--wheel-radius must be a positive, finite number [m], got {wheel_radius}")
    if stamps not in ("header", "receive"):
        raise LogFormatError(bag, f"--stamps must be header or receive, got {stamps!r}")
    if imu_axis not in ("auto", *AXES, *(f"-{a}" for a in AXES)):
        raise LogFormatError(bag, f"--imu-axis must be auto, x, y, z, -x, -y or -z, got {imu_axis!r}")
    notes, warnings = [f"imported from bag {bag.name}"], []
    wheels, fixes, rates = [], [], []
    kind = None
    fix_frame, imu_frame, no_fix, null_island, no_rate = None, None, 0, 0, 0
    # messages whose numbers are NaN or infinite (a receiver's "no value"), dropped and counted per topic
    not_finite: dict[str, int] = {}
    try:
        with _reader(bag) as reader:
            conns = list(reader.connections)
            present = {c.topic for c in conns}
            missing = {t for t in (wheel_topic, gps_topic, imu_topic, *(tick_topics or ())) if t} - present
            if missing:
                raise LogFormatError(bag, f"topic(s) {sorted(missing)} not in the bag (it has {sorted(present)}; "
                                          "odomgraph import rosbag BAG --list shows them)")
            cands = _candidates(conns)
            picks = _pick(cands)
            if tick_topics is None and wheel_topic is None:
                tick_topics = _auto_ticks(bag, conns, cands, ticks_per_meter is not None, notes)
            commands = _commands(conns)
            if tick_topics:
                wheel_topic = ""      # the counters are the wheels
            chosen = {}
            for role, given in (("wheels", wheel_topic), ("imu", imu_topic), ("gps", gps_topic)):
                if given is None:
                    given = picks[role]
                    if given is None and cands[role] and role == "wheels":
                        others = sorted({c.topic for c in cands[role]} - set(commands))
                        if not others:
                            raise LogFormatError(bag, f"the bag's only wheel topics are velocity commands {commands}: "
                                                      "a command is what was asked of the wheels, not what they did, "
                                                      "and calibrates nothing; give --wheel-topic to take one anyway")
                        pair = _tick_pair(conns)
                        raise LogFormatError(bag, f"no topic is clearly the wheels' own odometry among {others}"
                                                  + (f" (velocity commands {commands} are no wheels)" if commands
                                                     else "") + ": give --wheel-topic"
                                                  + (f" (or --ticks-per-meter for the tick counters {list(pair)})"
                                                     if pair else ""))
                    if given is None and len({c.topic for c in cands[role]}) > 1:
                        raise LogFormatError(bag, f"several {role} topics ({sorted({c.topic for c in cands[role]})}): "
                                                  f"give --{role}-topic (or --{role}-topic '' for none)")
                    if given:
                        notes.append(f"{role}: picked {given}")
                chosen[role] = given or None
            types = {c.topic: c.msgtype for c in conns}
            if tick_topics:
                kind = "ticks"
                bad = [t for t in tick_topics if types[t] not in TICK_TYPES]
                if bad:
                    raise LogFormatError(bag, f"{bad[0]}: a {types[bad[0]]} is not a std_msgs integer tick counter")
                tpm = (ticks_per_meter,) * 2 if isinstance(ticks_per_meter, (int, float)) else ticks_per_meter
                if tpm is None or len(tpm) != 2 or not all(v and v > 0 for v in tpm):
                    raise LogFormatError(bag, f"the tick counters {list(tick_topics)} need a positive "
                                              "--ticks-per-meter (nominal, one value or left,right)")
                notes.append("tick counters carry no header: stamped with the bag's receive times")
            elif chosen["wheels"] is None:
                raise LogFormatError(bag, "no wheel topic (sensor_msgs/JointState, nav_msgs/Odometry, "
                                          "geometry_msgs/TwistStamped or left/right std_msgs tick counters) in "
                                          "the bag" + (f"; {commands}: velocity commands, not wheel measurements"
                                                       if commands else "") + "; --list shows what it has")
            elif types[chosen["wheels"]] not in WHEEL_TYPES:
                raise LogFormatError(bag, f"{chosen['wheels']}: a {types[chosen['wheels']]} cannot be wheels")
            else:
                kind = WHEEL_TYPES[types[chosen["wheels"]]]
            for role, want in (("imu", IMU_TYPE), ("gps", GPS_TYPE)):
                if chosen[role] and types[chosen[role]] != want:
                    raise LogFormatError(bag, f"{chosen[role]}: a {types[chosen[role]]}, not a {want}")
            if kind == "joints" and (wheel_radius is None or wheel_radius <= 0):
                raise LogFormatError(bag, f"{chosen['wheels']} holds JointState wheels: give a positive "
                                          "--wheel-radius [m]")
            _options_apply(bag, kind, chosen["wheels"] or tick_topics, types, ticks_per_meter, wheel_radius,
                           left_joint, right_joint)
            if kind != "ticks" and wheel_topic and _is_command(wheel_topic):
                warnings.append(f"{wheel_topic}: its name says a velocity command, not a wheel measurement: taken "
                                "as the wheels (--wheel-topic), it holds what was asked of them, not their slip, "
                                "lag or scale, and a calibration from it calibrates the command")
            use = [c for c in conns if c.topic in chosen.values() or c.topic in (tick_topics or ())]
            ticks = {t: [] for t in tick_topics or ()}
            joint_msgs = []
            # the first stamp read [ns] and its topic: the log's origin (below); each header
            # topic's (receive, header) stamps [ns], for _header_clocks
            first, clocks = None, {}
            for conn, t_rx, raw in reader.messages(connections=use):
                msg = reader.deserialize(raw, conn.msgtype)
                ns = int(t_rx) if stamps == "receive" or conn.topic in ticks else _stamp_ns(msg)
                if ns == 0:
                    # a driver's unset header (a probe: two such wheel messages made the log span
                    # 27 years); _drop_unset decides once the topic is read
                    stamp = UNSET
                else:
                    # integer nanoseconds until every topic is read: the tick counters' receive
                    # times may move onto the header clock (_header_clocks), then the origin is set
                    stamp = ns
                    first = first or (conn.topic, ns)
                    if stamps == "header" and conn.topic not in ticks:
                        clocks.setdefault(conn.topic, []).append((int(t_rx), ns))
                if conn.topic == chosen["wheels"]:
                    if kind == "joints":
                        # the joints are chosen once the topic is read (_joint_rows): another
                        # publisher's message may come first
                        joint_msgs.append((stamp, tuple(msg.name), np.asarray(msg.position, float),
                                           np.asarray(msg.velocity, float)))
                    else:
                        tw = msg.twist.twist if kind == "odometry" else msg.twist
                        if not (np.isfinite(tw.linear.x) and np.isfinite(tw.angular.z)):
                            not_finite[conn.topic] = not_finite.get(conn.topic, 0) + 1
                            continue
                        # Odometry's pose too (x, y, yaw): a driver may fill only the pose, or
                        # put the twist in the odom frame (_body_twist)
                        pose = ((msg.pose.pose.position.x, msg.pose.pose.position.y,
                                 _yaw(msg.pose.pose.orientation)) if kind == "odometry" else (np.nan,) * 3)
                        wheels.append((stamp, tw.linear.x, tw.angular.z, np.nan, np.nan,
                                       tw.linear.y if np.isfinite(tw.linear.y) else 0.0, *pose))
                elif conn.topic in ticks:
                    ticks[conn.topic].append((stamp, int(msg.data)))
                elif conn.topic == chosen["gps"]:
                    fix_frame = msg.header.frame_id.lstrip("/")
                    if msg.status.status < 0:
                        no_fix += 1
                        continue
                    if not (np.isfinite(msg.latitude) and np.isfinite(msg.longitude)):
                        not_finite[conn.topic] = not_finite.get(conn.topic, 0) + 1
                        continue
                    if msg.latitude == 0.0 and msg.longitude == 0.0:
                        null_island += 1      # a receiver's placeholder before its first fix
                        continue
                    cov = np.asarray(msg.position_covariance, float)
                    sig = float(np.sqrt(0.5 * (cov[0] + cov[4]))) if msg.position_covariance_type > 0 else np.nan
                    fixes.append((stamp, msg.latitude, msg.longitude, sig))
                else:
                    imu_frame = msg.header.frame_id.lstrip("/")
                    if msg.angular_velocity_covariance[0] == -1.0:
                        no_rate += 1          # REP 145: this IMU does not measure angular velocity
                        continue
                    a = msg.angular_velocity
                    if not (np.isfinite(a.x) and np.isfinite(a.y) and np.isfinite(a.z)):
                        not_finite[conn.topic] = not_finite.get(conn.topic, 0) + 1
                        continue
                    rates.append((stamp, a.x, a.y, a.z))
            frames = _static_frames(reader, conns)
            span_s = reader.duration * 1e-9
            msg_counts = {c.topic: 0 for c in conns}
            for c in conns:
                msg_counts[c.topic] += c.msgcount
    except LogFormatError:
        raise
    except Exception as exc:  # rosbags raises its own types for unreadable bags
        raise _unreadable(bag, exc) from None
    roles = {t: r for r, t in chosen.items() if t}
    shift = _header_clocks(bag, {t: np.array(v, dtype=np.int64) for t, v in clocks.items()}, roles,
                           list(ticks), span_s, warnings)
    if shift:
        ticks = {t: [(r[0] - shift, *r[1:]) for r in rows] for t, rows in ticks.items()}
        if first and first[0] in ticks:
            first = (first[0], first[1] - shift)
    origin_ns = None
    if first:
        # A real clock counts from the first whole second (Log.t_origin): the difference of
        # integer nanoseconds is exact, and so is every interval.
        whole = first[1] // 1_000_000_000
        origin_ns = whole * 1_000_000_000 if whole >= ORIGIN_ABOVE else 0
    wheels, joint_msgs, fixes, rates = (_seconds(rows, origin_ns) for rows in (wheels, joint_msgs, fixes, rates))
    ticks = {t: _seconds(rows, origin_ns) for t, rows in ticks.items()}
    for topic, rows in ((chosen["wheels"], joint_msgs if kind == "joints" else wheels), (chosen["gps"], fixes),
                        (chosen["imu"], rates)):
        _drop_unset(topic, rows, bool(origin_ns), notes,
                    _publisher if kind == "joints" and topic == chosen["wheels"] else None)
    if kind == "joints":
        wheels = _joint_rows(bag, chosen["wheels"], joint_msgs, left_joint, right_joint, notes, not_finite)
    if stamps != "receive":
        # the wheels' own rows (another JointState publisher's stamps are its own)
        for topic, rows in ((chosen["wheels"], wheels), (chosen["gps"], fixes), (chosen["imu"], rates)):
            _steps_back(bag, topic, rows, topic == chosen["wheels"], warnings)
    if null_island:
        notes.append(f"{chosen['gps']}: {null_island} fixes at latitude 0, longitude 0 (a receiver's placeholder "
                     "before its first fix) dropped")
    if no_rate:
        line = (f"{chosen['imu']}: {no_rate} messages without angular velocity (angular_velocity_covariance[0] = -1, "
                "REP 145) dropped")
        (notes if rates else warnings).append(line + ("" if rates else ": the IMU gives no yaw rate, so no gyro"))
    enc = None
    if kind == "ticks":
        sides = []
        for topic in tick_topics:
            rows = sorted(ticks[topic])
            sides.append((np.array([r[0] for r in rows]), np.array([r[1] for r in rows], dtype=np.int64),
                          TICK_TYPES[types[topic]]))
        enc = _encoders_from_ticks(bag, sides[0], sides[1], notes)
        dt = np.diff(enc.t)
        # the wheels' speeds, for the IMU axis check below
        ws = WheelSpeeds(enc.t[1:], enc.ticks_left[1:] / (tpm[0] * dt), enc.ticks_right[1:] / (tpm[1] * dt))
    else:
        ws = _wheel_speeds(bag, chosen["wheels"], kind, wheels, wheel_radius, track_width, notes, warnings)
    if not (np.any(ws.v_left) or np.any(ws.v_right)):
        # a driver that fills nothing (a probe: twist and pose all zero beside a GPS that moved 50 m)
        warnings.append(f"{chosen['wheels'] or 'the tick counters'}: the wheels never move in its {len(ws.t)} rows: "
                        "every estimate reads a robot standing still (a driver that fills nothing?)")
    if kind not in ("joints", "ticks"):
        notes.append(f"wheels from the {'odometry twist' if kind == 'odometry' else 'TwistStamped'} of "
                     f"{chosen['wheels']} through the nominal track "
                     f"({track_width:g} m): this assumes that odometry came from the wheels alone, and that "
                     f"{track_width:g} m is the wheel_separation its controller used (the calibrated track is "
                     "relative to it)")
    gps, origin, gps_sigma = None, None, 0.05
    if no_fix:
        notes.append(f"{chosen['gps']}: {no_fix} messages without a fix (status < 0) dropped")
    for topic, n in not_finite.items():
        notes.append(f"{topic}: {n} messages with a value that is not a finite number (NaN or inf) dropped")
    if fixes:
        f = np.array(fixes)
        tf, lat, lon, sig = _increasing(f[:, 0], f[:, 1], f[:, 2], f[:, 3])
        if _said_equal_stamps(chosen["gps"], len(f), len(tf), notes, warnings):
            fixes = []
    if fixes:
        origin = (float(lat[0]), float(lon[0]))
        x, y = latlon_to_local(lat, lon, *origin)
        known = np.isfinite(sig) & (sig > 0)
        if known.all():
            gps, gps_sigma = Gps(tf, x, y, sig), float(np.median(sig))
        elif known.any():
            # One fix's NaN covariance used to drop every fix's sigma (a probe: RTK fixes at 2 cm
            # taken at the 5 cm default, 637 of 1800 rejected). The others' median stands in.
            gps_sigma = float(np.median(sig[known]))
            # the largest known sigma, at least the default: a fix without one may come from a fallback mode
            fill = max(float(sig[known].max()), 0.05)
            gps = Gps(tf, x, y, np.where(known, sig, fill))
            notes.append(f"{chosen['gps']}: {int((~known).sum())} of {known.size} fixes carry no usable covariance "
                         f"(NaN, zero, or type unknown): they take sigma {fill:.3g} m (the largest of the others', "
                         "at least 0.05 m)")
        else:
            gps = Gps(tf, x, y)
            notes.append(f"{chosen['gps']}: no fix carries a usable covariance: sigma {gps_sigma:g} m assumed "
                         "(robot.toml [gps] sigma; the estimators' noise fit measures it)")
        if gps_lever_arm is None:
            gps_lever_arm = _lever_from_tf(frames, fix_frame, notes)
            if gps_lever_arm == (0.0, 0.0) and not any("lever arm (" in n for n in notes):
                warnings.append(f"{chosen['gps']}: the GPS antenna's lever arm is unknown (no /tf_static for frame "
                                f"{fix_frame!r}) and taken as (0, 0); an antenna off the robot's centre then looks "
                                "like a GPS time offset or a wrong track: give --gps-lever-arm X,Y")
    gyro = None
    if rates and not np.any(np.array(rates)[:, 1:]):
        warnings.append(f"{chosen['imu']}: every angular velocity is exactly zero (an IMU that does not measure it): "
                        "no gyro")
        rates = []
    if rates:
        g = np.array(rates)
        tg, wx, wy, wz = _increasing(g[:, 0], g[:, 1], g[:, 2], g[:, 3])
        if _said_equal_stamps(chosen["imu"], len(g), len(tg), notes, warnings):
            rates = []
    if rates:
        found = _in_base(frames, imu_frame) if imu_frame else None
        mount = found[2] if found is not None else None
        if imu_axis == "auto" and mount is not None:
            # The robot's yaw rate is the z row of the rotation into base_link.
            om = mount[2] @ np.stack([wx, wy, wz])
            notes.append(f"yaw from the IMU frame {imu_frame!r} through /tf_static (its vertical in the IMU frame: "
                         f"{np.round(mount[2], 3).tolist()})")
        else:
            om, line = _yaw_axis(imu_axis, ws, track_width, tg, {"x": wx, "y": wy, "z": wz}, chosen["imu"])
            if line:
                warnings.append(line)
        warnings.extend(_gyro_against_wheels(chosen["imu"], tg, om, ws, track_width,
                                             " -> ".join(found[0]) if imu_axis == "auto" and mount is not None
                                             else None))
        gyro = Gyro(tg, om)
    for role, want, sensor, got in (("imu", IMU_TYPE, "gyro", gyro), ("gps", GPS_TYPE, "GPS", gps)):
        warnings.extend(_said_missing(role, want, sensor, got is not None, chosen[role],
                                      imu_topic if role == "imu" else gps_topic, types, msg_counts, warnings,
                                      {"without a fix (status < 0)": no_fix, "at latitude 0, longitude 0": null_island,
                                       "not a finite number": not_finite.get(chosen["gps"], 0)} if role == "gps"
                                      else {"not a finite number": not_finite.get(chosen["imu"], 0)}))
    robot = RobotConfig(ticks_per_meter_left=float(tpm[0]) if enc is not None else 1.0,
                        ticks_per_meter_right=float(tpm[1]) if enc is not None else 1.0, track_width=track_width,
                        encoder_sigma=tuple(encoder_sigma), gps_sigma=gps_sigma, gps_origin=origin,
                        gps_lever_arm=tuple(float(v) for v in (gps_lever_arm or (0.0, 0.0))),
                        gyro_sigma=gyro_sigma)
    return Log(robot=robot, encoders=enc, wheel_speeds=None if enc is not None else ws, gps=gps, gyro=gyro,
               notes=tuple(notes), warnings=tuple(warnings),
               t_origin=(origin_ns or 0) // 1_000_000_000)


def _said_missing(role: str, msgtype: str, sensor: str, got: bool, topic: str | None, given: str | None,
                  types: dict, counts: dict, warnings: list, dropped: dict) -> list[str]:
    """A warning when a sensor the bag has gives nothing and no warning says
    why yet (a probe: an IMU topic without messages, named or found, and a
    GPS whose every fix was NO_FIX, each imported in silence): the topic
    picked or given holds no message, or none usable (``dropped``: {why:
    how many}), or the only topics of its type (``msgtype``) hold none."""
    if got or given == "":
        return []
    if topic is not None:
        if any(w.startswith(f"{topic}:") for w in warnings):
            return []
        if counts.get(topic, 0) == 0:
            return [f"{topic}: the {role.upper()} topic holds no messages: no {sensor}"]
        why = ", ".join(f"{n} {k}" for k, n in dropped.items() if n)
        return [f"{topic}: none of its {counts[topic]} messages is usable ({why or 'see the notes'}): no {sensor}"]
    empty = sorted(t for t, ty in types.items() if ty == msgtype and counts.get(t, 0) == 0)
    if not empty:
        return []
    return [f"{', '.join(empty)}: {'an' if role == 'imu' else 'a'} {role.upper()} topic without messages: no {sensor}"
            if len(empty) == 1 else f"{', '.join(empty)}: {role.upper()} topics without messages: no {sensor}"]


#: A gyro's yaw rate between these multiples of the wheels' turn rate (with a
#: clear correlation) is in degrees per second (57.3x) read as rad/s, give or
#: take the wheels' scale (a probe: 57x imported without a word) and a
#: skid-steer's scrub (its wheels turn up to 2-3x the robot: 57.3 / 2.2 = 26),
#: as analysis.mounting.DEGREES_RATIO, by which estimate refuses the log.
DEG_RATIO = (15.0, 90.0)
#: The correlation of a gyro's yaw rate with the wheels' turn rate that says
#: clearly which way it turns (a probe's IMU mounted against /tf_static: -0.80).
CLEAR_CORR = 0.5


def _gyro_against_wheels(topic: str, t: np.ndarray, om: np.ndarray, ws: WheelSpeeds, track: float,
                         tf_chain: str | None) -> list[str]:
    """Warnings when the gyro's yaw rate ``om`` (N,) at ``t`` (N,) [s]
    contradicts the wheels' turn rate (v_right - v_left) / track [rad/s]
    where both overlap and the run turns (MIN_TURN): about 57x of it (a gyro
    in deg/s, DEG_RATIO), or, when the yaw axis came from /tf_static
    (``tf_chain``: its frames), turning against it with a clear correlation
    (CLEAR_CORR: the mounting in /tf_static is the other way up)."""
    w = np.interp(t, ws.t, (ws.v_right - ws.v_left) / track)
    inside = (t >= ws.t[0]) & (t <= ws.t[-1])
    if inside.sum() < 30 or np.std(w[inside]) < MIN_TURN or np.std(om[inside]) == 0:
        return []
    w, o = w[inside], om[inside]
    corr = float(np.corrcoef(o, w)[0, 1])
    # the gyro's rate in multiples of the wheels', where they turn (2 MIN_TURN): the median, which
    # a wheel slipping does not move (a probe's: least squares read 32x for a gyro in deg/s)
    turning = np.abs(w) >= 2.0 * MIN_TURN
    ratio = float(np.median(o[turning] / w[turning])) if turning.sum() >= 30 else 0.0
    out = []
    if tf_chain is not None and corr <= -CLEAR_CORR:
        out.append(f"{topic}: /tf_static's mounting of {tf_chain.split(' -> ')[-1]!r} ({tf_chain}) gives a yaw rate "
                   f"that turns against the wheels' (correlation {corr:+.2f}): the data say the IMU is mounted the "
                   "other way up; --imu-axis (z or -z) overrides /tf_static")
    if abs(corr) >= CLEAR_CORR and DEG_RATIO[0] <= abs(ratio) <= DEG_RATIO[1]:
        out.append(f"{topic}: its yaw rate reads {abs(ratio):.0f}x the wheels' turn rate (correlation "
                   f"{abs(corr):.2f}): an IMU in degrees per second (57.3x)? sensor_msgs/Imu is in rad/s")
    return out


def _said_equal_stamps(topic, n_in: int, n_out: int, notes: list, warnings: list | None = None) -> bool:
    """A note when messages shared a stamp with an earlier one (only the
    first of each stamp is kept): many such mean a coarse clock. True, with
    a warning, when every message had one stamp (a driver that never sets
    its header): the sensor is then left out."""
    if n_out < 2 <= n_in and warnings is not None:
        warnings.append(f"{topic}: all {n_in} messages carry the same header stamp: left out (--stamps receive "
                        "uses the bag's receive times)")
        return True
    if n_out < n_in:
        notes.append(f"{topic}: {n_in - n_out} of {n_in} messages repeat an earlier stamp and were dropped"
                     + ("; the header stamps look coarse: --stamps receive uses the bag's receive times"
                        if n_out < 0.9 * n_in else ""))
    return False


def _wheel_speeds(bag, topic, kind, rows, wheel_radius, track_width, notes, warnings) -> WheelSpeeds:
    if len(rows) < 2:
        raise LogFormatError(bag, f"{topic}: fewer than two wheel messages")
    j = np.array(rows)
    t, a, b, vl, vr = _increasing(j[:, 0], j[:, 1], j[:, 2], j[:, 3], j[:, 4])
    if len(t) < 2:
        raise LogFormatError(bag, f"{topic}: all {len(j)} wheel messages carry the same header stamp; "
                                  "--stamps receive uses the bag's receive times")
    _said_equal_stamps(topic, len(j), len(t), notes)
    if kind != "joints":
        _, vy, px, py, yaw = _increasing(j[:, 0], *(j[:, c] for c in range(5, 9)))
        t, v, om = _body_twist(topic, t, a, vy, b, px, py, yaw, track_width, notes, warnings)
        if t.size < 2:
            # (a pose-only driver whose pose updated once gives one row, which no estimator can use)
            raise LogFormatError(bag, f"{topic}: fewer than two wheel rows from its twist and pose "
                                      f"({len(j)} messages)")
        return WheelSpeeds(t, v - 0.5 * track_width * om, v + 0.5 * track_width * om)
    positions = bool(np.all(np.isfinite(a)) and np.all(np.isfinite(b)))
    velocities = bool(np.all(np.isfinite(vl)) and np.all(np.isfinite(vr)))
    if positions and velocities and np.ptp(a) == 0 and np.ptp(b) == 0 and (np.any(vl) or np.any(vr)):
        # positions that never change beside velocities that do: a placeholder, not a robot at rest
        notes.append(f"{topic}: the wheel positions never change while the velocities do: velocities used")
        return WheelSpeeds(t, vl * wheel_radius, vr * wheel_radius)
    if positions:
        # each interval's mean speed, stamped at its midpoint: an instant to second order (LOG_FORMAT)
        a, b = (_unwrap_angle(x, topic, side, notes) for x, side in ((a, "left"), (b, "right")))
        dt = np.diff(t)
        keep = ~_restarts(a, b)
        if not keep.all():
            at = ", ".join(f"{t[k]:.2f}-{t[k + 1]:.2f}" for k in np.flatnonzero(~keep)[:5])
            notes.append(f"{topic}: the wheel positions began again near 0 (a driver restart) {int((~keep).sum())} "
                         f"time(s), at t = {at} s: the interval across each is left out (the wheels' travel "
                         "over it is unknown)")
        return WheelSpeeds(0.5 * (t[1:] + t[:-1])[keep], (np.diff(a) * wheel_radius / dt)[keep],
                           (np.diff(b) * wheel_radius / dt)[keep])
    if velocities:
        return WheelSpeeds(t, vl * wheel_radius, vr * wheel_radius)
    raise LogFormatError(bag, f"{topic}: JointState has neither positions nor velocities for the wheels")


#: An Odometry pose whose wheels travel this far [m] (translation and
#: track / 2 x turning) while every twist is zero: a driver that fills only
#: the pose (_body_twist). The same travel (or POSE_TURN_RAD of turning)
#: while one part of every twist (linear or angular) is zero: a driver that
#: never fills that part.
POSE_ONLY_M = 0.5
POSE_TURN_RAD = 1.0
#: A run of zero twists among moving ones is a placeholder when the pose's
#: wheels travel across it, and its rows' median pace, are between this
#: share of what the twists either side say and its inverse (a robot that
#: really stopped hardly moves, and a fused pose's jitter moves far faster
#: than creeping twists say: a probe's 2 cm corrections at stops were read
#: as 1 m/s rows), and the travel at least POSE_STEP_M [m].
PLACEHOLDER_SHARE = 0.5
POSE_STEP_M = 2e-3
#: A pose step faster than this many times the 90th percentile of the
#: pose's moving speeds (above POSE_MOVING_V [m/s]), plus POSE_JUMP_V [m/s],
#: or turning faster than POSE_JUMP_W [rad/s] plus as many times its 90th
#: percentile, is a jump, a driver resetting its pose, and left out. The
#: 90th percentile leaves a reset out of its own reference in a short bag
#: (a second read: a 60-message bag's reset read as a -19.5 m/s row); a
#: stop's step is judged at the speed its row will carry (_PoseTrack.rows).
POSE_JUMP_TIMES = 5.0
POSE_JUMP_NEIGHBOURS = 1.5
POSE_JUMP_V = 0.5
POSE_JUMP_W = 10.0
POSE_MOVING_V = 0.01
#: Between two pose updates further apart than this many median update
#: periods the robot stood: its wheels' rows are 0 until the last period,
#: which holds the step (a pose-only driver at a stop).
POSE_STOP_PERIODS = 5.0
#: The baseline [s] over which a pose's steps are compared with its yaw
#: (a yaw that does not follow the motion; a pose's jitter averages out),
#: and the least sideways speed said [m/s] (a pivoting robot's chord over a
#: second is short and off its midpoint heading: 0.009 m/s, a probe's).
POSE_SIDE_BASELINE_S = 1.0
POSE_SIDE_MIN_V = 0.05
#: A twist whose lateral speed's rms is more than this share of its forward
#: one: not a differential drive's body-frame twist (REP 105: the twist is in
#: child_frame_id) (_body_twist).
LATERAL_SHARE = 0.2
#: The pose's heading that takes the lateral speed's rms below this share of
#: itself: a twist in the odom frame (_body_twist).
ODOM_FRAME_SHARE = 0.25
#: A lateral speed above this share of the forward one, with a pose that
#: does not move to tell the twist's frame, is said: an odom-frame twist
#: heading near the x axis is scaled by cos(heading) (a probe: 0.12 m/s rms
#: lateral, speeds 2 % short, scale factors z -9).
LATERAL_UNCHECKED_SHARE = 0.02


def _yaw(q) -> float:
    """The yaw [rad] of a geometry_msgs/Quaternion about z (ZYX Euler angles)."""
    return float(np.arctan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z)))


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x)))) if x.size else 0.0


class _PoseTrack:
    """An Odometry's pose as a function of time, from its updates: a driver
    may republish a pose faster than it updates it (a probe: 50 Hz messages,
    a new pose every 5th, read as speeds 0, 0, 0, 0, 5v), so only the
    messages whose pose differs from the one before count. Per interval
    between updates (K - 1,): ``dt`` [s], the body's forward speed ``fwd``
    [m/s] (the step's arc rotated into the body at the interval's mean
    heading), yaw rate ``om`` [rad/s] and ``jump`` (POSE_JUMP_TIMES: a
    driver resetting its pose)."""

    def __init__(self, t, x, y, yaw, track):
        same = (np.diff(x) == 0) & (np.diff(y) == 0) & (np.diff(yaw) == 0)
        u = np.concatenate([[0], np.flatnonzero(~same) + 1])
        self.t, self.x, self.y = t[u], x[u], y[u]
        self.yaw = np.unwrap(yaw[u])
        self.track = track
        dt = np.diff(self.t)
        dyaw = np.diff(self.yaw)
        mid_yaw = self.yaw[:-1] + 0.5 * dyaw
        dx, dy = np.diff(self.x), np.diff(self.y)
        self.dt = dt
        # the arc, not its chord: a step turning by dyaw is chord * (dyaw/2) / sin(dyaw/2) long at a
        # steady turn (a probe: 1 s gaps in a turning pose-only bag read short, track z -3.1)
        arc = 1.0 / np.sinc(dyaw / (2.0 * np.pi))
        self.fwd = arc * (np.cos(mid_yaw) * dx + np.sin(mid_yaw) * dy) / dt
        self.om = dyaw / dt
        self.period = float(np.median(dt)) if dt.size else 0.0
        self.stop = dt > POSE_STOP_PERIODS * self.period
        # A jump is judged over the one message interval it arrives in: a reset at the end of a
        # stop spread over the stop is a slow creep (a second read), and a late update or a gap in
        # the messages at its own interval's speed is no jump (a probe: both read as resets).
        # A republished pose's updates read its hold factor faster; so do its percentiles.
        t_before = t[np.maximum(u[1:] - 1, 0)]
        arrive = self.t[1:] - t_before
        speed, turn = np.hypot(dx, dy) / arrive, np.abs(dyaw) / arrive
        moving = speed > POSE_MOVING_V
        self.jump = np.zeros(dt.size, bool)
        if moving.any():
            # percentiles over moving intervals: a mostly idle bag's would be 0 (a probe: 93 of 110
            # driving rows of an 11 s drive after 25 min at rest taken for jumps)
            v90, w90 = np.percentile(speed[moving], 90), np.percentile(turn[moving], 90)
            sudden = ((speed > POSE_JUMP_TIMES * v90 + POSE_JUMP_V)
                      | (turn > POSE_JUMP_TIMES * w90 + POSE_JUMP_W))
            # ...and faster over its own update interval than the intervals either side: a pose held
            # while the robot drives, then caught up, is as fast as its neighbours (a probe: holds of
            # 6-60 messages taken for resets, z -4 to -5), a reset is not
            v_upd, w_upd = np.hypot(dx, dy) / dt, np.abs(dyaw) / dt
            pad = lambda a: np.maximum(np.concatenate([a[1:], [0.0]]), np.concatenate([[0.0], a[:-1]]))
            self.jump = sudden & ((v_upd > POSE_JUMP_NEIGHBOURS * pad(v_upd) + POSE_MOVING_V)
                                  | (w_upd > POSE_JUMP_NEIGHBOURS * pad(w_upd) + 10 * POSE_MOVING_V))
        # repeats between updates while moving (not at a stop, where a pose stays by itself), when
        # the pose updates slower than its messages come (not a stop's flicker of single ticks)
        msg_period = float(np.median(np.diff(t))) if t.size > 1 else 0.0
        self.held = (int((np.diff(u) - 1)[~self.stop].sum()) if self.period > 1.5 * msg_period else 0)
        # the messages: their times and the intervals between them (rows)
        self.t_msgs = t
        self.noise = self._noise()

    def _noise(self) -> float:
        """The pose's own noise [m of wheel travel]: the robust scale of its
        second differences over updates (sqrt(6) sigma for white noise; a
        wheel odometry's smooth pose, the motion's own changes, about 0)."""
        if self.t.size < 4:
            return 0.0
        d2 = [np.diff(c, 2) for c in (self.x, self.y, 0.5 * self.track * self.yaw)]
        return robust_sigma(np.sqrt(d2[0] ** 2 + d2[1] ** 2 + d2[2] ** 2)) / np.sqrt(6.0)

    def _has_jump(self, idx: np.ndarray) -> np.ndarray:
        """(len(idx) - 1,) True where the intervals between updates idx[i]
        and idx[i + 1] hold a jump."""
        c = np.concatenate([[0], np.cumsum(self.jump)])
        return (c[idx[1:]] - c[idx[:-1]]) > 0

    def _baseline(self) -> np.ndarray:
        """Every POSE_SIDE_BASELINE_S's update index (at least every one)."""
        k = max(1, int(round(POSE_SIDE_BASELINE_S / self.period))) if self.period > 0 else 1
        idx = np.arange(0, self.t.size, k)
        return idx if idx[-1] == self.t.size - 1 else np.append(idx, self.t.size - 1)

    def moved(self, t0: float = -np.inf, t1: float = np.inf) -> tuple[float, float]:
        """How far the pose's wheels travel [m] and how far it turns [rad]
        (between t0 and t1 [s]), over POSE_SIDE_BASELINE_S steps, each less
        three times its noise (a parked robot's jittery pose, summed update
        by update, travelled 57.7 m in a second read's minute), jumps left
        out."""
        idx = self._baseline()
        idx = idx[(self.t[idx] >= t0) & (self.t[idx] <= t1)]
        if idx.size < 2:
            return 0.0, 0.0
        bad = self._has_jump(idx)
        dp = np.hypot(np.diff(self.x[idx]), np.diff(self.y[idx]))
        dth = np.abs(np.diff(self.yaw[idx]))
        floor = 3.0 * np.sqrt(2.0) * self.noise
        dp, dth = np.maximum(dp - floor, 0.0)[~bad], np.maximum(dth - 2 * floor / self.track, 0.0)[~bad]
        return float(dp.sum() + 0.5 * self.track * dth.sum()), float(dth.sum())

    def interval(self, t: np.ndarray) -> np.ndarray:
        """(M,) index of the interval between updates that ends at or after
        each time t (the update that brings the motion at t); -1 outside."""
        i = np.searchsorted(self.t, t, side="left") - 1
        return np.where((i >= 0) & (i < self.dt.size) & (t > self.t[0]), i, -1)

    def rows(self):
        """Pose-only rows (times, forward, yaw rate): one per interval
        between messages, at its midpoint, carrying the mean over the pose
        update that holds it (the pose's own interval where it updates at
        every message: exact). One layout at the messages' rate, whether the
        pose updates at every message, is republished between late updates,
        or stands still (a probe: rows at irregular update midpoints beside
        100 Hz rows at stops put batch at z -21; a step squeezed into a
        stop's last period read 16 m/s). Jumps left out."""
        tm = self.t_msgs
        mid = 0.5 * (tm[1:] + tm[:-1])
        k = self.interval(tm[1:])
        ok = k >= 0
        ok[ok] = ~self.jump[k[ok]]
        return mid[ok], self.fwd[k[ok]], self.om[k[ok]]

    def sideways(self) -> tuple[float, float]:
        """The rms lateral and forward speeds [m/s] of the pose's steps over
        POSE_SIDE_BASELINE_S, against its own yaw (jitter averages out)."""
        idx = self._baseline()
        k = max(1, int(np.median(np.diff(idx)))) if idx.size > 1 else 1
        dx, dy, dyaw = np.diff(self.x[idx]), np.diff(self.y[idx]), np.diff(self.yaw[idx])
        h = self.yaw[idx][:-1] + 0.5 * dyaw
        dt = np.diff(self.t[idx])
        ok = dt < 2 * k * POSE_STOP_PERIODS * self.period if self.period > 0 else np.ones(dt.size, bool)
        # a reset's window is no step of the robot's (a probe: a false "sideways" at every reset)
        ok &= ~self._has_jump(idx)
        fwd = (np.cos(h) * dx + np.sin(h) * dy)[ok] / dt[ok]
        side = (-np.sin(h) * dx + np.cos(h) * dy)[ok] / dt[ok]
        return _rms(side), _rms(fwd)


def _zero_runs(zero: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of each run of True in ``zero``."""
    d = np.diff(np.concatenate([[0], zero.astype(int), [0]]))
    return list(zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1))


def _body_twist(topic, t, vx, vy, wz, px, py, yaw, track, notes, warnings):
    """The body's forward speed [m/s] and yaw rate [rad/s] rows (times,
    forward, yaw rate) from a twist (N,) stamped t (N,) [s]: as given when
    it is a body-frame twist (REP 105). An Odometry pose (px, py [m], yaw
    [rad]; NaN for TwistStamped) mends drivers' habits that imported as a
    robot standing still, or as speeds scaled by the cosine of the heading
    (a probe's bags, each a confident wrong calibration), going by the
    pose's updates (_PoseTrack):
      - every twist zero while the pose's wheels travel POSE_ONLY_M or more:
        the speeds are the pose's (_PoseTrack.rows);
      - a part of every twist zero (linear.x never filled, or angular.z)
        while the pose moves or turns: that part from the pose, at each
        message's stamp (the interval that brings its motion);
      - zero twists among real ones whose motion the pose, between its
        updates, holds beyond what the twists there say (PLACEHOLDER_SHARE
        of what their neighbours would have driven): those rows from the
        pose;
      - pose jumps (a driver resetting) left out;
      - a lateral speed that the pose's heading rotates away: a twist in
        the odom frame, rotated into the body (_frame_checked)."""
    fin = np.isfinite(px) & np.isfinite(py) & np.isfinite(yaw)
    if fin.sum() < max(2, 0.5 * fin.size):
        if fin.any():
            notes.append(f"{topic}: the pose is not a finite number in {int((~fin).sum())} of {fin.size} messages: "
                         "not used (its twist taken as it is)")
        return _frame_checked(topic, t, vx, vy, wz, None, notes, warnings)
    if not fin.all():
        notes.append(f"{topic}: {int((~fin).sum())} messages with a pose that is not a finite number: their pose "
                     "left out")
    pose = _PoseTrack(t[fin], px[fin], py[fin], yaw[fin], track)
    if pose.dt.size == 0:
        return _frame_checked(topic, t, vx, vy, wz, (px, py, yaw), notes, warnings, moves=False)
    zero = (vx == 0) & (vy == 0) & (wz == 0)
    moved, turned = pose.moved()
    jumps = (f"; {int(pose.jump.sum())} pose jump(s) (a driver resetting it?) left out" if pose.jump.any() else "")
    held = (f"; the speeds go by the pose's updates ({pose.held} messages repeat the pose before them)"
            if pose.held > 0.1 * t.size else "")
    if zero.all() and moved >= POSE_ONLY_M:
        notes.append(f"{topic}: every twist is zero while the pose's wheels travel {moved:.1f} m: the speeds are "
                     "the pose's differences (each interval's mean, at its midpoint)" + jumps + held)
        side, fwd = pose.sideways()
        if side > max(LATERAL_SHARE * fwd, POSE_SIDE_MIN_V):
            warnings.append(f"{topic}: the pose steps sideways to its own heading ({side:.2g} m/s rms beside a "
                            f"forward {fwd:.2g}, over {POSE_SIDE_BASELINE_S:g} s): its yaw does not follow the "
                            "motion, and the forward speeds taken from it are short")
        return pose.rows()
    k = pose.interval(t)
    ok = k >= 0
    kk = np.where(ok, k, 0)
    ok &= ~pose.jump[kk]
    vx, vy, wz = vx.copy(), vy.copy(), wz.copy()
    drop = np.zeros(t.size, bool)
    filled = np.zeros(t.size, bool)      # rows whose forward speed came from the pose: body frame already
    if not np.any(wz) and (np.any(vx) or np.any(vy)) and turned >= POSE_TURN_RAD:
        notes.append(f"{topic}: angular.z is zero in every message while the pose turns {turned:.1f} rad: "
                     "the yaw rate is the pose's (the interval that brings each message's motion)" + jumps + held)
        wz[ok] = pose.om[kk[ok]]
        drop |= ~ok
    elif not (np.any(vx) or np.any(vy)) and np.any(wz) and moved - 0.5 * track * turned >= POSE_ONLY_M:
        notes.append(f"{topic}: linear.x is zero in every message while the pose moves "
                     f"{moved - 0.5 * track * turned:.1f} m: the forward speed is the pose's (the interval that brings "
                     "each message's motion)" + jumps + held)
        vx[ok], vy[ok] = pose.fwd[kk[ok]], 0.0
        drop |= ~ok
        filled = ok.copy()
    else:
        placeholder = np.zeros(t.size, bool)
        # The twists' own travel, message by message (each the motion over the interval before it):
        # a run of zeros is a placeholder when the pose, between the updates around it, went further
        # than the twists there say, by about what the run's neighbours would have driven. A genuine
        # zero (a coarse encoder's), or one whose motion the next twist carries, leaves nothing
        # missing (probes: rebuilt genuine zeros, path 106-113 %, z +5; stale reads kept, z -21).
        step_said = np.concatenate([[0.0], (np.hypot(vx[1:], vy[1:]) + 0.5 * track * np.abs(wz[1:]))
                                    * np.diff(t)])
        said_cum = np.cumsum(step_said)
        changed = np.zeros(t.size, bool)
        changed[0] = True
        changed[1:] = ~((np.diff(px) == 0) & (np.diff(py) == 0) & (np.diff(yaw) == 0)) & fin[1:]
        updates = np.flatnonzero(changed & fin)
        runs = []
        for k0, k1 in _zero_runs(zero):
            nb = [j for j in (k0 - 1, k1 + 1) if 0 <= j < t.size and not zero[j]]
            if not nb:
                continue
            # the run's own intervals: message m's twist is the motion over (t[m-1], t[m]]. A
            # genuine zero's pose does not move over its interval; the next message's motion is
            # not the run's (a probe: every zero before a faster twist taken for a placeholder)
            s0 = max(k0 - 1, 0)
            # (the speed in whatever frame the twist is in: its length)
            speed = float(np.mean([np.hypot(vx[j], vy[j]) + 0.5 * track * abs(wz[j]) for j in nb]))
            run = np.arange(k0, k1 + 1)[ok[k0:k1 + 1]]
            pace = (float(np.median(np.abs(pose.fwd[kk[run]]) + 0.5 * track * np.abs(pose.om[kk[run]])))
                    if run.size else 0.0)
            # a long run (a driver warming up, or dropping out) is judged by the pose alone: one
            # neighbour's speed says little of seconds of driving (a probe: 10 s left zero, 16 % short)
            far = pose.moved(t[s0], t[k1])[0] >= POSE_ONLY_M
            runs.append((k0, k1, speed, pace, far))
        # Each zero's motion lies in the pose update that brings it, (ua, ub]; the zeros in one
        # update are judged together: what the pose went there beyond the twists is all of theirs
        # (a probe: 2-3 zeros in one held update, each judged against the whole, were kept: path
        # 95 %, z -19). An update whose own message has a zero twist is joined to the next: the
        # next twist may carry the zero's motion (a probe: such zeros filled and counted twice,
        # path 104 %, track z +8.4).
        breaks = np.union1d(updates[~zero[updates]], [t.size - 1])

        def update_of(m: int) -> tuple[int, int]:
            i = int(np.searchsorted(breaks, m, side="left"))
            return (int(breaks[i - 1]) if i >= 1 else 0), (int(breaks[i]) if i < breaks.size else t.size - 1)
        said_in: dict[tuple[int, int], float] = {}
        keys = {}
        for k0, k1, speed, _, _ in runs:
            for m in range(max(k0, 1), k1 + 1):
                keys[m] = update_of(m)
                said_in[keys[m]] = said_in.get(keys[m], 0.0) + speed * (t[m] - t[m - 1])
        near_in = {}
        for (ua, ub), total in said_in.items():
            went = (float(np.hypot(px[ub] - px[ua], py[ub] - py[ua])
                          + 0.5 * track * abs(wrap_angle(yaw[ub] - yaw[ua])))
                    if fin[ua] and fin[ub] else 0.0)
            missing = went - float(said_cum[ub] - said_cum[ua])
            # about what the neighbours say the zeros drove, give or take: a robot that stopped misses
            # nothing, and a fused pose's jitter (a probe's: 1 cm) beside creeping twists misses far
            # more than they say
            near_in[ua, ub] = max(POSE_STEP_M, PLACEHOLDER_SHARE * total) <= missing <= (
                total / PLACEHOLDER_SHARE + POSE_STEP_M)
        for k0, k1, speed, pace, far in runs:
            fast = PLACEHOLDER_SHARE * speed <= pace <= speed / PLACEHOLDER_SHARE
            for m in range(k0, k1 + 1):
                if far or (fast and m in keys and near_in[keys[m]]):
                    placeholder[m] = True
        if placeholder.any():
            use, out = placeholder & ok, placeholder & ~ok
            notes.append(f"{topic}: {int(placeholder.sum())} messages with a zero twist while the pose moved "
                         f"as the twists either side say: {int(use.sum())} of those rows from the pose (the interval "
                         "that brings each one's motion)" + (f", {int(out.sum())} left out (a pose jump, or no "
                                                            "pose update after them)" if out.any() else "") + held)
            vx[use], vy[use], wz[use] = pose.fwd[kk[use]], 0.0, pose.om[kk[use]]
            drop |= placeholder & ~ok
            filled = use
    keep = ~drop
    return _frame_checked(topic, t[keep], vx[keep], vy[keep], wz[keep], (px[keep], py[keep], yaw[keep]),
                          notes, warnings, moves=moved >= POSE_ONLY_M, fixed=filled[keep])


def _frame_checked(topic, t, vx, vy, wz, pose, notes, warnings, moves: bool = False, fixed=None):
    """_body_twist's frame check of twist rows: as given, or rotated into
    the body by the pose's yaw (``pose`` (px, py, yaw) (N,), NaN where a
    message had none, or None for a TwistStamped) when that takes its
    lateral speed away. ``moves``: the pose travels far enough to tell the
    frame; ``fixed`` (N,): rows already in the body (from the pose), left
    out of the test and never rotated."""
    fixed = np.zeros(t.size, bool) if fixed is None else fixed
    lateral, forward = _rms(vy[~fixed]), _rms(vx[~fixed])
    if lateral <= 1e-6 * max(forward, 1.0):
        return t, vx, wz
    if pose is not None and moves:
        fin = np.isfinite(pose[0]) & np.isfinite(pose[1]) & np.isfinite(pose[2])
        test = fin & ~fixed
        # tried whenever there is a lateral speed: an odom-frame twist heading near the x axis
        # has a small one, and taking its linear.x for the forward speed scales it by cos(yaw)
        c, s = np.cos(pose[2][test]), np.sin(pose[2][test])
        fwd, side = c * vx[test] + s * vy[test], -s * vx[test] + c * vy[test]
        if test.any() and _rms(side) <= ODOM_FRAME_SHARE * _rms(vy[test]):
            keep = fin | fixed
            out = vx.copy()
            out[test] = fwd
            notes.append(f"{topic}: the twist is in the odom frame (its lateral speed, {lateral:.2g} m/s rms, is "
                         "the heading's; REP 105 puts it in child_frame_id): rotated into the body by the pose's yaw"
                         + (f"; {int((~keep).sum())} rows without a pose to rotate by left out" if not keep.all()
                            else ""))
            return t[keep], out[keep], wz[keep]
    if lateral > LATERAL_SHARE * forward:
        warnings.append(f"{topic}: the twist has a lateral speed of {lateral:.2g} m/s rms beside a forward "
                        f"{forward:.2g} m/s: not a differential drive's body-frame twist (a skid or holonomic base, "
                        "or a twist in another frame); only its forward speed linear.x is used")
    elif pose is not None and not moves and lateral > LATERAL_UNCHECKED_SHARE * forward:
        warnings.append(f"{topic}: the twist has a lateral speed of {lateral:.2g} m/s rms ({lateral / forward:.0%} "
                        "of the forward) and the pose does not move, so the twist's frame cannot be checked: in the "
                        "odom frame its linear.x is the forward speed times cos(heading); only linear.x is used")
    return t, vx, wz


#: A driver restart (_restarts): both wheel positions land within this of 0 [rad]...
RESTART_NEAR = 1.0
#: ...after a step of at least this many turns on each wheel, towards 0...
RESTART_TURNS = 1.0
#: ...and this many times the wheel's median step between messages.
RESTART_STEPS = 20.0


def _restarts(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N - 1,) True for the intervals across which both wheel positions
    [rad] (N,) began again at 0: a driver restarted (a probe: a 3 s gap
    after which positions counted from 0 again was imported as one -9 m/s
    row, and the estimators blamed an encoder counting backwards). Both
    land within RESTART_NEAR of 0 from at least RESTART_TURNS turns away,
    a step RESTART_STEPS times the wheel's median one or more: a robot
    that drives back to where its wheels read 0 does so step by step."""
    out = np.ones(max(a.size - 1, 0), bool)
    for x in (a, b):
        d = np.diff(x)
        typical = float(np.median(np.abs(d))) if d.size else 0.0
        out &= ((np.abs(x[1:]) <= RESTART_NEAR) & (np.abs(x[:-1]) >= RESTART_NEAR + 2 * np.pi * RESTART_TURNS)
                & (np.abs(d) > RESTART_STEPS * typical))
    return out


def _unwrap_angle(x: np.ndarray, topic: str, side: str, notes: list) -> np.ndarray:
    """A wheel joint's position [rad], unwrapped when the driver reports it
    modulo 2 pi (every value within one turn, steps beyond half a turn: a
    wheel turning half a turn between two messages would be 10 m/s at
    20 Hz on a 0.15 m wheel)."""
    if x.size > 2 and np.abs(x).max() <= 2 * np.pi + 1e-6 and np.any(np.abs(np.diff(x)) > np.pi):
        notes.append(f"{topic}: the {side} wheel's position wraps at a full turn: unwrapped")
        return np.unwrap(x)
    return x


def _is_base(frame: str) -> bool:
    """base_link or base_footprint, with or without a namespace ("robot1/base_link")."""
    return frame.rsplit("/", 1)[-1] in BASE_FRAMES


def _in_base(frames, child: str) -> tuple[list[str], np.ndarray, np.ndarray] | None:
    """(the chain of frames from the robot's base frame down to ``child``,
    child's origin in it (3,) [m], rotation (3, 3) child -> base) from
    /tf_static's transforms (``frames``: _static_frames), composed along the
    chain: p_base = R1 (R2 p + t2) + t1. None when no chain reaches a base
    frame (a probe: base_link -> mast -> gps gave a lever arm of (0, 0) and
    "no /tf_static for frame 'gps'"; so did robot1/base_link -> robot1/gps)."""
    parent_of = {}
    for (p, c), tr in frames.items():
        parent_of.setdefault(c, (p, tr))
    chain, t, R = [child], np.zeros(3), np.eye(3)
    frame = child
    while not _is_base(frame):
        if frame not in parent_of or len(chain) > len(frames):
            return None               # no parent, or a loop
        frame, ((x, y, z), Rp) = parent_of[frame][0], parent_of[frame][1]
        t, R = Rp @ t + np.array([x, y, z]), Rp @ R
        chain.insert(0, frame)
    return (chain, t, R) if len(chain) > 1 else None


def _lever_from_tf(frames, fix_frame, notes) -> tuple[float, float]:
    """The antenna's (x, y) in base_link from /tf_static, or (0, 0) with a note."""
    found = _in_base(frames, fix_frame) if fix_frame else None
    if found is not None:
        chain, v, _ = found
        notes.append(f"GPS lever arm ({v[0]:+.3f}, {v[1]:+.3f}) m from /tf_static {' -> '.join(chain)}")
        return float(v[0]), float(v[1])
    notes.append("GPS lever arm not in /tf_static: taken as (0, 0); give --gps-lever-arm if the antenna is "
                 "off the robot's centre")
    return 0.0, 0.0


def _yaw_axis(axis: str, ws: WheelSpeeds, track: float, t: np.ndarray, rates: dict, topic: str):
    """(yaw rate (N,) [rad/s], warning or None): the requested axis, or with
    "auto" the signed axis that follows the wheels' turn rate best."""
    if axis != "auto":
        sign = -1.0 if axis.startswith("-") else 1.0
        return sign * rates[axis[-1]], None
    w = np.interp(t, ws.t, (ws.v_right - ws.v_left) / track)
    inside = (t >= ws.t[0]) & (t <= ws.t[-1])
    if inside.sum() < 30:
        return rates["z"], (f"{topic}: its stamps overlap the wheels' too little to tell the IMU's yaw axis from the "
                            "data (another clock?): z taken as mounted upright; give --imu-axis (or /tf_static)")
    if np.std(w[inside]) < MIN_TURN:
        # too little turning to tell the axis (or its sign) from the data
        return rates["z"], (f"{topic}: the run turns too little to tell the IMU's yaw axis from the data: z taken "
                            "as mounted upright; check the mounting, or give --imu-axis (or /tf_static)")
    corr = {a: (float(np.corrcoef(rates[a][inside], w[inside])[0, 1]) if np.std(rates[a][inside]) > 0 else 0.0)
            for a in AXES}
    best = max(AXES, key=lambda a: abs(corr[a]))
    if best == "z" and corr["z"] > 0:
        return rates["z"], None
    if abs(corr[best]) < 0.3 or (best != "z" and abs(corr[best]) < 2.0 * abs(corr["z"])):
        return rates["z"], (f"{topic}: no IMU axis follows the wheels' turn rate clearly (correlations "
                            + ", ".join(f"{a} {c:+.2f}" for a, c in corr.items()) + "): z taken; check the mounting")
    sign = 1.0 if corr[best] > 0 else -1.0
    name = ("" if sign > 0 else "-") + best
    return sign * rates[best], (f"{topic}: yaw taken from the IMU's {name} axis, which follows the wheels' turn rate "
                                f"(correlation {abs(corr[best]):.2f}; z {corr['z']:+.2f}): the IMU is mounted "
                                "turned; --imu-axis z keeps z")
