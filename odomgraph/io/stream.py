"""The text stream of ``odomgraph stream``: measurement lines in, states.csv lines out.

Input, one measurement per line, the sensor's name and its LOG_FORMAT.md
columns in order::

    encoders,0.023,-6,6
    gps,0.152,-0.278,0.0525          (an optional 4th value: sigma [m])
    gyro,0.011,0.82
    ranges,1.2,A,25.3                (beacon id as in robot.toml)
    velocity,3.1,0.5,0.1
    wheel_speeds,0.05,0.31,0.33

Blank lines and lines starting with ``#`` are skipped; a UTF-8 byte-order
mark before the first line is allowed. Output: states.csv's header, then one
row per estimate, formatted exactly as ``write_states`` formats states.csv.
"""
from __future__ import annotations

import math
from typing import Iterator

import numpy as np

from odomgraph.io.csvtable import stamp_text
from odomgraph.io.estimate import STATES_HEADER
from odomgraph.io.log import SENSOR_FILES, Log

#: Each sensor's values on a line, in order: its LOG_FORMAT.md columns after
#: ``t`` (io.log.SENSOR_FILES; gps's third, sigma [m], is optional). One table
#: for the stream's reader (odomgraph.online) and writer (log_lines).
SENSOR_COLUMNS = {sf.name: sf.columns for sf in SENSOR_FILES}

#: states.csv's header line.
HEADER = ",".join(STATES_HEADER)


class LineError(ValueError):
    """A line the stream cannot split (the values are checked by odomgraph.online)."""


def parse_line(line: str) -> tuple[str, str, list[str]] | None:
    """(sensor, stamp text, value texts) of one input line, or None for a
    blank or comment line. The stamp stays text: the caller reads it."""
    s = line.strip().lstrip("\ufeff").strip()
    if not s or s.startswith("#"):
        return None
    parts = [p.strip() for p in s.split(",")]
    if len(parts) < 3:
        raise LineError(f"expected '<sensor>,<t>,<values...>', got {s[:60]!r}")
    return parts[0], parts[1], parts[2:]


def row_line(t: float, mean: np.ndarray, sigma: np.ndarray, t_origin: int = 0) -> str:
    """One states.csv row (no newline), as io.estimate.write_states writes it."""
    stamp = stamp_text(np.array([t]), t_origin)[0]
    return ",".join([stamp, *np.char.mod("%.9g", np.concatenate([mean, sigma])).tolist()])


def exact_stamp(t: float, origin: int = 0) -> str:
    """The absolute stamp of t [s since the integer second ``origin``] as
    text that reads back exactly: repr on a small clock; on a real clock the
    whole seconds and the fraction's exact decimal, which io.csvtable's
    split_stamps (and odomgraph.online) read without float rounding."""
    if not origin:
        return repr(float(t))
    from decimal import Decimal
    whole = math.floor(t)
    frac = t - whole                       # exact in float64
    tail = format(Decimal(frac), "f")[1:] if frac else ""
    return f"{origin + int(whole)}{tail}"


#: Sensors in the order lines of equal stamps are merged.
_ORDER = tuple(sf.name for sf in sorted(SENSOR_FILES, key=lambda sf: sf.tie))


def log_lines(log: Log) -> Iterator[str]:
    """Every measurement of ``log`` as stream lines, merged in time order
    (equal stamps: in _ORDER, then in file order). Values are written with
    repr and stamps with exact_stamp, so reading them back gives the log's
    numbers exactly."""
    ts, keys, texts = [], [], []
    for rank, name in enumerate(_ORDER):
        obj = getattr(log, name)
        if obj is None or not len(obj.t):
            continue
        parts = []
        for c in SENSOR_COLUMNS[name]:
            v = getattr(obj, c, None)
            if v is None:
                continue
            if name == "ranges" and c == "beacon":
                parts.append([log.robot.beacons[int(i)].id for i in v])
            else:
                parts.append(list(map(repr, np.asarray(v, float).tolist())))
        stamps = [exact_stamp(t, log.t_origin) for t in np.asarray(obj.t, float).tolist()]
        texts += [",".join((name, st, *vals)) for st, *vals in zip(stamps, *parts)]
        ts.append(np.asarray(obj.t, float))
        keys.append(np.full(len(obj.t), rank))
    if not ts:
        return iter(())
    order = np.lexsort((np.concatenate(keys), np.concatenate(ts)))
    return (texts[i] for i in order.tolist())
