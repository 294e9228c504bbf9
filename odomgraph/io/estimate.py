"""The estimate directory of LOG_FORMAT.md: states.csv, trajectory.tum, summary.json."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from odomgraph import state as S
from odomgraph.errors import LogFormatError
from odomgraph.result import Estimate
from odomgraph.io.csvtable import read_table, stamp_text, write_table
from odomgraph.io.outdir import atomic_output_dir


#: states.csv's header, in order (LOG_FORMAT.md).
STATES_HEADER = ("t",) + S.NAMES + tuple(f"sigma_{n}" for n in S.NAMES)


def states_columns(est: Estimate) -> dict[str, np.ndarray]:
    """states.csv's columns; ``t`` as the absolute stamps' text (Estimate.t_origin)."""
    cols = {"t": stamp_text(est.t, est.t_origin)}
    cols.update({name: est.mean[:, i] for i, name in enumerate(S.NAMES)})
    cols.update({f"sigma_{name}": est.sigma[:, i] for i, name in enumerate(S.NAMES)})
    return cols


def write_states(path: Path, est: Estimate) -> None:
    write_table(path, states_columns(est), {k: "%.9g" for k in STATES_HEADER[1:]})


def is_states_file(path: Path) -> bool:
    """Whether ``path`` holds a states.csv as odomgraph writes it (its
    header line), so that writing one never replaces another kind of file."""
    from odomgraph.io.csvtable import header_of
    try:
        return tuple(header_of(Path(path))) == STATES_HEADER
    except (OSError, LogFormatError, ValueError):
        return False


def _tum_lines(t_text, x, y, theta) -> str:
    return "".join(f"{t} {xi:.6f} {yi:.6f} 0 0 0 {np.sin(th / 2):.9f} {np.cos(th / 2):.9f}\n"
                   for t, xi, yi, th in zip(t_text, x, y, theta))


def tum_text(est: Estimate) -> str:
    """TUM trajectory lines ``t x y z qx qy qz qw`` (z = 0, yaw-only
    quaternion), after one ``#`` comment naming the method, so that evo's
    legends tell the files apart (evo and numpy.loadtxt skip the comment)."""
    return (f"# odomgraph {est.method}: t x y z qx qy qz qw\n"
            + _tum_lines(stamp_text(est.t, est.t_origin), est.mean[:, S.X], est.mean[:, S.Y], est.mean[:, S.THETA]))


def truth_tum_text(t: np.ndarray, x: np.ndarray, y: np.ndarray, theta: np.ndarray, t_origin: int = 0) -> str:
    """truth.tum: the log's truth.csv rows (robot frame origin, world frame) as TUM lines."""
    return "# odomgraph truth: t x y z qx qy qz qw\n" + _tum_lines(stamp_text(t, t_origin), x, y, theta)


def write_estimate(est: Estimate, out_dir: Path | str, summary: dict, inputs=(), truth_tum: str | None = None) -> Path:
    """Write ``est`` and its ``summary`` dict (see ``summary``) atomically.
    ``inputs``: paths the output must not touch (io.outdir). ``truth_tum``
    (see truth_tum_text) is written as truth.tum beside trajectory.tum."""
    with atomic_output_dir(out_dir, inputs, kind="estimate") as d:
        write_states(d / "states.csv", est)
        (d / "trajectory.tum").write_text(tum_text(est), encoding="utf-8")
        if truth_tum is not None:
            (d / "truth.tum").write_text(truth_tum, encoding="utf-8")
        if est.online is not None:
            write_states(d / "online.csv", est.online)
        (d / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return Path(out_dir)


def read_states(path: Path | str) -> Estimate:
    """Read a states.csv back into an Estimate (for reports and comparisons)."""
    c = read_table(Path(path), ("t", *S.NAMES, *(f"sigma_{n}" for n in S.NAMES)))
    mean = np.column_stack([c[n] for n in S.NAMES])
    sigma = np.column_stack([c[f"sigma_{n}"] for n in S.NAMES])
    if len(c["t"]) == 0:
        raise LogFormatError(path, "has no rows")
    origin, t = 0, c["t"]
    if "_t_sec" in c:  # a real clock: count from its first whole second, as read_log does
        origin = int(c["_t_sec"][0])
        t = (c["_t_sec"] - origin).astype(float) + c["_t_frac"]
    return Estimate(method=Path(path).parent.name, t=t, mean=mean, sigma=sigma, t_origin=origin)
