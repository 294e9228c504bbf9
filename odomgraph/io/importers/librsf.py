"""libRSF text datasets (TU Chemnitz; the Labyrinth UWB set is CC BY-SA 4.0).

Each line is one measurement, selected by its first word:

    range2    t range cov anchor_x anchor_y anchor_id snr
    odom2diff t v_a v_b v_y half_track cov_a cov_b cov_y   (readme: v_right v_left ... track)
    point2    t x y ...                                  (ground truth file)

Wheel speeds become wheel_speeds.csv (already in m/s: nominal ticks per metre
are set to 1), ranges become ranges.csv with the anchors as beacons, and
point2 lines become truth.csv.

Which wheel is which, and what "distance between wheels" means, are taken
from libRSF's own odometry factor (include/factors/OdometryFactor2DDifferential.h),
not from the dataset's readme: that factor predicts its first speed as
v - W*omega and its second as v + W*omega, and turns at
(second - first) / (2 W). With yaw counter-clockwise, v - W*omega is the
left wheel (LOG_FORMAT.md), whatever the readme calls it, and W is half the
track. The Labyrinth cut agrees: with the readme's labels the wheels turn
the robot the wrong way (heading change over 2-5 s against the truth's:
correlation -0.995, slope -0.48); read as the factor reads them, slope
+0.96 (tests/test_importers.py).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from odomgraph.errors import LogFormatError
from odomgraph.io.csvtable import read_text, shown, text_lines
from odomgraph.io.log import Log, Ranges, Truth, WheelSpeeds
from odomgraph.io.robot import Beacon, RobotConfig


def _lines(path: Path):
    for lineno, raw in text_lines(read_text(path)):
        parts = raw.split()
        if parts and not parts[0].startswith("#"):
            yield lineno, parts


def _floats(path, lineno, parts, n):
    if len(parts) < n + 1:
        raise LogFormatError(path, f"'{shown(parts[0])}' needs {n} values, found {len(parts) - 1}", lineno)
    try:
        vals = [float(v) for v in parts[1:n + 1]]
    except ValueError:
        raise LogFormatError(path, f"'{shown(parts[0])}' has a value that is not a number", lineno) from None
    if not np.all(np.isfinite(vals)):
        raise LogFormatError(path, f"'{shown(parts[0])}' has a non-finite value", lineno)
    return vals


def import_librsf(input_txt: Path | str, gt_txt: Path | str | None = None) -> Log:
    """Import a libRSF input file (and its ground truth, default: *_GT.txt beside it)."""
    input_txt = Path(input_txt)
    odo, rng, anchors = [], [], {}
    for lineno, parts in _lines(input_txt):
        kind = parts[0]
        if kind == "odom2diff":
            # first = v - W*omega (our left wheel), W = half the track: see the module docstring
            t, vl, vr, _vy, half_track, cl, cr = _floats(input_txt, lineno, parts, 7)
            if not (half_track > 0 and cr > 0 and cl > 0):
                raise LogFormatError(input_txt, "odom2diff needs a positive track width and variances", lineno)
            odo.append((t, vl, vr, 2.0 * half_track, cl, cr))
        elif kind == "range2":
            t, r, cov, ax, ay, aid = _floats(input_txt, lineno, parts, 6)
            if not (r >= 0 and cov > 0):
                raise LogFormatError(input_txt, "range2 needs a non-negative range and a positive variance", lineno)
            key = str(int(aid)) if aid == int(aid) else str(aid)
            if key in anchors and np.hypot(anchors[key][0] - ax, anchors[key][1] - ay) > 1e-6:
                raise LogFormatError(input_txt, f"anchor {key} moved from {anchors[key]} to ({ax}, {ay})", lineno)
            anchors[key] = (ax, ay)
            rng.append((t, key, r, cov))
        else:
            raise LogFormatError(input_txt, f"unknown measurement type '{shown(kind)}'", lineno)
    if len(odo) < 2:
        raise LogFormatError(input_txt, "fewer than two odom2diff lines: the log needs wheel speeds")
    o = np.array([row for row in odo])
    if (np.diff(o[:, 0]) <= 0).any():
        raise LogFormatError(input_txt, "odom2diff time does not increase")
    beacons = tuple(Beacon(k, xy[0], xy[1]) for k, xy in sorted(anchors.items()))
    index = {b.id: i for i, b in enumerate(beacons)}
    ranges = None
    if rng:
        t = np.array([r[0] for r in rng])
        if (np.diff(t) < 0).any():      # several anchors may share a time stamp (LOG_FORMAT.md)
            raise LogFormatError(input_txt, "range2 time decreases")
        ranges = Ranges(t, np.array([index[r[1]] for r in rng]), np.array([r[2] for r in rng]))
    robot = RobotConfig(
        ticks_per_meter_left=1.0, ticks_per_meter_right=1.0,       # speeds are already in m/s
        track_width=float(np.median(o[:, 3])),
        encoder_sigma=(float(np.sqrt(np.median(o[:, 4:6]))), 0.0),
        range_sigma=float(np.sqrt(np.median([r[3] for r in rng]))) if rng else 0.05,
        beacons=beacons,
    )
    truth = None
    if gt_txt is None:
        cand = input_txt.with_name(input_txt.name.replace("_Input", "_GT"))
        gt_txt = cand if cand.is_file() and cand != input_txt else None
    if gt_txt is not None:
        gt_txt = Path(gt_txt)
        pts = [_floats(gt_txt, ln, p, 3) for ln, p in _lines(gt_txt) if p[0] == "point2"]
        if pts:
            g = np.array(pts)
            # keep strictly increasing times (a row at or before the latest so far is dropped)
            keep = np.concatenate([[True], g[1:, 0] > np.maximum.accumulate(g[:, 0])[:-1]])
            truth = Truth(g[keep, 0], {"x": g[keep, 1], "y": g[keep, 2]})
    notes = (f"imported from libRSF {input_txt.name} (CC BY-SA 4.0, T. Pfeifer, TU Chemnitz)",)
    return Log(robot=robot, wheel_speeds=WheelSpeeds(o[:, 0], o[:, 1], o[:, 2]), ranges=ranges, truth=truth,
               notes=notes)
