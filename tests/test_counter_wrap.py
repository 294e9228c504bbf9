"""Tick differences taken across a counter's wrap-around (io.log.unwrapped_ticks).

A 16-bit encoder counter differenced naively gives -65177 for +359 each
time it wraps; a probe's log had 57 such rows, which the estimators only
"rejected as outliers", losing their ticks. They are given back their 2^16
(2^32) as the log is read and as a stream line arrives, and said."""
from dataclasses import replace

import numpy as np
import pytest

from odomgraph.io.log import read_log, unwrapped_ticks, write_log
from odomgraph.io.stream import log_lines
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper, yard


def _wrapped(log, bits: int, every: int, seed: int):
    """``log`` with every ``every``-th encoder row (either wheel, at random) wrapped by 2^bits."""
    e = log.encoders
    rng = np.random.default_rng(seed)
    left, right = e.ticks_left.copy(), e.ticks_right.copy()
    rows = np.arange(5, len(e.t), every)
    side = rng.integers(0, 2, rows.size).astype(bool)
    for arr, pick in ((left, rows[side]), (right, rows[~side])):
        arr[pick] = np.where(arr[pick] >= 0, arr[pick] - 2 ** bits, arr[pick] + 2 ** bits)
    return log.with_(encoders=replace(e, ticks_left=left, ticks_right=right)), int(side.sum()), int((~side).sum())


@pytest.mark.parametrize("make,bits,every,seed", [(paper, 16, 37, 1), (yard, 32, 53, 2)])
def test_a_wrapped_counter_is_read_back_exactly_and_said(tmp_path, make, bits, every, seed):
    log = inject(make(40.0), Faults(), seed)
    bad, n_left, n_right = _wrapped(log, bits, every, seed)
    # (write_log refuses such rows, as read_log did: the file is written as a converter would)
    d = write_log(log, tmp_path / "log")
    e = bad.encoders
    (d / "encoders.csv").write_text("t,ticks_left,ticks_right\n" + "".join(
        f"{t:.6f},{int(a):d},{int(b):d}\n" for t, a, b in zip(e.t, e.ticks_left, e.ticks_right)))
    back = read_log(d)
    assert np.allclose(back.encoders.t, log.encoders.t, atol=1e-6)
    assert np.array_equal(back.encoders.ticks_left, log.encoders.ticks_left)
    assert np.array_equal(back.encoders.ticks_right, log.encoders.ticks_right)
    said = [w for w in back.warnings if "counter's wrap-around, unwrapped" in w]
    assert len(said) == 2, back.warnings
    assert said[0].startswith(f"encoders.csv: {n_left} left tick count(s) are a {bits}-bit counter's")
    assert said[1].startswith(f"encoders.csv: {n_right} right tick count(s) are a {bits}-bit counter's")
    # a clean log is left alone
    same, lines = unwrapped_ticks(log.encoders, log.robot)
    assert same is log.encoders and lines == []


@pytest.mark.parametrize("tpm,hz", [(520_000.0, 10.0), (50_000.0, 1.0)])
def test_a_fine_encoder_s_big_counts_are_no_wrap(tpm, hz):
    """A 4096-line quadrature encoder behind a 20:1 gearbox (520k ticks/m)
    counts 52k ticks a 10 Hz row at 1 m/s, as a 1 Hz log at 50k ticks/m
    does: within a quarter of 2^16, yet a wheel speed of 1 m/s, not a wrap."""
    from odomgraph.io.log import Encoders
    from odomgraph.io.robot import RobotConfig
    t = np.arange(0.0, 20.0, 1.0 / hz)
    ticks = np.round(tpm / hz * (1.0 + 0.05 * np.sin(t))).astype(np.int64)
    ticks[0] = 0
    e = Encoders(t, ticks, ticks.copy())
    robot = RobotConfig(ticks_per_meter_left=tpm, ticks_per_meter_right=tpm, track_width=0.5)
    same, lines = unwrapped_ticks(e, robot)
    assert same is e and lines == [] and ticks.max() > 49152


def test_a_stream_unwraps_each_line_and_says_it():
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.io.stream import parse_line
    from odomgraph.online import Online
    log = inject(paper(40.0), Faults(), 3)
    bad, n_left, n_right = _wrapped(log, 16, 41, 3)
    rows = {}
    for name, lg in (("clean", log), ("wrapped", bad)):
        live = Online(lg.robot, "ekf", Schedule(calibrate_until=20.0))
        out = []
        for line in log_lines(lg):
            out += live.push(*(lambda p: (p[0], p[1], *p[2]))(parse_line(line)))
        out += live.close()
        rows[name] = (live, out)
    assert len(rows["clean"][1]) == len(rows["wrapped"][1])
    for a, b in zip(rows["clean"][1], rows["wrapped"][1]):
        assert a.t == b.t and np.array_equal(a.mean, b.mean)
    said = [a for a in rows["wrapped"][0].alerts if "16-bit counter's wrap-around" in a]
    assert len(said) == n_left + n_right
