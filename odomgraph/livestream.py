"""The loop behind ``odomgraph stream``: lines in, rows out, checkpoints on the way.

``run_stream`` reads measurement lines (io.stream), pushes them into an
``online.Online``, and writes each row as soon as it is final, flushed, so a
robot's next process reads it at once. Problems with one line (an unknown
sensor, a wrong number of values, text where a number belongs) are said on
the error stream with the line number and skipped: one bad line from a
sensor driver must not stop a robot's estimator. Recoveries and warnings
are said there as they happen; the counts come at the end.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import IO, Iterable

from odomgraph.errors import EstimatorDivergedError, OdomgraphError
from odomgraph.io.stream import HEADER, LineError, parse_line, row_line
from odomgraph.online import Online, StreamInputError

#: Bad lines said one by one, at most; the rest are counted.
SAY_BAD_LINES = 20


@dataclass
class StreamStats:
    lines: int = 0           # lines read (blank and comment lines included)
    skipped_bad: int = 0     # lines that could not be read
    skipped_resumed: int = 0  # lines a resumed replay had consumed before its checkpoint
    rows: int = 0            # rows written
    checkpoints: int = 0


def run_stream(online: Online, lines: Iterable[str], out: IO[str], err: IO[str], *, source: str = "stdin",
               rate: float | None = None, speed: float = 0.0, checkpoint=None, checkpoint_every: float = 60.0,
               skip_lines: int = 0) -> StreamStats:
    """Stream ``lines`` through ``online``; rows to ``out`` (states.csv header
    first), problems to ``err``. ``rate`` [Hz]: one row per 1/rate seconds
    of log time, the first at or after each multiple of 1/rate (None: every row). ``speed``: pace the lines against
    the wall clock at this multiple of real time (0: as fast as possible).
    ``checkpoint``: path written every ``checkpoint_every`` seconds of log
    time, and when the input ends (before the last rows are
    flushed, so that a resumed stream goes on as if never stopped). ``skip_lines``: lines to pass over first (a
    replay resumed from a checkpoint that had read them)."""
    st = StreamStats()
    out.write(HEADER + "\n")
    out.flush()
    next_t = [-math.inf]
    said = [len(online.ekf.recoveries) if online.ekf is not None else 0, len(online.restarts), len(online.alerts),
            len(online.ekf.departures) if online.ekf is not None else 0]
    wall0 = t_first = None
    last_ckpt = None

    def emit(rows):
        for r in rows:
            if rate is not None:
                if r.t < next_t[0]:
                    continue
                next_t[0] = math.floor(r.t * rate + 1.0 + 1e-9) / rate
            out.write(row_line(r.t, r.mean, r.sigma, r.t_origin) + "\n")
            st.rows += 1
        if rows:
            out.flush()
        eng = online.ekf if online.ekf is not None else (online.smoother.runner if online.smoother else None)
        if eng is not None and len(eng.recoveries) > said[0]:
            for msg in eng.recoveries[said[0]:]:
                err.write(f"odomgraph: recovered: {msg}\n")
            said[0] = len(eng.recoveries)
            err.flush()
        deps = getattr(eng, "departures", [])
        if len(deps) > said[3]:
            for msg in deps[said[3]:]:
                err.write(f"odomgraph: followed a departure: {msg}\n")
            said[3] = len(deps)
            err.flush()
        if len(online.alerts) > said[2]:
            for msg in online.alerts[said[2]:]:
                err.write(f"odomgraph: warning: {msg}\n")
            said[2] = len(online.alerts)
            err.flush()
        if len(online.restarts) > said[1]:
            for msg in online.restarts[said[1]:]:
                err.write(f"odomgraph: restarted: {msg}\n")
            said[1] = len(online.restarts)
            said[0] = said[3] = 0       # a new engine counts its recoveries from 0
            err.flush()

    for n, line in enumerate(lines, 1):
        st.lines += 1
        if n <= skip_lines:
            st.skipped_resumed += 1
            continue
        try:
            parsed = parse_line(line)
            if parsed is None:
                continue
            sensor, stamp, values = parsed
            if speed > 0:
                try:
                    t = float(stamp)
                except ValueError:
                    raise StreamInputError(f"time {stamp!r} is not a number") from None
                if wall0 is None:
                    wall0, t_first = time.monotonic(), t
                wait = wall0 + (t - t_first) / speed - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            rows = online.push(sensor, stamp, *values)       # the text: a real clock's stamp read exactly
        except EstimatorDivergedError as exc:
            emit(getattr(exc, "rows_before", []))     # the rows given before the stream gave up
            raise
        except (LineError, StreamInputError) as exc:
            st.skipped_bad += 1
            if st.skipped_bad <= SAY_BAD_LINES:
                err.write(f"odomgraph: {source}:{n}: {exc} (line skipped)\n")
                err.flush()
            continue
        emit(rows)
        if checkpoint is not None and online.t_released > -math.inf:
            if last_ckpt is None:
                last_ckpt = online.t_released
            elif online.t_released - last_ckpt >= checkpoint_every:
                online.lines_read = n
                online.save(checkpoint)
                st.checkpoints += 1
                last_ckpt = online.t_released
    if checkpoint is not None:
        # before close(): a stream that ended (the robot's pipe closed) can go on from here
        online.lines_read = st.lines
        online.save(checkpoint)
        st.checkpoints += 1
    try:
        rows = online.close()
    except EstimatorDivergedError as exc:
        emit(getattr(exc, "rows_before", []))
        raise
    emit(rows)
    if st.skipped_bad > SAY_BAD_LINES:
        err.write(f"odomgraph: {source}: {st.skipped_bad - SAY_BAD_LINES} more bad lines skipped\n")
    return st


def summary_lines(online: Online, st: StreamStats) -> list[str]:
    """The end-of-stream account, one line each: what was used, rejected
    (by the gate, for arriving too late, as a repeated stamp) and recovered."""
    s = online.summary()
    out = []

    def counts(d):
        return ", ".join(f"{k} {v}" for k, v in sorted(d.items())) or "none"
    out.append(f"stream: {st.lines} lines, {st.rows} rows written; used: {counts(s['accepted'])}")
    for key, what in (("rejected_by_gate", "rejected by the gate"),
                      ("rejected_late", f"rejected, older than the {s['latency_s']:g} s latency window"),
                      ("repeated_stamps", "dropped, a stamp the sensor had sent already"),
                      ("rejected_ahead", "rejected, stamped far past the newest (a clock ahead?)"),
                      ("impossible_rows", "a speed no ground robot reaches, taken for a counter glitch")):
        if s[key]:
            out.append(f"stream: {what}: {counts(s[key])}")
    if st.skipped_bad:
        out.append(f"stream: {st.skipped_bad} lines could not be read and were skipped")
    if s["recoveries"]:
        out.append(f"stream: {len(s['recoveries'])} recoveries (said above as they happened)")
    if s.get("departures"):
        out.append(f"stream: {len(s['departures'])} departures followed (said above as they happened)")
    if s["restarts"]:
        out.append(f"stream: {len(s['restarts'])} restart(s), after a divergence or to take up the fixes' frame "
                   "(said above)")
    out += [f"warning: {w}" for w in s["warnings"]]
    out += [f"flag: {f}" for f in s["flags"]]
    return out


def check_resume(online: Online, method: str) -> None:
    """A checkpoint belongs to the method it was made with."""
    if online.method.value != method:
        raise OdomgraphError(f"the checkpoint was made with --method {online.method.value}, not {method}")
