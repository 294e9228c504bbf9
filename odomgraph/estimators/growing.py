"""A keyframe problem that grows as a stream's data arrive (odomgraph.online).

The incremental smoothers (incremental.py) read their Problem (graph.py) by
interval index: keyframe k+1's update uses interval k's arrays. Built from a
whole log, the Problem holds every interval; a stream has only what arrived.
``GrowingProblem`` starts from the Problem of the warm-up's data, cut to its
final intervals, and appends each later interval, computed by the same code
(keyframes.build_keyframes over a short window of cleaned data, starting at
a keyframe so that its keyframes are the log's), into buffers that double
when full: appending costs O(1), not a copy of the history.

An interval k is final when keyframe k+2 is known (the random walk from W_k
to W_{k+1} spans both intervals, graph.walk_span) and every
measurement up to t_{k+1} is (the cleaning reads a few rows ahead).
"""
from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from odomgraph.estimators.batch import zero_slip_intervals
from odomgraph.estimators.graph import Problem, motion_sigma, unary_rows, walk_span
from odomgraph.estimators.keyframes import Keyframes, build_keyframes
from odomgraph.estimators.measurements import clean
from odomgraph.io.log import Log

#: Keyframe intervals before the first new one that a window holds: a rate
#: sensor's interval mean reads the samples before t_k (keyframes.interval_means).
WINDOW_BACK = 3

#: Keyframes fields by what they have one row of.
_PER_KEYFRAME = ("t",)
_PER_INTERVAL = ("enc_m", "enc_sigma", "enc_n", "gyro_z", "gyro_sigma", "gyro_n", "vel_z", "vel_sigma", "vel_n", "mid_tau_vw", "trans_bend",
                 "mid_bend")
_PER_FIX = ("gps_k", "gps_tau_vw", "gps_xy", "gps_sigma", "gps_t", "gps_bend")
_PER_RANGE = ("rng_k", "rng_tau_vw", "rng_beacon", "rng_z", "rng_id", "rng_bend")


class _Buffers:
    """Named arrays with spare rows; ``view(name)`` is the filled part."""

    def __init__(self, arrays: dict[str, np.ndarray]):
        self.a = {k: np.asarray(v).copy() for k, v in arrays.items()}
        self.n = {k: len(v) for k, v in self.a.items()}

    def append(self, name: str, rows: np.ndarray) -> None:
        rows = np.asarray(rows)
        a, n = self.a[name], self.n[name]
        if n + len(rows) > len(a):
            b = np.zeros((max(2 * len(a), n + len(rows), 16),) + a.shape[1:], a.dtype)
            b[:n] = a[:n]
            self.a[name] = a = b
        a[n:n + len(rows)] = rows
        self.n[name] = n + len(rows)

    def view(self, name: str) -> np.ndarray:
        return self.a[name][:self.n[name]]


