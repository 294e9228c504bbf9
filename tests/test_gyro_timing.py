"""The gyro's clock against the wheels (analysis.gyrotiming).

A hostile probe found a gyro clock that jumped 0.5 s mid-log leaving a wheel
scale 4 sigma off, status ok, and a gyro stamped 0.25 s late taken for a GPS
clock jump. Only the GPS was timed before. Scenarios, seeds, offsets and
jump times here are other than the probe's (paper seed 164, +0.5 s at 40 s;
+0.25 s throughout)."""
import pytest

from odomgraph.analysis.gyrotiming import window_offsets
from odomgraph.analysis.timing import combine
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.result import status_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper, yard


@pytest.mark.parametrize("make,seed,late", [(paper, 61, 0.15), (yard, 62, -0.3), (yard, 63, 0.4)])
def test_a_late_gyro_is_measured_and_flagged(make, seed, late):
    log = inject(make(90.0), Faults(clock_jumps=(("gyro", -1.0, late),)), seed)
    off = combine(window_offsets(log))
    assert off is not None and abs(off.delta - late) < max(3.0 * off.sigma, 0.03), off
    est = estimate(log, "batch", Schedule(20.0))
    said = [w for w in est.warnings if w.startswith("gyro time stamps look")]
    assert len(said) == 1, est.warnings
    assert float(said[0].split("look ")[1].split(" s late")[0]) == pytest.approx(late, abs=0.03)
    assert status_of(est)[0] == "degraded"


@pytest.mark.parametrize("make,seed,at,size", [(paper, 64, 55.0, 0.3), (yard, 65, 35.0, -0.4)])
def test_a_gyro_clock_that_jumps_is_found(make, seed, at, size):
    log = inject(make(100.0), Faults(clock_jumps=(("gyro", at, size),)), seed)
    est = estimate(log, "ekf", Schedule(20.0))
    said = [w for w in est.warnings if w.startswith("the gyro clock seems to jump by")]
    assert len(said) == 1, est.warnings
    assert float(said[0].split("jump by ")[1].split(" s")[0]) == pytest.approx(size, abs=0.04)
    a, b = (float(v) for v in said[0].split("between t=")[1].split(" s ")[0].split(" and "))
    assert a <= at <= b                                 # said between the windows either side
    assert status_of(est)[0] == "degraded"


@pytest.mark.parametrize("make,seed", [(paper, 66), (yard, 67), (paper, 68)])
def test_an_honest_gyro_clock_says_nothing(make, seed):
    log = inject(make(120.0), Faults(), seed)
    parts = window_offsets(log)
    assert len(parts) >= 4
    assert abs(combine(parts).delta) < 0.03, [p.delta for p in parts]
    est = estimate(log, "batch", Schedule(20.0))
    assert not [w for w in est.warnings if "gyro clock" in w or "gyro time stamps" in w], est.warnings


def test_brief_slips_at_every_turn_are_not_a_late_clock():
    """A second probe's false alarm: a wheel that slips 0.15 m/s for 0.5 s at
    the start of each of 22 turns shifts the windows by 0.06 s, which read
    as a late gyro; no clock was off (MIN_OFFSET 0.1 s)."""
    from odomgraph.sim.scenarios import Segment, SlipEvent
    turns = (Segment(3.0, 0.8, 0.0), Segment(3.0, 0.5, 0.8), Segment(3.0, 0.8, 0.0), Segment(3.0, 0.5, -0.8))
    slips = tuple(SlipEvent("right" if k % 2 == 0 else "left", 23.0 + 6 * k, 23.5 + 6 * k, 0.15) for k in range(22))
    sc = paper(150.0).with_(loop=turns, slips=slips)
    log = inject(sc, Faults(), 321)
    parts = window_offsets(log)
    assert parts and abs(combine(parts).delta) < 0.1
    est = estimate(log, "batch", Schedule(20.0))
    assert not [w for w in est.warnings if "gyro clock" in w or "gyro time stamps" in w], est.warnings


