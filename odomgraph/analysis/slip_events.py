"""Slip events read from an estimate, and from the truth where a log has it.

An event is a stretch where a wheel's slip estimate is both large
(|slip| > ``min_slip``) and significant (|slip| > 3 sigma), lasting at least
``min_duration``; stretches closer than ``merge_gap`` are one event. On the
truth (no sigma) only the size counts. Times are seconds since the log start.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from odomgraph import state as S
from odomgraph.io.log import Log
from odomgraph.result import Estimate

#: Slip below this [m/s] is not an event (the paper's events are 0.5 m/s; encoder noise is ~0.01).
MIN_SLIP = 0.05
MIN_DURATION = 0.5
MERGE_GAP = 0.5


@dataclass(frozen=True)
class SlipEvent:
    wheel: str
    """"left" or "right"."""
    start: float
    """[s] since the log start."""
    end: float
    peak: float
    """Slip of largest magnitude in the event [m/s], with its sign."""
    peak_sigma: float | None
    """The estimate's 1-sigma at the peak [m/s] (None for the truth)."""


def _stretches(t: np.ndarray, on: np.ndarray, min_duration: float, merge_gap: float) -> list[tuple[int, int]]:
    """(first, last) row indices of runs of ``on``, merged across gaps shorter
    than merge_gap and kept when at least min_duration long."""
    idx = np.flatnonzero(on)
    if idx.size == 0:
        return []
    runs = []
    start = prev = idx[0]
    for i in idx[1:]:
        if t[i] - t[prev] > merge_gap:
            runs.append((start, prev))
            start = i
        prev = i
    runs.append((start, prev))
    return [(a, b) for a, b in runs if t[b] - t[a] >= min_duration]


def events(t: np.ndarray, slip: np.ndarray, sigma: np.ndarray | None, wheel: str, t0: float = 0.0,
           min_slip: float = MIN_SLIP, min_duration: float = MIN_DURATION,
           merge_gap: float = MERGE_GAP) -> list[SlipEvent]:
    """Events of one wheel's slip series (t [s], slip and sigma [m/s], (N,))."""
    on = np.abs(slip) > min_slip
    if sigma is not None:
        on &= np.abs(slip) > 3 * sigma
    out = []
    for a, b in _stretches(t, on, min_duration, merge_gap):
        k = a + int(np.argmax(np.abs(slip[a:b + 1])))
        out.append(SlipEvent(wheel, float(t[a] - t0), float(t[b] - t0), float(slip[k]),
                             None if sigma is None else float(sigma[k])))
    return out


def estimated_events(est: Estimate, log: Log) -> list[SlipEvent]:
    """Both wheels' events in ``est``, by start time."""
    out = []
    for wheel, i in (("left", S.SLIP_L), ("right", S.SLIP_R)):
        out += events(est.t, est.mean[:, i], est.sigma[:, i], wheel, log.t_start)
    return sorted(out, key=lambda e: (e.start, e.wheel))


def true_events(log: Log) -> list[SlipEvent] | None:
    """The truth's events (None when the log has no slip truth)."""
    tr = log.truth
    if tr is None or "slip_left" not in tr.values:
        return None
    out = []
    for wheel in ("left", "right"):
        out += events(tr.t, tr.values[f"slip_{wheel}"], None, wheel, log.t_start)
    return sorted(out, key=lambda e: (e.start, e.wheel))