class GrowingProblem:
    """The problems of one incremental runner (its own and its graph's two
    linearisation copies, which share the keyframes) grown together.

    prob: the warm-up's Problem (batch.build_problem, causal), already cut
    to its final intervals and keyframes (``cut``); t_next: the keyframe
    after its last one [s] (the last interval's random walk spans to it)."""

    def __init__(self, problems: list[Problem], t_next: float, schedule, step: int, keyframe_hz: float):
        self.problems = problems
        p = problems[0]
        kf = p.kf
        self.schedule, self.step, self.keyframe_hz = schedule, step, keyframe_hz
        arrays = {f.name: getattr(kf, f.name) for f in fields(kf)}
        if arrays["gps_t"] is None:
            arrays["gps_t"] = np.zeros(len(kf.gps_k))
        self.walks = p.rw                    # its unit covariance; the spans grow here
        arrays.update(zero_slip=p.zero_slip, walk_span=p.rw.span, motion_whiten=p.motion_whiten, gps_slot=p.gps_slot, rng_slot=p.rng_slot,
                      no_slip=np.zeros(len(p.zero_slip), bool))
        self.buf = _Buffers(arrays)
        # the last interval's walk spans to t_next: redo it with the real next dt
        self._set_walk(len(kf.t) - 2, float(kf.t[-1] - kf.t[-2]), float(t_next - kf.t[-1]))
        self._publish()

    @staticmethod
    def cut(prob: Problem, n_intervals: int) -> tuple[Problem, float]:
        """``prob`` with its first n_intervals intervals (n_intervals + 1
        keyframes), and the time of the keyframe after them [s]."""
        kf = prob.kf
        m = n_intervals
        sel_g = kf.gps_k < m
        sel_r = kf.rng_k < m
        kw = {}
        for name in _PER_KEYFRAME:
            kw[name] = getattr(kf, name)[:m + 1]
        for name in _PER_INTERVAL:
            kw[name] = getattr(kf, name)[:m]
        for name in _PER_FIX:
            v = getattr(kf, name)
            kw[name] = None if v is None else v[sel_g]
        for name in _PER_RANGE:
            kw[name] = getattr(kf, name)[sel_r]
        return replace(prob, kf=Keyframes(**kw), zero_slip=prob.zero_slip[:m]), float(kf.t[m + 1])

    def _set_walk(self, j: int, dt: float, dt_next: float) -> None:
        self.buf.view("walk_span")[j] = walk_span(np.array([dt]), np.array([dt_next]))[0]

    def append(self, piece: Keyframes, w: int, t_next: float | None, log_t_start: float) -> None:
        """Interval ``w`` of ``piece`` (the keyframes of a window that starts at
        one of this problem's keyframes) as the next interval; t_next [s]: the
        keyframe after its end (its own end again for the stream's last), or
        None when not known yet (``set_walk`` later, before it is read)."""
        b = self.buf
        j = b.n["enc_m"]                                     # its index here
        b.append("t", piece.t[w + 1:w + 2])
        for name in _PER_INTERVAL:
            b.append(name, getattr(piece, name)[w:w + 1])
        g = np.flatnonzero(piece.gps_k == w)
        b.append("gps_k", np.full(g.size, j))
        for name in ("gps_tau_vw", "gps_xy", "gps_sigma", "gps_bend"):
            b.append(name, getattr(piece, name)[g])
        b.append("gps_t", piece.gps_t[g] if piece.gps_t is not None else np.zeros(g.size))
        b.append("gps_slot", np.arange(g.size))
        r = np.flatnonzero(piece.rng_k == w)
        b.append("rng_k", np.full(r.size, j))
        for name in ("rng_tau_vw", "rng_beacon", "rng_z", "rng_id", "rng_bend"):
            b.append(name, getattr(piece, name)[r])
        b.append("rng_slot", np.arange(r.size))
        p = self.problems[0]
        t = b.view("t")
        b.append("zero_slip", zero_slip_intervals(t[j:j + 2], p.init, log_t_start, self.schedule))
        b.append("motion_whiten", 1.0 / motion_sigma(piece, p.robot.process.yaw_accel**2, p.robot.track_width)[w:w + 1])
        b.append("walk_span", np.zeros(1))
        b.append("no_slip", np.zeros(1, bool))
        self._publish(g.size, r.size)
        if t_next is not None:
            self.set_walk(j, t_next)

    def set_walk(self, j: int, t_next: float) -> None:
        """Interval j's random walk, now that the keyframe after its end is
        known at t_next [s] (its own end again: the stream's last interval)."""
        t = self.buf.view("t")
        dt = float(t[j + 1] - t[j])
        self._set_walk(j, dt, float(t_next - t[j + 1]) if t_next > t[j + 1] else dt)

    def _publish(self, g_max: int = 0, r_max: int = 0) -> None:
        """Every problem reads the buffers' filled parts; g_max, r_max: the
        fixes and ranges of the interval just appended."""
        b = self.buf
        kf = Keyframes(**{name: b.view(name) for name in _PER_KEYFRAME + _PER_INTERVAL + _PER_FIX + _PER_RANGE})
        for i, p in enumerate(self.problems):
            p.kf = kf
            # the graph's linearisation copies carry no slip priors (incremental._Graph)
            p.zero_slip = b.view("zero_slip") if i == 0 else b.view("no_slip")
            p.rw = replace(self.walks, span=b.view("walk_span"))
            p.motion_whiten = b.view("motion_whiten")
            p.gps_slot, p.rng_slot = b.view("gps_slot"), b.view("rng_slot")
            # the row layout only grows: padding rows are dropped before GTSAM sees them
            p.g_max = max(p.g_max, g_max)
            if p.range_bias_sigma is None:
                p.r_max = max(p.r_max, r_max)
            p.rows_unary = unary_rows(p.g_max, p.r_max)


def window_piece(raw: Log, t_from: float, t_to: float, keyframe_hz: float, step: int) -> Keyframes:
    """The keyframes of raw's data between keyframes at t_from and t_to [s]
    (both wheel-row stamps), cleaned over all of ``raw`` (which holds some
    context before and after), computed as a whole log's are (causal)."""
    from dataclasses import replace as dc_replace
    log = clean(raw, frozen=False)[0]        # (a live window: measurements.clean)
    if log.encoders is not None:
        e = log.encoders
        m = (e.t >= t_from) & (e.t <= t_to)
        log = log.with_(encoders=dc_replace(e, t=e.t[m], ticks_left=e.ticks_left[m], ticks_right=e.ticks_right[m]))
    else:
        w = log.wheel_speeds
        m = (w.t >= t_from) & (w.t <= t_to)
        log = log.with_(wheel_speeds=dc_replace(w, t=w.t[m], v_left=w.v_left[m], v_right=w.v_right[m]))
    return build_keyframes(log, t_from, keyframe_hz, causal=True, step=step)