def test_calibrate_refuses_a_late_gyro():
    """calibrate reads the clock's line back from the estimate's flags (it
    does not fit the clock again) and will not write: paper seed 69, the
    gyro 0.3 s late throughout."""
    from odomgraph.pipeline import calibrate
    log = inject(paper(90.0), Faults(clock_jumps=(("gyro", -1.0, 0.3),)), 69)
    _, rep = calibrate(log, tune=False)
    said = [w for w in rep["problems"] if w.startswith("gyro time stamps look")]
    assert len(said) == 1, rep["problems"]
    assert float(said[0].split("look ")[1].split(" s late")[0]) == pytest.approx(0.3, abs=0.03)


@pytest.mark.parametrize("make, seed, lag", [(paper, 71, 0.15), pytest.param(yard, 72, 0.25, marks=pytest.mark.slow)])
def test_both_references_late_alike_name_the_wheels(make, seed, lag, tmp_path):
    """Wheel stamps late (an odometry filter's lag: a hostile probe's
    diff_drive_controller with its 10-sample rolling window) made the GPS and
    the gyro both look early, and calibrate advised --time-offset for the
    GPS, which mends neither. Now one more line names the wheels, and
    calibrate's refusal drops that advice."""
    from dataclasses import replace
    from odomgraph.errors import CalibrationRejectedError
    from odomgraph.pipeline import calibrate_to_file
    log = inject(make(90.0 if make is paper else 120.0), Faults(), seed)
    late = log.with_(encoders=replace(log.encoders, t=log.encoders.t + lag))
    cal = Schedule(20.0 if make is paper else 30.0)
    est = estimate(late, "batch", cal)
    line = [f for f in est.flags if f.startswith("the GPS (")]
    assert len(line) == 1 and f"re-stamp the wheels' file (t less {lag:.2f} s)" in line[0], est.flags
    # in place of the references' own lines, whose remedies would mend neither
    assert not any(f.startswith(("GPS time stamps look", "gyro time stamps look")) for f in est.flags), est.flags
    with pytest.raises(CalibrationRejectedError) as exc:
        calibrate_to_file(late, tmp_path / "cal.toml", cal, tune=False)
    said = str(exc.value)
    assert "re-stamp the wheels' file" in said and "--time-offset" not in said and "re-stamp gyro.csv" not in said
    # the GPS alone late: its own line, not the wheels'
    g = log.gps
    gps_late = log.with_(gps=replace(g, t=g.t + 0.2))
    flags = estimate(gps_late, "batch", cal).flags
    assert any(f.startswith("GPS time stamps look") for f in flags)
    assert not any(f.startswith("the GPS (") for f in flags), flags


def test_wheels_late_lines_compare_the_two_offsets():
    from odomgraph.analysis.gyrotiming import wheels_late_lines
    gps = "GPS time stamps look {:+.2f} s late (sigma {:.2f} s) against the wheels: ..."
    gyro = "gyro time stamps look {:+.2f} s late (sigma {:.2f} s) against the wheels: ..."
    line = wheels_late_lines([gps.format(-0.10, 0.02), gyro.format(-0.12, 0.01)])
    assert len(line) == 1 and "by about -0.12 s" in line[0] and "(t less 0.12 s)" in line[0], line
    assert wheels_late_lines([gps.format(-0.10, 0.01), gyro.format(-0.20, 0.01)]) == []      # not alike
    # the weighted mean: a wide GPS offset hardly moves it (a review: unweighted, 0.30 s left the gyro 10 sigma off)
    line = wheels_late_lines([gps.format(0.50, 0.20), gyro.format(0.10, 0.02)])
    assert len(line) == 1 and "(t plus 0.10 s)" in line[0], line
    assert wheels_late_lines([gps.format(0.10, 0.05), gyro.format(-0.05, 0.05)]) == []       # opposite signs
    assert wheels_late_lines([gps.format(-0.10, 0.02)]) == []
    assert wheels_late_lines([gps.format(-0.10, 0.02) + " or a GPS lever arm ...", gyro.format(-0.1, 0.01)]) == []
