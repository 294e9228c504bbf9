"""OptiOdom runs (Sousa et al., J. Intell. Robot. Syst. 2022; MIT licence).

A session directory holds ``<id>_run-NN.csv`` files with columns
``t, x_gt, y_gt, theta_gt, ticks_right, ticks_left`` (ticks per 50 ms cycle,
ground truth from OptiTrack) and ``<id>_metadata.csv`` with rows ``key,v1,v2,...``:
ngear, encRes, Li (track, m), Di (wheel diameters, m), and per run gt_ti/gt_tf
(motion-capture span) and odo_ti/odo_tf (odometry span).

Nominal ticks per metre = ngear * encRes / (pi * D). Motion capture becomes
truth.csv and the start pose robot.toml [initial]; optionally also gps.csv
(motion capture as an absolute position sensor at ``fixes_hz``).
"""
from __future__ import annotations

import io
import math
import re
import warnings
from pathlib import Path

import numpy as np

from odomgraph.factors._math import wrap_angle
from odomgraph.errors import LogFormatError
from odomgraph.io.csvtable import read_text, shown, text_lines
from odomgraph.io.log import Encoders, Gps, Log, Truth
from odomgraph.io.robot import InitialPose, RobotConfig


def read_metadata(path: Path) -> dict[str, list[str]]:
    meta = {}
    for lineno, raw in text_lines(read_text(path)):
        parts = [p.strip() for p in raw.split(",")]
        if parts and parts[0]:
            meta[parts[0]] = [p for p in parts[1:]]
    return meta


def _number(meta, key, path, index=0, positive=False) -> float:
    try:
        vals = [v for v in meta[key] if v != ""]
        val = float(vals[index])
    except KeyError:
        raise LogFormatError(path, f"metadata has no '{key}' row") from None
    except (IndexError, ValueError):
        raise LogFormatError(path, f"metadata '{key}' has no number at position {index + 1}") from None
    if not math.isfinite(val) or (positive and val <= 0):
        raise LogFormatError(path, f"metadata '{key}' must be a {'positive' if positive else 'finite'} number, "
                                   f"got {shown(vals[index])}")
    return val


def import_optiodom(run_csv: Path | str, metadata: Path | str | None = None, fixes_hz: float = 0.0,
                    fix_sigma: float = 0.01) -> Log:
    """Import one OptiOdom run. ``metadata`` defaults to the session's *_metadata.csv."""
    run_csv = Path(run_csv)
    if not run_csv.is_file():
        raise LogFormatError(run_csv, "file is missing")
    if not (math.isfinite(fixes_hz) and 0 <= fixes_hz <= 1000):
        raise LogFormatError(run_csv, f"--fixes-hz must be between 0 and 1000, got {fixes_hz:g}")
    if not (math.isfinite(fix_sigma) and fix_sigma > 0):
        raise LogFormatError(run_csv, f"--fix-sigma must be positive (motion capture is not noise-free), "
                                      f"got {fix_sigma:g}")
    m = re.search(r"run-(\d+)", run_csv.name)
    if not m:
        raise LogFormatError(run_csv, "expected a file named <session>_run-NN.csv")
    run = int(m.group(1)) - 1
    if metadata is None:
        found = sorted(run_csv.parent.glob("*_metadata.csv"))
        if not found:
            raise LogFormatError(run_csv.parent, "no *_metadata.csv beside the run file")
        metadata = found[0]
    metadata = Path(metadata)
    meta = read_metadata(metadata)
    ngear, enc = _number(meta, "ngear", metadata, positive=True), _number(meta, "encRes", metadata, positive=True)
    track = _number(meta, "Li", metadata, positive=True)
    d_right = _number(meta, "Di", metadata, 0, positive=True)
    d_left = _number(meta, "Di", metadata, 1, positive=True) if len([v for v in meta["Di"] if v]) > 1 else d_right
    odo_ti, odo_tf = _number(meta, "odo_ti", metadata, run), _number(meta, "odo_tf", metadata, run)

    text = read_text(run_csv)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")      # "input contained no data": checked below
            data = np.loadtxt(io.StringIO(text), delimiter=",", ndmin=2)
    except ValueError as exc:
        raise LogFormatError(run_csv, f"not a numeric CSV ({shown(str(exc), 120)})") from None
    if data.shape[0] < 2:
        raise LogFormatError(run_csv, "needs at least two rows")
    if data.shape[1] < 6:
        raise LogFormatError(run_csv, f"expected 6 columns (t, x, y, theta, ticks_right, ticks_left), found "
                                      f"{data.shape[1]}", 1)
    bad = ~np.isfinite(data).all(1)
    if bad.any():
        raise LogFormatError(run_csv, "non-finite value", int(np.argmax(bad)) + 1)
    t = data[:, 0]
    if (np.diff(t) <= 0).any():
        raise LogFormatError(run_csv, "time does not increase", int(np.argmax(np.diff(t) <= 0)) + 2)
    odo = (t >= odo_ti - 1e-9) & (t <= odo_tf + 1e-9)
    if odo.sum() < 2:
        raise LogFormatError(metadata, f"odo_ti..odo_tf of run {run + 1} ({odo_ti:g} to {odo_tf:g} s) holds fewer "
                                       "than two rows of the run")
    enc_log = Encoders(t[odo], data[odo, 5], data[odo, 4])          # columns: right, left
    # Motion capture is recorded over the whole run; gt_ti..gt_tf only marks the
    # span OptiOdom scores, so truth keeps every row.
    truth = Truth(t, {"x": data[:, 1], "y": data[:, 2], "theta": wrap_angle(data[:, 3])})
    x0, y0, th0 = data[0, 1], data[0, 2], float(wrap_angle(data[0, 3]))
    # The start pose from motion capture at the first odometry sample.
    robot = RobotConfig(
        ticks_per_meter_left=ngear * enc / (math.pi * d_left),
        ticks_per_meter_right=ngear * enc / (math.pi * d_right),
        track_width=track,
        encoder_sigma=(0.005, 0.02),
        gps_sigma=fix_sigma,
        initial=InitialPose(x0, y0, th0, (0.01, 0.01, 0.02)),
    )
    gps = None
    if fixes_hz > 0:
        tf = np.arange(truth.t[0], truth.t[-1], 1.0 / fixes_hz)
        gps = Gps(tf, truth.at("x", tf), truth.at("y", tf), np.full(tf.size, fix_sigma))
    notes = (f"imported from OptiOdom {run_csv.name} (MIT licence, Sousa et al. 2022)",)
    return Log(robot=robot, encoders=enc_log, gps=gps, truth=truth, notes=notes)
