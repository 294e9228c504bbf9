"""Library entry points behind the CLI: every command is a function here.

    from odomgraph.pipeline import estimate, summary
    est = estimate(read_log("LOG"), Method.ekf, Schedule(calibrate_until=20))
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from odomgraph import state as S
from odomgraph.analysis.metrics import nis_summary, nis_warnings, truth_errors
from odomgraph.errors import CalibrationRejectedError, OdomgraphError
from odomgraph.estimators.priorcheck import applied
from odomgraph.estimators.registry import Method, check_option_names, parse_method
from odomgraph.estimators.registry import run as _run
from odomgraph.estimators.schedule import Schedule
from odomgraph.io.log import Log
from odomgraph.result import Estimate, status_of

__all__ = ["Method", "parse_method", "estimate", "summary", "status_of", "warnings_of", "estimate_to_dir",
           "calibrate", "calibrate_to_file", "tune_process_noise"]


def estimate(log: Log, method: Method = Method.ekf, schedule: Schedule = Schedule(), progress=None,
             **options) -> Estimate:
    """Run one estimator over a log. ``progress(done, total)`` is optional.

    ``method`` is a Method or its name. Options are those of the method's
    options dataclass (EKFOptions, SmootherOptions, IncrementalOptions); None
    values mean the default. An unknown method or option is an OptionError.
    """
    method = parse_method(method)
    time_offset = bool(options.pop("time_offset", False))
    fit_noise = bool(options.pop("fit_noise", True))
    check_option_names(options)
    options = {k: v for k, v in options.items() if v is not None}
    from odomgraph.io.log import rebased
    log = rebased(log)  # a real clock's stamps, counted from a whole second (Log.t_origin)
    _refuse_units(log)
    def run(sch: Schedule, prog, lg: Log = log) -> Estimate:
        if time_offset:
            return _with_time_offset(lg, method, sch, prog, {**options, "fit_noise": fit_noise})
        return _estimate_checked(lg, method, sch, prog, options, fit_noise)
    est = _with_window_slip(run(schedule, progress), log, schedule, run, method)
    if not time_offset:
        # (with a clock offset, the run is an estimate() call of its own, checked there)
        est = _with_sideways(est, log, schedule, run, method)
        est = _with_outrun(est, log)
    est = applied(est)   # batch's check of its slip prior, last (priorcheck.applied)
    for e in (est, est.online):
        if e is not None:
            e.t_origin = log.t_origin
    return est


def _absolute_times(log: Log) -> np.ndarray:
    """Sorted times [s] of the log's absolute measurements (fixes on the
    wheels' clock, ranges, body velocities)."""
    from odomgraph.analysis.metrics import gps_times
    ts = [gps_times(log)] if log.gps is not None else []
    ts += [s.t for s in (log.ranges, log.velocity) if s is not None]
    return np.sort(np.concatenate(ts)) if ts else np.zeros(0)


def _refuse_units(log: Log) -> None:
    """LogFormatError (one line, naming gyro.csv) for a gyro in degrees per
    second, or a dead one: no estimate from it is worth writing, as none is
    from stamps in milliseconds (io.log refuses those as it reads them)."""
    from odomgraph.analysis.mounting import unit_refusal
    line = unit_refusal(log)
    if line:
        from odomgraph.errors import LogFormatError
        raise LogFormatError(log.path / "gyro.csv" if log.path is not None else "gyro.csv", line)


def _with_outrun(est: Estimate, log: Log) -> Estimate:
    """``est`` flagged where its rows moved the robot further than its wheels
    turned (analysis.plausible.outrun_stretches: fixes shifted along the
    path, which every estimator follows with a slip no driven wheel makes).
    Flagged only: whether the fixes inside the stretch or those around it
    are off, or the robot skidded, the wheels cannot tell. After the
    sideways check, which runs batch and isam2 again only when nothing
    flagged them before. Only with a position or speed reference: without
    one the ground speed is the wheels' own."""
    from odomgraph.analysis.plausible import outrun_stretches, outrun_warning
    found = outrun_stretches(est, log.robot.track_width) if _has_reference(log) else []
    if found:
        line = outrun_warning(found)
        est.warnings.insert(0, line)
        est.flags.append(line)
    return est


def _with_sideways(est: Estimate, log: Log, schedule: Schedule, run, method: Method) -> Estimate:
    """``est`` flagged when its rows moved the robot sideways
    (analysis.sideways: fixes with a smooth bias, which every estimator
    follows). Batch's and isam2's estimate is first run again, ``run(schedule,
    None, log)``, with the fixes of those stretches held out; when that
    shows them biased and moves nothing sideways, its rows replace the
    first ones, and it is flagged all the same: nothing outside the fixes
    tells which side of the stretch the good ones are on (a probe: a 30 s
    bias seen at its start only had the good fixes before it held out; a
    robot really pushed sideways was taken for a bias, its rows within
    their wide sigma but good fixes lost)."""
    from odomgraph.analysis import sideways, windowfit
    from odomgraph.errors import OdomgraphError
    from odomgraph.estimators.measurements import runs_of
    def chords(e: Estimate):
        if len(e.t) < 3 or (log.encoders is None and log.wheel_speeds is None):
            return None
        from odomgraph.estimators.measurements import clean
        from odomgraph.estimators.shares import Shares
        return Shares(clean(log)[0]).chord_angle(e.t[:-1], e.t[1:])
    found = sideways.stretches(est, chords(est))
    if not found:
        return est

    def flagged() -> Estimate:
        line = sideways.warning(found, fixes=any(src is not None and len(src.t) for src in (log.gps, log.ranges)))
        est.warnings.insert(0, line)
        est.flags.append(line)
        return est
    g = log.gps
    if (method in (Method.ekf, Method.fixed_lag) or g is None or est.flags or est.time_offsets.get("gps")
            or any(windowfit.said(w) for w in est.warnings)):
        # Flagged, not run again:
        # - the EKF (as for the window's slip): its rows are causal; run
        #   without the fixes on a probe's log it came out 2 m off at z 39;
        # - fixed-lag: across a hole longer than its lag its rows come from
        #   the fixes before it alone (2.2 m off at z 8 on a test's log,
        #   against 0.8 m with the bias);
        # - no fixes: none to blame;
        # - flagged already: the cause may not be the fixes (encoder rows
        #   lost with their ticks move it sideways too);
        # - a clock offset or a second look at the window: a run would not repeat them.
        return flagged()

    from odomgraph.analysis.metrics import gps_times
    tg = gps_times(log)              # the rows' clock (a configured [gps] time_offset applied)

    def within(spans) -> np.ndarray:
        """(M,) mask of the fixes inside any of the (start, end) spans [s]."""
        out = np.zeros(len(g.t), bool)
        for a, b in spans:
            out |= (tg >= a) & (tg <= b)
        return out
    pad = sideways.HELD_PAD
    held = within([(a - pad, b + pad) for a, b, _, _ in found])
    if not held.any() or held.sum() > sideways.HELD_MAX * len(g.t):
        return flagged()

    def without(drop):
        """The run on the log without the fixes ``drop`` (None: it failed or
        moved sideways again). Its own flags stay with it: a gap made here
        can flag isam2's causal rows across it (dead-reckoned 0.65 m off at
        4.8 sigma on a probe's log), which is true of them."""
        keep = ~drop
        try:
            e = run(schedule, None, log.with_(gps=replace(
                g, t=g.t[keep], x=g.x[keep], y=g.y[keep], sigma=None if g.sigma is None else g.sigma[keep])))
        except OdomgraphError:
            return None
        return None if sideways.stretches(e, chords(e)) else e

    # Held out, the fixes that sit off the new path by more than their own
    # noise (the rows' sigma there is a dead reckoning's, wide) are the
    # biased ones. A bias that reaches the edge of what was held out goes on
    # past it (a smoother's finding covers where its rows moved most, and a
    # fix kept just past the edge drags the rows held out with it: a probe's
    # isam2 0.6 m off at z 39 so): the edge moves out, three times at most.
    for _ in range(4):
        if held.sum() > sideways.HELD_MAX * len(g.t):
            return flagged()
        alt = without(held)
        if alt is None:
            return flagged()
        scale = alt.noise_scales.get("gps", {}).get("applied", 1.0)
        spans = [(float(tg[i]), float(tg[j])) for i, j in runs_of(held)]
        biased = [(max(a, c), min(b, d)) for a, b in spans
                  for c, d in windowfit.stretches(alt, log, a, b + 1e-9, scale, rows=False)]
        if not biased:
            return flagged()     # (the fixes agree with the wheels: something else moved it sideways)
        # (windowfit widens its stretches by PAD_BEFORE and PAD_AFTER: the
        # biased seconds themselves reach the edge when within 1 s of it)
        grow = within([(a - 2 * pad, a) for a, b in spans
                       if any(c + windowfit.PAD_BEFORE - a < 1.0 for c, d in biased if a <= c <= b)]
                      + [(b, b + 2 * pad) for a, b in spans
                         if any(b - (d - windowfit.PAD_AFTER) < 1.0 for c, d in biased if a <= d <= b)])
        if not (grow & ~held).any():
            break
        held |= grow
    else:
        return flagged()
    # The good fixes of the stretch back in: as precise as the log allows.
    bad = within(biased) & held
    drop = held
    if bad.sum() < held.sum():
        better = without(bad)
        if better is not None:
            alt, drop = better, bad
    # counted as the estimators count: a repeated copy of a fix is no fix
    # (measurements.clean), and fixes outside the rows' span were never offered
    from odomgraph.estimators.measurements import repeated_fixes
    drop = drop & ~repeated_fixes(g) & (tg >= est.t[0]) & (tg <= est.t[-1])
    n = int(drop.sum())
    line = sideways.recovered(found, biased, n)
    alt.rejected["gps"] = alt.rejected.get("gps", 0) + n
    alt.used["gps"] = alt.used.get("gps", 0) + n
    alt.held_out["gps"] = np.sort(np.concatenate([alt.held_out.get("gps", np.zeros(0)), tg[drop]]))
    # Still flagged: nothing outside the fixes can tell which side of the
    # stretch the good fixes are on. A bias that outlasts what was held out
    # leaves the rows after it following it (a probe's 30 s bias: batch
    # 0.63 m off at z 99), and a robot really pushed sideways loses good
    # fixes here (its rows stay within their wide sigma).
    alt.warnings.insert(0, line)
    alt.flags.append(line)
    return alt


def _diverged_in_window(message: str, log: Log, schedule: Schedule) -> bool:
    """Whether a divergence message's time (``at t=...``) lies inside the
    calibration window or a few seconds after it (where a window's wrong
    scale factors show); a message without a time is not (not retried)."""
    import re
    m = re.search(r"at t=(-?[0-9.]+) s", message)
    if m is None:
        return False            # (not a divergence in time: unphysical scale factors, a mounting mistake)
    return float(m.group(1)) < log.t_schedule + schedule.calibrate_until + WINDOW_AFTERMATH


#: What a run again without the calibration window says (_estimate_checked).
RETRIED = "run again with slip estimated throughout"
#: Seconds after the calibration window in which a divergence is blamed on it.
WINDOW_AFTERMATH = 15.0


def _with_window_slip(est: Estimate, log: Log, schedule: Schedule, run, method: Method) -> Estimate:
    """``est``, or when its GPS fixes sat far from it for seconds inside the
    calibration window (analysis.windowfit: both wheels slipped alike, which
    the check before the fit misses), a smoother's estimate ``run(schedule,
    None)`` gives with those seconds out of the window (twice at most: the
    second look may show the rest of a slip), with a warning; a flag if the
    fixes still disagree. The EKF is flagged, not run again: its scale
    states take up part of such a slip while it happens, and its fixes
    disagree only later (a probe: slip at 4-11 s, fixes off at 15-20 s),
    so the seconds it names are not the slip's (run again on them, its
    scale factors came out 50 sigma off)."""
    from odomgraph.analysis import windowfit
    from odomgraph.errors import OdomgraphError
    from odomgraph.estimators.slipcheck import merged
    if est.time_offsets.get("gps"):
        return est              # (its fixes' times are the corrected ones: compared elsewhere)
    if any(RETRIED in f for f in est.flags):
        return est              # (it ran again without the window, and says so)
    t0, t_switch = log.t_schedule, schedule.switch_time(log.t_schedule)

    def found(e):
        return windowfit.stretches(e, log, t0, t_switch, e.noise_scales.get("gps", {}).get("applied", 1.0))
    new = found(est)
    if not new:
        return est
    if method is Method.ekf:
        line = windowfit.ekf_warning(new)
        est.warnings.insert(0, line)
        est.flags.append(line)
        return est
    out, first = list(schedule.slipping), est
    for _ in range(2):
        out = merged(out + new)
        try:
            est = run(replace(schedule, slipping=tuple(out)), None)
        except OdomgraphError as exc:
            line = windowfit.failed_warning(out, exc)
            first.warnings.insert(0, line)
            first.flags.append(line)
            return first
        new = [s for s in found(est) if not any(a <= s[0] and s[1] <= b for a, b in out)]
        if not new:
            break
    line = windowfit.warning(out, resolved=not new)
    est.warnings.insert(0, line)
    if new:
        est.flags.append(line)
    return est


def _estimate_checked(log: Log, method: Method, schedule: Schedule, progress, options: dict,
                      fit_noise: bool) -> Estimate:
    """One estimator run with the checks of ``estimate``: physical scale
    factors, fitted noise scales, prior conflicts, mounting and GPS timing."""
    from odomgraph.analysis.mounting import mounting_warnings
    from odomgraph.errors import EstimatorDivergedError
    motion: dict[str, float] = {}
    rows: dict[str, float] = {}
    if fit_noise:
        from odomgraph.analysis.noise import motion_scales, row_scales, widened_motion, widened_rows
        # the wheel rows' and gyro samples' own noise first: the motion's measure takes it out of the speeds' steps
        rows = row_scales(log)
        log = widened_rows(log, rows)
        motion = motion_scales(log)
        log = widened_motion(log, motion)
    def run(schedule: Schedule, options: dict) -> tuple[Estimate, dict]:
        est = _estimate_once(log, method, schedule, progress, options)
        _check_physical(est)
        est, options, offsets_note = _with_range_offsets(est, log, method, schedule, options)
        if fit_noise:
            est = _with_noise_scales(est, log, method, schedule, options)
        _check_physical(est)
        est.warnings += offsets_note
        return est, options

    retried = None
    options0 = options
    try:
        try:
            est, options = run(schedule, options)
        except EstimatorDivergedError as exc:
            # A wheel that slipped all through the calibration window leaves
            # scale factors the later fixes contradict, and an incremental
            # smoother cannot undo its window's zero-slip priors (a probe's
            # yard log: isam2 and fixed-lag stopped 2 s after a 20 s window
            # that a 0.12 m/s slip filled). Without the window the slip is
            # estimated throughout; the run is flagged either way.
            if (method not in (Method.isam2, Method.fixed_lag, Method.ekf) or not schedule.calibrate_until
                    or (method is Method.ekf and (not _diverged_in_window(str(exc), log, schedule)
                                                  or mounting_warnings(log)))):
                raise
            # (the EKF has no window-free schedule: slip-only, its scale factors stay at their prior)
            free = 0.0 if method is Method.ekf else None
            retried = (f"{exc}; {RETRIED} (no calibration window"
                       + ("; the EKF's scale factors then stay at their prior" if method is Method.ekf else "")
                       + "): if the wheels slipped inside the window, which the schedule takes as slip-free, "
                       "the scale factors it gave were wrong; not trustworthy")
            schedule = replace(schedule, calibrate_until=free)
            est, options = run(schedule, options)
    except EstimatorDivergedError as exc:
        # A mounting mistake is the likeliest cause, and the data can name it;
        # so can a GPS clock off against the wheels (a probe's 2 s late fixes:
        # the EKF stopped where batch ran and named the offset).
        found = mounting_warnings(log)
        if not found and log.gps is not None and not log.robot.gps_time_offset:
            from odomgraph.analysis.timing import gps_offset_warnings
            found = gps_offset_warnings(log, _Nominal())
        if found:
            raise EstimatorDivergedError(f"{exc}; the log shows why: {'; '.join(found)}") from exc
        raise
    bias_walk = None
    if fit_noise and log.gyro is not None and _has_reference(log):
        # The gyro bias wandering far faster than [process] gyro_bias lets the
        # estimate follow (a gyro warming up: the EKF held 81 % of its headings
        # outside 3 sigma, status ok): the walk widened as much, and run again.
        # Only with an absolute reference: without one the bias is the gyro's
        # difference from the wheels, whose own model errors (a skid-steer's
        # scrub) would pass for drift.
        from odomgraph.analysis.noise import BIAS_WIDEN_ABOVE, bias_walk_scale
        q = log.robot.process.gyro_bias
        f = bias_walk_scale(est, q)
        if f is not None and f > BIAS_WIDEN_ABOVE:
            first, log0 = est, log
            log = log.with_(robot=log.robot.with_(process=replace(log.robot.process, gyro_bias=q * f)))
            try:
                est, _ = run(schedule, options0)
                bias_walk = (f, bias_walk_scale(est, q * f))
            except EstimatorDivergedError as exc:
                # the first run stands, with what it left unmended said
                est, log = first, log0
                line = (f"[process] gyro_bias: the estimated gyro bias wanders {f:.2g}x faster than robot.toml's "
                        f"{q:.3g} (rad/s)/sqrt(s) allows, and the run with it widened failed "
                        f"({' '.join(str(exc).split())}): the headings' sigma understate their error")
                est.warnings.append(line)
                est.flags.append(line)
    if retried is not None:
        est.warnings.insert(0, retried)
        est.flags.append(retried)
    from odomgraph.estimators.measurements import repeat_notes, saturation_notes
    est.warnings += [w for w in repeat_notes(log) + saturation_notes(log) if w not in est.warnings]
    from odomgraph.analysis.mounting import dead_encoder_warnings
    from odomgraph.analysis.pathscale import path_scale_warnings
    from odomgraph.observability import few_beacons_warnings
    from odomgraph.analysis.plausible import reversed_motion_warnings, skid_warnings, window_transfer_warnings
    from odomgraph.estimators.standstill import moved_flags
    skid = skid_warnings(est, log.robot.track_width) if _has_reference(log) else []
    # (a wheel's skid says the same of the window, louder: one line a wheel is enough)
    transfer = [w for w in (window_transfer_warnings(est, log.robot.track_width, _absolute_times(log))
                            if _has_reference(log) else [])
                if not any(f"the {side} wheel" in w and f"the {side} wheel" in s for s in skid
                           for side in ("left", "right"))]
    suspect = (_prior_warnings(est, log) + mounting_warnings(log) + dead_encoder_warnings(log)
               + reversed_motion_warnings(est, log.robot.track_width) + skid + transfer
               + path_scale_warnings(est, log)
               + few_beacons_warnings(log, est.warnings)
               + moved_flags(est.warnings))
    if log.gps is not None and not est.time_offsets:
        from odomgraph.analysis.timing import gps_offset_warnings
        suspect += gps_offset_warnings(log, est)
    from odomgraph.analysis.gyrotiming import gyro_offset_warnings, wheels_late_lines, without_reference_clocks
    from odomgraph.analysis.wheelgaps import lost_tick_warnings
    suspect += gyro_offset_warnings(log)
    # both references off alike: the wheels' stamps are, and one line says so in place of theirs
    suspect = without_reference_clocks(suspect + wheels_late_lines(suspect))
    suspect += _gap_warnings(est, log, options) + _revision_warnings(est) + lost_tick_warnings(log)
    # the EKF's innovations (the smoothers keep none): stream says the same of its own
    suspect += nis_warnings(est, rows)
    est.warnings += [w for w in suspect if w not in est.warnings] + _window_warnings(est, log, schedule)
    est.flags += suspect
    _note_motion_scales(est, log, motion)
    _note_row_scales(est, log, rows)
    if bias_walk is not None:
        _note_bias_walk(est, log, *bias_walk)
    return est


def _note_bias_walk(est: Estimate, log: Log, f: float, again: float | None) -> None:
    """Record the gyro-bias walk widened ``f`` times (analysis.noise.
    bias_walk_scale; ``log``: widened) in ``est.noise_scales["gyro_bias"]``,
    with a warning; flagged when the widened run's bias still wanders past
    the threshold (``again``, in units of the widened walk)."""
    from odomgraph.analysis.noise import BIAS_WIDEN_ABOVE
    q = log.robot.process.gyro_bias
    est.noise_scales["gyro_bias"] = {"measured": f, "applied": f}
    est.warnings.append(f"[process] gyro_bias: the estimated gyro bias wanders {f:.2g}x faster than robot.toml's "
                        f"{q / f:.3g} (rad/s)/sqrt(s) allows (a gyro warming up, or a bias that steps): it was "
                        f"widened to {q:.3g} for this run (calibrate writes it back)")
    if again is not None and again > BIAS_WIDEN_ABOVE:
        line = (f"[process] gyro_bias: widened {f:.2g}x, the gyro bias still wanders {again:.2g}x faster than the "
                "walk allows: the headings' sigma understate their error")
        est.warnings.append(line)
        est.flags.append(line)


class _Nominal:
    """What the timing check reads of an estimate (its final scale factors)
    when there is none: the nominal ones."""
    mean = np.ones((1, S.N))


def _gap_warnings(est: Estimate, log: Log, options: dict) -> list[str]:
    """Rows that cannot carry the unknown timing of slip inside a gap in the
    GPS fixes (estimators.gaps; GPS only: a range fixes no point to read a
    prediction against; the whole-log smoothers' rows are widened there
    instead): a filter's (the EKF's, isam2's online.csv) when the
    first fix after the gap finds them far off, fixed-lag's when the gap
    holds more slip than their sigma."""
    if log.gps is None or not len(log.gps.t):
        return []
    from odomgraph.estimators import gaps
    from odomgraph.estimators.measurements import dead_reckoning, from_log
    if est.method == "batch":
        return []
    meas = from_log(log)
    if meas.gps is None or not gaps.gaps(meas.gps[0]):
        return []
    path = dead_reckoning(meas, log.robot.track_width, tuple(est.mean[-1, S.SCALE]))
    lever = log.robot.gps_lever_arm
    out = []
    if est.method == "fixed-lag":
        from odomgraph.estimators.incremental import IncrementalOptions
        out += gaps.unwidened_gap_warnings(est.method, est.t, est.mean, est.sigma, meas.gps[0],
                                           gaps.min_distance(meas.gps[2], log.robot))
        lag = float(options.get("lag", IncrementalOptions().lag))
        out += gaps.gap_end_warnings(est.method, est.t, est.mean, est.pose_cov, meas.gps, lever, path, lag)
    if est.method.startswith("ekf"):
        out += gaps.gap_end_warnings(est.method, est.t, est.mean, est.pose_cov, meas.gps, lever, path)
    if est.online is not None:
        # isam2's causal rows carry no pose covariance: their sigmas, uncorrelated
        o = est.online
        pc = o.pose_cov if o.pose_cov is not None else np.stack([np.diag(v) for v in o.sigma[:, 0:3] ** 2])
        out += gaps.gap_end_warnings(f"{est.method} (online.csv)", o.t, o.mean, pc, meas.gps, lever, path)
    return out


def _revision_warnings(est: Estimate) -> list[str]:
    """Causal rows that jumped further than their sigma allowed
    (analysis.plausible.revision_warnings): the EKF's and fixed-lag's
    states.csv, isam2's online.csv. A smoothed trajectory (batch's, isam2's
    states.csv) is not a sequence of estimates each revised by the next."""
    from odomgraph.analysis.plausible import revision_warnings
    out = []
    if est.method.startswith("ekf") or est.method == "fixed-lag":
        out += revision_warnings(est.method, est.t, est.mean, est.sigma)
    if est.online is not None:
        o = est.online
        out += revision_warnings(f"{est.method} (online.csv)", o.t, o.mean, o.sigma)
    return out


def _has_reference(log: Log) -> bool:
    """The log has an absolute position or speed reference (GPS, ranges or a
    velocity sensor), so the ground speed is not only the wheels' word."""
    return any(x is not None and len(x.t) for x in (log.gps, log.ranges, log.velocity))


def _with_range_offsets(est: Estimate, log: Log, method: Method, schedule: Schedule,
                        options: dict) -> tuple[Estimate, dict, list[str]]:
    """Beacons that read constantly long or short (analysis.rangeoffsets):
    batch runs again with a bias state per beacon, unless the caller chose
    (``range_bias`` given, True or False); the other estimators have none,
    and say so. Returns the estimate, the options the later runs take, and
    the warning (added to the final estimate)."""
    from odomgraph.analysis.rangeoffsets import MIN_BEACONS, offsets_text, range_offsets, significant
    if log.ranges is None or not len(log.ranges.t) or "range_bias" in options:
        return est, options, []
    found = significant(range_offsets(est, log), log.robot.range_sigma)
    if not found:
        return est, options, []
    if method is Method.batch and np.unique(log.ranges.beacon).size >= MIN_BEACONS:
        from odomgraph.errors import EstimatorDivergedError
        try:
            biased = _estimate_once(log, method, schedule, None, {**options, "range_bias": True})
            _check_physical(biased)
        except EstimatorDivergedError as exc:
            # the first fit stands; the offsets are still said
            return est, options, [f"ranges: beacons read constantly off ({offsets_text(found)} after the fit); "
                                  f"a run with a bias per beacon failed ({exc}), so none is estimated"]
        est, options = biased, {**options, "range_bias": True}
        return est, options, [f"ranges: beacons read constantly off ({offsets_text(found)} after a first fit): a "
                              "bias per beacon was estimated for this run (as --range-bias; summary.json "
                              "range_bias)"]
    return est, options, [f"ranges: beacons read constantly off ({offsets_text(found)} after the fit), which "
                          f"{method.value} has no states for: the positions lean towards them; --method batch "
                          "estimates a bias per beacon"]


def _note_motion_scales(est: Estimate, log: Log, motion: dict[str, float]) -> None:
    """Record the velocity random-walk scales (analysis.noise.motion_scales)
    beside the sensors' in ``est.noise_scales``, with a warning for each one
    applied. ``log`` is the widened log the estimate ran on."""
    from odomgraph.analysis.noise import MOTION_WIDEN_ABOVE
    pn = log.robot.process
    for name, f in motion.items():
        applied = f if f > MOTION_WIDEN_ABOVE else 1.0
        est.noise_scales[name] = {"measured": f, "applied": applied}
        if applied > 1.0:
            unit = "m/s" if name == "accel" else "rad/s"
            est.warnings.append(f"[process] {name}: the wheels' own {'speed' if name == 'accel' else 'yaw rate'} "
                                f"wanders {f:.2g}x faster than robot.toml's {getattr(pn, name) / f:.3g} {unit}/sqrt(s) "
                                f"allows: it was widened to {getattr(pn, name):.3g} for this run (calibrate writes "
                                "it back)")


def _note_row_scales(est: Estimate, log: Log, scales: dict[str, float]) -> None:
    """Record the wheel rows' and gyro samples' scatter (analysis.noise.
    row_scales) in ``est.noise_scales["encoders"]`` and ``["gyro"]``, with
    a warning for each one applied. ``log`` is the widened log the estimate
    ran on."""
    from odomgraph.analysis.noise import applied_row_scale
    for sensor, f in scales.items():
        applied = applied_row_scale(sensor, f)
        est.noise_scales[sensor] = {"measured": f, "applied": applied}
        if applied > 1.0:
            est.warnings.append(_row_scale_line(sensor, log, f))


def _row_scale_line(sensor: str, log: Log, f: float) -> str:
    """The warning for a sensor's sigma widened ``f`` times (log: widened)."""
    if sensor == "gyro":
        g = log.robot.gyro_sigma
        return (f"gyro: consecutive samples scatter {f:.2g}x more than robot.toml's [gyro] sigma ({g / f:.3g} "
                f"rad/s) says: it was widened to {g:.3g} rad/s for this run (calibrate writes it back)")
    from odomgraph.analysis.noise import ROW_FACTOR_CAP
    a, b = log.robot.encoder_sigma
    if log.encoders is not None:
        fits = f"{'at least ' if f >= ROW_FACTOR_CAP else ''}{f:.2g}x"
        return (f"encoders: consecutive rows' speeds scatter more than robot.toml's [encoders] sigma "
                f"({a / f:.3g} m/s + {b / f:.3g} |v|) and the ticks' quantisation say: the wheels' noise fits "
                f"{fits} that sigma, and it was widened to ({a:.3g}, {b:.3g}) for this run (calibrate writes "
                "it back)")
    return (f"wheel_speeds: consecutive rows scatter {f:.2g}x more than robot.toml's [encoders] sigma "
            f"({a / f:.3g} m/s + {b / f:.3g} |v|) says (speeds differenced from quantised wheel positions carry "
            f"noise that grows with the rate): it was widened to ({a:.3g}, {b:.3g}) for this run (calibrate "
            "writes it back)")


#: A calibration window with fewer absolute measurements than this calibrates nothing.
MIN_WINDOW_FIXES = 5


def _window_warnings(est: Estimate, log: Log, schedule: Schedule) -> list[str]:
    """A calibration window that is empty or too short to calibrate in (the
    scale factors then stay at their prior, which is not an estimate)."""
    c = schedule.calibrate_until
    if not c:
        return []
    t_end = log.t_schedule + c
    if est.t[0] >= t_end:
        return [f"the calibration window (until t={t_end:.1f} s) ended before the estimator started at "
                f"t={est.t[0]:.1f} s: nothing was calibrated in it; lengthen --calibrate-until"]
    absolute = [s for s in (log.gps, log.ranges, log.velocity) if s is not None and len(s.t)]
    # Without any absolute sensor the window calibrates the ratio and the
    # track against the gyro (the common scale is reported undetermined).
    sensors, what = (absolute, "absolute measurements") if absolute else ([log.gyro], "gyro samples")
    from odomgraph.analysis.metrics import gps_times
    stamps = [gps_times(log) if s is log.gps else s.t for s in sensors if s is not None]
    n = sum(int(np.sum((t >= est.t[0]) & (t < t_end))) for t in stamps)
    if n < MIN_WINDOW_FIXES:
        return [f"the calibration window (t={est.t[0]:.1f}-{t_end:.1f} s) holds only {n} {what}: "
                "too few to calibrate the scale factors in it; lengthen --calibrate-until"]
    return []


#: A scale factor this many prior sigmas from 1 says the prior is wrong.
PRIOR_CONFLICT = 4.0


def _check_physical(est: Estimate) -> None:
    """EstimatorDivergedError when a final scale factor is not physical (as
    the EKF's own check, EKFOptions.max_scale_error): a smoother can settle
    on a track scale below zero (a gyro upside down) and call it converged."""
    from odomgraph.errors import EstimatorDivergedError
    k = est.mean[-1, S.SCALE]
    if k.min() < 0.05 or k.max() > 6.0:
        raise EstimatorDivergedError(f"{est.method}: the scale factors came out {np.round(k, 3).tolist()}, which is "
                                     "not physical (outside 0.05 to 6)")


def _prior_warnings(est: Estimate, log: Log) -> list[str]:
    """A warning when a scale factor lands far outside its prior: the nominal
    parameters are badly off (the libRSF cut as first imported, its track
    halved: scale factors twice nominal against a 5 % prior), and everything
    that rests on the prior (the slip/scale split, the sigmas) deserves
    suspicion. Running again with a wide prior was tried: on that cut it let
    the scale factors run to 10-28, a 30 s range-only log cannot pin them."""
    pn = log.robot.process
    k = est.mean[-1, S.SCALE]
    off = float(np.max(np.abs(k - 1.0)))
    if off <= PRIOR_CONFLICT * pn.initial_scale_sigma:
        return []
    return [f"the scale factors came out up to {off:.0%} from nominal ({np.round(k, 3).tolist()}), far outside "
            f"their prior (sigma {pn.initial_scale_sigma:g}): the nominal parameters are badly off, and the result "
            "leans on a prior that is wrong; run calibrate on a log with good fixes, or widen [process] "
            "initial_scale_sigma"]


def _estimate_once(log: Log, method: Method, schedule: Schedule, progress, options: dict) -> Estimate:
    """One estimate, run again holding what the data barely inform (see estimate)."""
    try:
        est = _run(log, method, schedule, progress, options)
        # A combination the structure allows but the data barely inform (a
        # pure rotation's common scale, say) is still pulled around by the
        # random-walk priors: run again holding it at nominal, so that it
        # keeps its prior value and sigma.
        weak = {k: v for k, v in est.unobservable().items()
                if est.observability is not None and k not in est.observability.unobservable}
        if weak and "pin" not in options:
            est = _run(log, method, schedule, None, {**options, "pin": tuple(weak.items())})
        return est
    except (RuntimeError, ArithmeticError, __import__("numpy").linalg.LinAlgError) as exc:
        # GTSAM's IndeterminateSystemException and LAPACK failures: the log
        # does not constrain the problem well enough for this solver.
        from odomgraph.errors import EstimatorDivergedError
        first = next((ln.strip() for ln in str(exc).splitlines() if ln.strip()), type(exc).__name__)
        raise EstimatorDivergedError(f"{method.value}: the solver failed ({first})") from exc


def _with_noise_scales(est: Estimate, log: Log, method: Method, schedule: Schedule, options: dict) -> Estimate:
    """Widen GPS and range sigmas that the data say are too small, and run
    again (at most twice): every sigma of the estimate inherits them
    (analysis.noise). The scales found and applied go into the result."""
    from odomgraph.analysis.noise import (NARROW_BELOW, NARROW_MIN_COUNT, WIDEN_ABOVE, WIDEN_FLAG_ABOVE,
                                          correlation_factors, floored,
                                          gps_sigma_floor, measured_count, measured_from, noise_scales, widened)
    applied: dict[str, float] = {}
    cur = log
    floor_note = []
    fl = gps_sigma_floor(est, cur)
    if fl is not None:
        # Per-fix sigmas off by more than one factor: the floor first, then
        # the usual scale on top (1 when the floor explains the scatter).
        g = cur.gps.sigma
        cur = floored(cur, *fl)
        est = _estimate_once(cur, method, schedule, None, options)
        floor_note = [f"gps: the fixes' own sigmas ({np.quantile(g, 0.1):.3g}-{np.quantile(g, 0.9):.3g} m) are not "
                      f"off by one factor: their scatter fits sqrt(({fl[0]:.2g} sigma)^2 + ({fl[1]:.3g} m)^2), "
                      "which this run used (robot.toml cannot hold it: its gps sigma is used only where gps.csv "
                      "has none)"]
    measured = noise_scales(est, cur)
    first = est
    # Persistence is credited once, on the first pass: the passes after it
    # measure the scatter against the sigma it widened (analysis.noise). It
    # multiplies the scatter, not the configured sigma: a generous sigma (the
    # OptiOdom mocap's, 5-20 % of it scattered) already covers persistent
    # errors that small.
    corr = correlation_factors(est, cur)
    scales = {k: v * corr.get(k, (0.0, 1.0))[1] for k, v in measured.items()}
    for _ in range(2):
        act = {k: v for k, v in scales.items() if v > WIDEN_ABOVE}
        if not act:
            break
        for k, v in act.items():
            applied[k] = applied.get(k, 1.0) * v
        cur = widened(cur, act)
        est = _estimate_once(cur, method, schedule, None, options)
        scales = noise_scales(est, cur)
    source = {k: measured_from(first, k) for k in measured}
    est.noise_scales = {k: {"measured": v, "correlation": corr.get(k, (0.0, 1.0))[0],
                            "applied": applied.get(k, 1.0), "from": source[k]} for k, v in measured.items()}
    if fl is not None:
        est.noise_scales.setdefault("gps", {"measured": 1.0, "correlation": 0.0, "applied": 1.0}).update(
            floor_factor=fl[0], floor_m=fl[1])
    est.warnings += floor_note
    for k, f in applied.items():
        if f > WIDEN_FLAG_ABOVE:
            # No sigma is set that wrong by accident as often as an estimate
            # fails to follow its fixes: a probe's fixed-lag at 0.5 Hz
            # keyframes through big slips, 45 m off with its fixes' sigma
            # widened 300x (z 4.4, 82 % inside 3 sigma), status ok.
            what = "fixes" if k == "gps" else "ranges"
            line = (f"{k}: the {what} scattered {f:.0f}x their sigma about the estimate, which then widened it "
                    f"as much: an estimate that did not follow them, or a sigma far off; not trustworthy (check "
                    "the sigma; try --method batch, or a higher --keyframe-hz)")
            est.warnings.insert(0, line)
            est.flags.append(line)
    per_fix = log.gps is not None and log.gps.sigma is not None
    for k, f in applied.items():
        conf = log.robot.gps_sigma if k == "gps" else log.robot.range_sigma
        if k == "gps" and per_fix:
            # the sigmas in force are the fixes' own (LOG_FORMAT): quote those
            why = (f"the data scatter {measured[k]:.2g}x more than the fixes' own sigmas (median "
                   f"{float(np.median(log.gps.sigma)):.3g} m{', with the floor above' if fl else ''}) say"
                   + (f", and their errors persist from one measurement to the next (lag-1 correlation "
                      f"{corr.get(k, (0.0, 1.0))[0]:.2f}, worth {corr.get(k, (0.0, 1.0))[1]:.2g}x)"
                      if corr.get(k, (0.0, 1.0))[1] > 1.0 else ""))
            if source[k] == "predictions":
                why += " (measured against the filter's predicted path: not the sensor's noise alone)"
            est.warnings.append(f"gps: {why}: every fix's sigma was widened {f:.2g}x for this run (calibrate "
                                "cannot write it: robot.toml's gps sigma is used only where gps.csv has none)")
            continue
        rho, cf = corr.get(k, (0.0, 1.0))
        why = ((f"the data scatter {measured[k]:.2g}x more than robot.toml's sigma ({conf:.3g} m) says"
                if measured[k] > 1.0 else f"the data scatter within robot.toml's sigma ({conf:.3g} m; "
                                          f"{measured[k]:.2g}x)")
               + (f", and their errors persist from one measurement to the next (lag-1 correlation {rho:.2f}, "
                  f"worth {cf:.2g}x)" if cf > 1.0 else ""))
        if source[k] == "predictions":
            # (analysis.noise.measured_from: the fixes against the filter's path, not the sensor's noise)
            n = first.innovations[k].nis.size if k in first.innovations else 0
            est.warnings.append(
                f"{k}: measured against the filter's predicted path ({n} accepted updates are too few to tell the "
                f"sensor's noise from the prediction's), {why}: the sigma was widened {f:.2g}x to {conf * f:.3g} m "
                "for this run; calibrate does not write it back (--method batch measures the sensor)")
            continue
        est.warnings.append(f"{k}: {why}: the sigma was widened {f:.2g}x to {conf * f:.3g} m for this run "
                            "(calibrate writes it back)")
    for k, v in measured.items():
        # A sigma too large is not a wrong answer with a tight sigma, but the
        # estimate's sigmas are then pessimistic and the fixes weigh too
        # little against the wheels; and calibrate's process-noise tuning
        # made up for it at its grid's edge (a probe: 10x too large, x40).
        # Said, not narrowed: a filter's predictions (measured_from) are no
        # measure of it, and a narrower sigma is a bet the log cannot undo.
        # The scale with persistence credited, as the widening takes it:
        # errors that persist from one fix to the next scatter little about
        # an estimate that follows them (AR(1) errors at a right sigma
        # measured 0.09-0.27, and those estimates were over-confident, a
        # second read). Nor from few measurements (NARROW_MIN_COUNT).
        v = v * corr.get(k, (0.0, 1.0))[1]
        if v >= NARROW_BELOW or k in applied or source[k] == "predictions" or (k == "gps" and fl is not None):
            continue
        count = measured_count(first, cur, k)
        if count < NARROW_MIN_COUNT:
            continue
        own = k == "gps" and per_fix
        conf = (f"the fixes' own sigmas (median {float(np.median(log.gps.sigma)):.3g} m)" if own else
                f"robot.toml's sigma ({log.robot.gps_sigma if k == 'gps' else log.robot.range_sigma:.3g} m)")
        what = "fixes" if k == "gps" else "ranges"
        if source[k] == "innovations":
            # a filter's innovation carries its prediction's spread too: a
            # process noise 400x the default read the same
            est.warnings.append(
                f"{k}: the {what} scatter only {v:.2g}x of what {conf} and the filter's predicted spread say "
                f"({count} updates): the sigma, or the process noise, looks {1 / max(v, 1e-9):.2g}x too large, so "
                f"this estimate's sigmas are pessimistic and the {what} count for less than they should; not changed")
        else:
            est.warnings.append(
                f"{k}: the {what} scatter only {v:.2g}x of {conf} about the estimate ({count} of them): it looks "
                f"{1 / max(v, 1e-9):.2g}x too large, so this estimate's sigmas are pessimistic and the {what} count "
                f"for less than they should; not changed (set {'the sigma in gps.csv' if own else 'it in robot.toml'})")
    return est


def _with_time_offset(log: Log, method: Method, schedule: Schedule, progress, options: dict) -> Estimate:
    """``estimate`` with the GPS time offset estimated (--time-offset).

    The offset is measured against the wheels (analysis.timing) with the
    nominal parameters, the log re-stamped, the estimator run, and the offset
    measured again with the estimated scale factors; if that moves it by more
    than its sigma, the estimator runs once more. The result carries the
    offset with its sigma (``Estimate.time_offsets``)."""
    from odomgraph.analysis.timing import gps_offset
    from odomgraph.errors import NotEnoughDataError
    if log.gps is None:
        raise NotEnoughDataError("--time-offset: the log has no GPS to measure a time offset of")
    total, sigma = log.robot.gps_time_offset, None
    scales = (1.0, 1.0, 1.0)
    est = first = None
    for _ in range(4):
        o = gps_offset(log.with_(robot=log.robot.with_(gps_time_offset=total)), scales)
        if o is None and est is None and first is None:
            # Wheels a few percent off nominal bend the path enough that the
            # offset cannot be told from them: measure with the estimated ones.
            # (the smoothers' slip prior unchecked: a prior-free path takes a late clock for slip, and its
            # scale factors then hide the offset; a paper log 0.3 s late gave no offset at all)
            first = estimate(log, method, schedule, progress,
                             **(options if method is Method.ekf else {**options, "slip_check": False}))
            scales = tuple(float(v) for v in first.mean[-1, S.SCALE])
            continue
        if o is None:
            break
        total, sigma = total + o.delta, o.sigma
        if est is not None and abs(o.delta) <= o.sigma:
            break
        est = estimate(log.with_(robot=log.robot.with_(gps_time_offset=total)), method, schedule, progress,
                       **options)
        scales = tuple(float(v) for v in est.mean[-1, S.SCALE])
    if est is None:
        est = first if first is not None else estimate(log, method, schedule, progress, **options)
        est.warnings.append("--time-offset: too little motion to measure the GPS time offset; none applied")
        return est
    est.time_offsets = {"gps": {"value": float(total), "sigma": float(sigma)}}
    est.notes.append(f"GPS time offset estimated at {total:+.3f} +- {sigma:.3f} s and applied")
    return est


def warnings_of(est: Estimate, log: Log | None = None) -> list[str]:
    """Everything the user must know to trust ``est``, one line each: the
    estimator's own warnings (with those ``estimate`` adds: mounting
    mistakes, a GPS clock off against the wheels, a prior in conflict),
    rejections and recoveries, and each scale combination the log does not
    determine."""
    out = list(est.warnings)
    for s, n in est.rejected.items():
        used = est.used.get(s)
        of = f" of {used}" if used else ""
        out.append(f"{s}: {n}{of} measurements rejected as outliers")
    for r in est.recoveries:
        out.append(f"{est.method} recovered at {r}")
    for r in est.departures:
        out.append(f"{est.method} followed a departure at {r}")
    unobs = est.unobservable()
    pinned = est.observability.unobservable if est.observability else {}
    for name, reason in unobs.items():
        held = " (held at nominal, reported with its prior sigma)" if name in pinned else ""
        out.append(f"{name} is not determined by this log{held}: {reason}")
    if "scale_common" in pinned and len(pinned) < 3:
        rest = [n for n in ("scale_ratio", "scale_track") if n not in unobs]
        if rest:
            out.append(f"{' and '.join(rest)} {'is' if len(rest) == 1 else 'are'} estimated relative to the nominal "
                       "common wheel scale "
                       "(summary.json scale_combinations)")
    return out


def summary(est: Estimate, log: Log, schedule: Schedule) -> dict:
    """summary.json content (LOG_FORMAT.md plus consistency and throughput)."""
    from odomgraph.observability import combinations_of
    from odomgraph.io.log import rebased
    log = rebased(log)  # on est's clock (Log.t_origin)
    pinned = est.observability.unobservable if est.observability else {}
    out = {
        "method": est.method,
        "log": str(log.path) if log.path else None,
        "n_steps": int(len(est.t)),
        # every time below counts seconds from this whole second of the log's clock
        "t_origin": est.t_origin,
        "wall_time_s": est.wall_time_s,
        "n_updates": est.n_updates,
        "updates_per_second": est.n_updates / est.wall_time_s if est.wall_time_s > 0 else None,
        "schedule": {"calibrate_until": schedule.calibrate_until, "hold": schedule.hold.value,
                     "t_switch": est.t_switch},
        "calibration": est.calibration,
        "unobservable": est.unobservable(),
        # (common, right/left ratio, track) with their sigma as the estimator
        # solved them: with unobservable combinations held at nominal.
        "scale_combinations": {n: {**c, **({"held_at_nominal": True} if n in pinned else {})} for n, c in
                               combinations_of(est.mean[-1, S.SCALE], est.scale_cov(given=True)).items()},
        **({"range_bias": est.range_bias} if est.range_bias is not None else {}),
        "nis": nis_summary(est),
        "status": status_of(est)[0],
        "status_reasons": status_of(est)[1],
        "rejected": est.rejected,
        "downweighted": est.downweighted,
        "used": est.used,
        "recoveries": est.recoveries,
        "departures": est.departures,
        **({"time_offsets": est.time_offsets} if est.time_offsets else {}),
        "noise_scales": est.noise_scales,
        "warnings": list(log.warnings) + warnings_of(est, log),
        "notes": est.notes,
        **({"import": {k: log.provenance[k] for k in ("importer", "source", "odomgraph") if k in log.provenance}}
           if log.provenance else {}),
    }
    if est.update_times is not None and len(est.update_times) >= 10:
        ut = est.update_times
        q = max(1, len(ut) // 10)
        out["update_time_ms"] = {"mean": 1e3 * float(ut.mean()), "first_10pct": 1e3 * float(ut[:q].mean()),
                                 "last_10pct": 1e3 * float(ut[-q:].mean()), "max": 1e3 * float(ut.max())}
    err = truth_errors(est, log)
    if err is not None:
        out["errors"] = err.as_dict()
        if est.online is not None:
            from dataclasses import replace
            online_err = truth_errors(replace(est.online, t_switch=est.t_switch), log)
            out["errors_online"] = online_err.as_dict()
        if log.truth_scales is not None:
            out["truth_scales"] = dict(zip(("scale_left", "scale_right", "scale_track"), log.truth_scales))
    return out


def estimate_to_dir(log: Log, out: Path, method: Method, schedule: Schedule, progress=None, rate: float | None = None,
                    at: str | None = None, **options) -> dict:
    """Estimate and write the estimate directory; returns the summary.

    The output is checked before the work starts (io.outdir): it must not be,
    hold or lie inside the log. ``rate`` [Hz] or ``at`` ("truth" or "gps")
    writes the rows at regular or at those sensors' times (analysis.resample,
    for evo); summary.json scores the estimator's own rows either way. A log
    with truth gets truth.tum beside trajectory.tum."""
    from odomgraph.io.estimate import truth_tum_text, write_estimate
    from odomgraph.io.log import rebased
    from odomgraph.io.outdir import check_output
    inputs = (log.path,) if log.path else ()
    check_output(out, inputs)
    if rate is not None and at is not None:
        raise OdomgraphError("give --rate or --at, not both")
    if log.truth is not None:
        log.truth.values    # scored at the end: a bad truth.csv is said now, not after the run
    log = rebased(log)
    if at is not None:
        src = {"truth": log.truth, "gps": log.gps}.get(at, "bad")
        if src == "bad":
            raise OdomgraphError(f"--at must be truth or gps, got {at!r}")
        if src is None or not len(src.t):
            raise OdomgraphError(f"--at {at}: the log has no {at}")
    if rate is not None and not rate > 0:
        raise OdomgraphError(f"--rate must be a positive number of Hz, got {rate!r}")
    est = estimate(log, method, schedule, progress, **options)
    summ = summary(est, log, schedule)
    rows = est
    if rate is not None or at is not None:
        from odomgraph.analysis.resample import regular_times, resampled
        times = regular_times(est, rate) if rate is not None else src.t
        from dataclasses import replace
        rows = replace(resampled(est, times, log), online=est.online)  # online.csv stays the causal estimate
        summ["rows"] = {"rate_hz": rate} if rate is not None else {"at": at}
        summ["rows"]["n"] = int(len(rows.t))
        rows_err = truth_errors(rows, log)
        if rows_err is not None:
            # what evo computes from trajectory.tum and truth.tum
            summ["rows"]["rms_position_m"] = rows_err.rms_position_m
    truth = None
    if log.truth is not None and "theta" in log.truth.values:
        tr = log.truth
        truth = truth_tum_text(tr.t, tr.values["x"], tr.values["y"], tr.values["theta"], log.t_origin)
    write_estimate(rows, out, summ, inputs, truth_tum=truth)
    return summ


#: Multipliers of the default velocity process noise (ProcessNoise accel, yaw_accel)
#: that ``tune_process_noise`` tries.
PROCESS_NOISE_FACTORS = (1.0, 2.5, 5.0, 10.0, 20.0, 40.0)


def _split_fixes(log: Log):
    """(log with every other absolute fix, the held-out fixes as a log) or None.

    GPS fixes if the log has them, else ranges."""
    import numpy as np
    from odomgraph.io.log import Gps, Ranges
    if log.gps is not None and len(log.gps.t) >= 20:
        g = log.gps
        keep = np.arange(len(g.t)) % 2 == 0
        part = lambda m: Gps(g.t[m], g.x[m], g.y[m], None if g.sigma is None else g.sigma[m])
        return log.with_(gps=part(keep)), log.with_(gps=part(~keep), ranges=None)
    if log.ranges is not None and len(log.ranges.t) >= 20:
        r = log.ranges
        keep = np.arange(len(r.t)) % 2 == 0
        part = lambda m: Ranges(r.t[m], r.beacon[m], r.range[m])
        return log.with_(ranges=part(keep)), log.with_(ranges=part(~keep), gps=None)
    return None


def tune_process_noise(log: Log, schedule: Schedule, method: Method = Method.batch, progress=None, **options):
    """Choose the velocity process noise by predicting held-out fixes.

    The velocity random walk is a prior, and a wrong one biases calibration: a
    small robot that starts and stops pivots within one encoder period makes
    the default prior resist each jump, and the cheapest way to resist is to
    shrink every velocity through the scale factors (on OptiOdom's square run
    the track came out 11 % high). Here every other fix (GPS, else range) is
    held out; for each multiplier in PROCESS_NOISE_FACTORS of the default
    (accel, yaw_accel) the estimator runs on the rest, and the one whose path
    best predicts the held-out fixes wins (2-fold would double the cost for
    little: the held-out fixes interleave with the used ones), if it beats
    the lowest candidate that ran beyond chance (_beats); else the lowest
    does. When every candidate of a filter misses the held-out fixes by
    PROCESS_NOISE_LOST of their sigmas or more (the sigmas the runs used,
    after the noise model's widening: _sigma_used), the filter is lost on
    them and nothing is tuned: robot.toml's process noise is kept.

    Returns (ProcessNoise, table of (factor, held-out RMS [m], the
    ProcessNoise that ran), lost: the best held-out RMS [m] when nothing was
    tuned for it, else None), or (log.robot.process, [], None) when the log
    has too few fixes. A candidate below the wheels' own motion intensity
    (analysis.noise.motion_scales) runs with that intensity instead, for
    accel and yaw_accel each; candidates that come out identical run once,
    under the lowest factor.
    """
    import numpy as np
    from dataclasses import replace
    from odomgraph.analysis.metrics import gps_deviation, range_residuals
    from odomgraph.errors import EstimatorDivergedError
    from odomgraph.io.robot import ProcessNoise
    split = _split_fixes(log)
    base = log.robot.process
    if split is None:
        return base, [], None
    train, held = split
    d = ProcessNoise()
    # A candidate below the wheels' own intensity would be widened to it by
    # estimate (analysis.noise.motion_scales): floor the candidates there, so
    # that the table holds the intensities that actually ran.
    floor = base
    if options.get("fit_noise", True):
        from odomgraph.analysis.noise import motion_scales, row_scales, widened_motion, widened_rows
        # measured as estimate measures it: after the wheels' and the gyro's own scatter is widened
        wl = widened_rows(log, row_scales(log))
        floor = widened_motion(wl, motion_scales(wl)).robot.process
    sensor = "gps" if held.gps is not None else "ranges"
    table, tried, errors, used = [], set(), [], []
    for j, f in enumerate(PROCESS_NOISE_FACTORS):
        pn = replace(base, accel=max(d.accel * f, floor.accel), yaw_accel=max(d.yaw_accel * f, floor.yaw_accel))
        if (pn.accel, pn.yaw_accel) in tried:
            continue
        tried.add((pn.accel, pn.yaw_accel))
        try:
            est = estimate(train.with_(robot=train.robot.with_(process=pn)), method, schedule, **options)
        except EstimatorDivergedError:
            continue
        res = gps_deviation(est, held) if sensor == "gps" else range_residuals(est, held)
        table.append((f, float(np.sqrt(np.mean(res[1] ** 2))), pn))
        errors.append(res)
        used.append(_sigma_used(held, sensor, est) if est.innovations else np.inf)
        if progress is not None:
            progress(j + 1, len(PROCESS_NOISE_FACTORS) + 1)
    if not table:
        return base, [], None
    b = min(range(len(table)), key=lambda i: table[i][1])
    if table[b][1] >= PROCESS_NOISE_LOST * used[b]:
        return base, table, table[b][1]
    return table[b if b > 0 and _beats(errors[b], errors[0]) else 0][2], table, None


#: Held-out errors this many fix sigmas away, for every candidate, say the
#: estimator is lost on them: no candidate is better, all are bad.
PROCESS_NOISE_LOST = 50.0


def _sigma_used(log: Log, sensor: str, est: Estimate) -> float:
    """The sigma [m] a run ``est`` gave ``sensor``'s measurements in ``log``:
    the fixes' median own sigma, else robot.toml's, times the noise model's
    widening where it measured the sensor (not a filter's predictions:
    analysis.noise.measured_from). An EKF on every other 0.2 Hz fix missed
    them by 6.5-8.5 m for every candidate, and calibrate wrote 20-40x the
    default for 3-12 % less. Only a filter's runs are judged so: a
    smoother's post-fit residuals measure a sigma low (configured 100x too
    small, batch measured 1.8x and then followed every fix), and its held-out
    errors are then hundreds of sigmas without its being lost."""
    if sensor == "gps":
        g = log.gps
        sig = float(np.median(g.sigma)) if g.sigma is not None else log.robot.gps_sigma
    else:
        sig = log.robot.range_sigma
    ns = est.noise_scales.get(sensor, {})
    return sig * (ns.get("applied", 1.0) if ns.get("from") != "predictions" else 1.0)


#: A candidate replaces the lowest that ran only when its held-out squared
#: errors are smaller by this many standard errors of their paired mean.
PROCESS_NOISE_Z = 2.0


def _beats(a, b) -> bool:
    """Whether held-out residuals ``a`` (t (M,), residual (M,)) are smaller
    than ``b``'s beyond chance: the mean of the paired differences of their
    squares below -PROCESS_NOISE_Z standard errors. Without it calibrate
    wrote 10x the default process noise for held-out errors of 752 cm
    against 762 cm (an EKF on 0.1 Hz fixes: every candidate was as bad)."""
    if np.array_equal(a[0], b[0]):
        d = a[1] ** 2 - b[1] ** 2          # (ranges share stamps across beacons: pair by row)
    else:
        _, ia, ib = np.intersect1d(a[0], b[0], return_indices=True)
        d = a[1][ia] ** 2 - b[1][ib] ** 2
    if d.size < 3:
        return False
    return float(d.mean()) < -PROCESS_NOISE_Z * float(d.std(ddof=1)) / np.sqrt(d.size)


def calibrate(log: Log, schedule: Schedule = Schedule(calibrate_until=None), method: Method = Method.batch,
              progress=None, tune: bool = True, **options):
    """Calibrated robot parameters from a calibration log.

    Runs the smoother (by default with a sparse slip prior over the whole log)
    and turns its scale factors into corrected ticks per metre and track width
    (LOG_FORMAT: true = scale x nominal). With ``tune`` the velocity process
    noise is first chosen from the data (``tune_process_noise``) and kept in
    the returned robot. Returns (RobotConfig, report dict): the report holds
    the parameters with their 1-sigma and, when the log has truth, how dead
    reckoning on this log changes with the new parameters.
    """
    from odomgraph.io.log import rebased
    log = rebased(log)  # Log.t_origin
    from odomgraph.analysis.deadreckoning import dead_reckon
    table, lost = [], None
    if tune:
        process, table, lost = tune_process_noise(log, schedule, method, progress, **options)
        log = log.with_(robot=log.robot.with_(process=process))
    est = estimate(log, method, schedule, progress, **options)
    gyro = None
    if log.gyro is not None and len(log.gyro.t):
        gyro = _gyro_scale(log, est, schedule, options)
        if gyro["corrected"]:
            from odomgraph.analysis.gyroscale import rescaled
            log = rescaled(log, gyro["value"])
            est = estimate(log, method, schedule, None, **options)
    cal = est.calibration
    r = log.robot
    k = [cal[n]["value"] for n in ("scale_left", "scale_right", "scale_track")]
    sk = [cal[n]["sigma"] for n in ("scale_left", "scale_right", "scale_track")]
    if gyro is not None:
        # the consider term: what the gyro scale's own uncertainty does to each scale factor
        sk = [float(np.hypot(s, j * gyro["sigma"])) for s, j in zip(sk, gyro["sensitivity"])]
    new = r.with_(ticks_per_meter_left=k[0] * r.ticks_per_meter_left,
                  ticks_per_meter_right=k[1] * r.ticks_per_meter_right,
                  track_width=k[2] * r.track_width)
    report = {
        "method": est.method,
        "scale": dict(zip(("left", "right", "track"), k)),
        "ticks_per_meter_left": {"value": new.ticks_per_meter_left, "sigma": sk[0] * r.ticks_per_meter_left},
        "ticks_per_meter_right": {"value": new.ticks_per_meter_right, "sigma": sk[1] * r.ticks_per_meter_right},
        "track_width": {"value": new.track_width, "sigma": sk[2] * r.track_width},
        "process_noise": {"accel": r.process.accel, "yaw_accel": r.process.yaw_accel,
                          "held_out_rms_m": [{"factor": f, "rms_m": e, "accel": p.accel, "yaw_accel": p.yaw_accel}
                                             for f, e, p in table],
                          "chosen_factor": next((f for f, _, p in table if p == r.process), None),
                          "lost_m": lost},
    }
    # Dead reckoning on this log, against truth or else the smoother's own path.
    start = (est.t[0], *est.mean[0, 0:3])
    if log.truth is not None:
        ref = lambda t: (log.truth.at("x", t), log.truth.at("y", t))
    else:
        ref = lambda t: (np.interp(t, est.t, est.mean[:, S.X]), np.interp(t, est.t, est.mean[:, S.Y]))
    for name, sc in (("nominal", (1.0, 1.0, 1.0)), ("calibrated", k)):
        t, p = dead_reckon(log, sc, start)
        rx, ry = ref(t)
        e = np.hypot(p[:, 0] - rx, p[:, 1] - ry)
        report[f"dead_reckoning_{name}"] = {"rms_m": float(np.sqrt(np.mean(e**2))), "final_m": float(e[-1])}
    report["reference"] = "truth" if log.truth is not None else "smoothed estimate"
    report.update(_calibration_checks(log, est, k, sk, method, schedule, options))
    # what reading the log said (rows read once, an import's warnings: Log.warnings) comes first
    report["warnings"][:0] = list(log.warnings)
    if gyro is not None:
        report["gyro_scale"] = {n: gyro[n] for n in ("value", "sigma", "determined", "corrected")}
        if gyro["line"]:
            report["warnings"].append(gyro["line"])
    if lost is not None:
        report["warnings"].append(
            f"process noise not tuned: with every other fix held out, every candidate's estimate missed them by "
            f"{lost:.3g} m RMS or more, over {PROCESS_NOISE_LOST:g} of the sigmas it gave them: {est.method} does "
            "not follow this log's fixes, so none is better; robot.toml's process noise is kept")
    top = PROCESS_NOISE_FACTORS[-1]
    if report["process_noise"]["chosen_factor"] == top:
        # The grid's edge: the held-out fixes favour more still, which a
        # velocity walk rarely needs; a fix sigma set too large did this (a
        # probe: 10x too large, x40 with the EKF), and so did errors that
        # persist from fix to fix (AR(1), a second read: the held-out fixes
        # share their neighbours' error, and the path that follows them wins).
        report["warnings"].append(
            f"process noise chosen at the top of the range tried (x{top:g} the default): the held-out fixes "
            "favour more still; a GPS or range sigma set too large, errors that persist from one fix to the next "
            "(multipath, a marker that slid), or motion a velocity random walk does not model (jerks, impacts) "
            "does this; the value written is the grid's edge, not a fit")
    per_fix = log.gps is not None and log.gps.sigma is not None
    new = _with_fitted_noise(new, est, report["warnings"], per_fix_gps=per_fix)
    # what is written, after the data's widening (the tuned value is its floor)
    report["process_noise"].update(accel=new.process.accel, yaw_accel=new.process.yaw_accel)
    if est.time_offsets.get("gps"):
        new = new.with_(gps_time_offset=est.time_offsets["gps"]["value"])
        report["time_offsets"] = est.time_offsets
    report["noise_scales"] = est.noise_scales
    return new, report


#: A calibrated scale factor this far from 1 is flagged as implausible.
IMPLAUSIBLE = 0.10


def _gyro_scale(log: Log, est: Estimate, schedule: Schedule, options: dict) -> dict:
    """The gyro's scale factor from the fixes, by its profile likelihood
    (analysis.gyroscale): batch runs with the gyro divided by 1 - STEP, 1,
    1 + STEP, on the noise model ``est`` fitted. Returns {"value", "sigma",
    "determined", "corrected", "sensitivity" (3,) d scale / d g, "line"}."""
    from odomgraph.analysis import gyroscale as G
    from odomgraph.analysis.noise import widened, widened_rows
    # (not a filter's widening from its predictions: it is the run's, not the sensor's; analysis.noise.measured_from)
    fitted = widened(log, {k: v["applied"] for k, v in est.noise_scales.items() if v.get("from") != "predictions"})
    # and the wheels' and gyro's own scatter (a second read: the profile ran them at the narrow sigma)
    fitted = widened_rows(fitted, {k: est.noise_scales.get(k, {}).get("applied") for k in ("encoders", "gyro")})
    if est.time_offsets.get("gps"):
        # the GPS clock the run estimated (a clock off moves the fixes along the path: every turn with it)
        fitted = fitted.with_(robot=fitted.robot.with_(gps_time_offset=est.time_offsets["gps"]["value"]))
    from dataclasses import fields
    from odomgraph.estimators.batch import BatchGraphOptions
    opts = {k: v for k, v in options.items() if k in {f.name for f in fields(BatchGraphOptions)}}
    gs, costs, scales = [], [], {}

    def profile(g):
        run = _estimate_once(G.rescaled(fitted, g), Method.batch, schedule, None, opts)
        gs.append(g)
        costs.append(run.cost)
        scales[g] = run.mean[-1, S.SCALE].copy()
    try:
        for g in (1.0 - G.STEP, 1.0, 1.0 + G.STEP):
            profile(g)
    except OdomgraphError as exc:
        # Not measured, so derived: the track fitted against a gyro that
        # reads g times the rate is the true track over g, so |d scale_track
        # / d g| = 1 at g = 1 (the sign does not matter to a consider term),
        # and the wheels' scales, fitted against the fixes' distance, do not
        # depend on g.
        return {"value": 1.0, "sigma": G.PRIOR, "determined": False, "corrected": False,
                "sensitivity": [0.0, 0.0, 1.0],
                "line": f"the gyro's scale factor could not be profiled ({' '.join(str(exc).split())}): "
                        f"{G.unknown_note(G.PRIOR)}"}
    sens = (scales[1.0 + G.STEP] - scales[1.0 - G.STEP]) / (2.0 * G.STEP)
    has_fixes = any(s is not None and len(s.t) for s in (log.gps, log.ranges))
    fit = G.fit_profile(np.asarray(gs), np.asarray(costs)) if has_fixes else None
    if fit is not None and G.STEP < abs(fit[0] - 1.0) <= G.MAX_OFF:
        # far from the stencil: one more run at the estimate, and the parabola through all four
        try:
            profile(fit[0])
            fit = G.fit_profile(np.asarray(gs), np.asarray(costs))
        except OdomgraphError:
            pass
    if fit is not None and abs(fit[0] - 1.0) > G.MAX_OFF:
        fit = None              # no scale error: a unit or mounting mistake (analysis.mounting says which)
    if fit is None:
        return {"value": 1.0, "sigma": G.PRIOR, "determined": False, "corrected": False,
                "sensitivity": [float(v) for v in sens], "line": G.unknown_note(G.PRIOR)}
    g_hat, sigma = fit
    corrected = G.significant(g_hat, sigma)
    return {"value": g_hat, "sigma": sigma, "determined": True, "corrected": corrected,
            "sensitivity": [float(v) for v in sens], "line": G.warning(g_hat, sigma) if corrected else ""}


def _calibration_checks(log: Log, est: Estimate, k, sk, method: Method, schedule: Schedule, options: dict) -> dict:
    """What ``calibrate`` must know before it writes: {"warnings": [...],
    "unobservable": {name: reason}, "held_out": {...} or None,
    "problems": [...]} (a non-empty "problems" means: do not write).

    The parameters are fitted again on the first part of the log and scored
    on the rest against the nominal ones (analysis.holdout). A fit that
    agrees with nominal within 2 sigma passes without a contest (the scores
    then differ by noise only)."""
    from odomgraph.analysis.holdout import held_out, slip_spans, split_time
    from odomgraph.analysis.mounting import mounting_warnings
    warnings = warnings_of(est, log)
    if est.time_offsets.get("gps"):
        log = log.with_(robot=log.robot.with_(gps_time_offset=est.time_offsets["gps"]["value"]))
    problems = [w for w in mounting_warnings(log)]
    if log.gps is not None and not est.time_offsets:
        # A GPS clock off against the wheels biases every scale factor (0.5 s
        # early gave 14-21 sigma): refuse rather than write it.
        from odomgraph.analysis.timing import gps_offset_warnings
        # A plain clock line gets the option that estimates it; a lever-arm
        # line, or one that cannot tell the two apart, names its own remedy.
        # Unless the gyro looks off alike: then the wheels' stamps are, estimate's flags say so
        # (gyrotiming.wheels_late_lines), and the GPS's own line would mislead.
        from odomgraph.analysis.gyrotiming import WHEELS_LATE
        wheels_late = any(w.startswith(WHEELS_LATE) for w in est.flags)
        clock = lambda w: w.startswith("GPS time stamps look") and "lever arm" not in w   # noqa: E731
        problems += [f"{w} (calibrate --time-offset estimates it)" if clock(w) else w
                     for w in gps_offset_warnings(log, est) if not (wheels_late and clock(w))]
    # So does a gyro clock off (every turn reads as slip), and an estimate no
    # robot can have driven (analysis.plausible: a wheel that skids for good
    # after slip went into its scale, or the mirror solution).
    # (estimate fitted the gyro's clock already: its lines are in the flags)
    from odomgraph.analysis.gyrotiming import SAID
    problems += [w for w in est.flags if w.startswith(SAID) and w not in problems]
    problems += [w for w in est.flags if w.endswith("not trustworthy") and w not in problems]
    unobs = est.unobservable()
    for name, v, s in zip(("scale_left", "scale_right", "scale_track"), k, sk):
        if abs(v - 1.0) > IMPLAUSIBLE:
            warnings.append(f"{name} came out {v - 1.0:+.1%} from nominal ({v:.4f} +- {s:.2g}): implausible for "
                            "a tyre or track change; check the nominal ticks per metre and track width")
    ho, ho_text = None, None
    t_split = split_time(log)
    if t_split is None:
        warnings.append("no held-out check: the log has too few fixes and no gyro to test the calibration on")
    else:
        try:
            train = estimate(log.truncated(t_split), method, schedule, None, **options)
            k_tr = [float(v) for v in train.mean[-1, S.SCALE]]
            s_tr = np.sqrt(np.maximum(np.diag(train.scale_cov()), 0.0))
            ho = held_out(log, (1.0, 1.0, 1.0), k_tr, t_split, skip=slip_spans(est))
        except OdomgraphError as exc:
            problems.append(f"the fit on the first part of the log (to t={t_split:.0f} s) failed: {exc}")
        if ho is None and not problems:
            warnings.append(f"no held-out check: too little data after t={t_split:.0f} s to score the calibration")
        elif ho is not None:
            ho_text = ho.text()
            agrees = bool(np.all(np.abs(np.asarray(k_tr) - 1.0) <= 2.0 * np.maximum(s_tr, 1e-9)))
            if not (ho.passed or agrees):
                problems.append(f"the calibration predicts held-out data worse than the nominal parameters: {ho_text}")
            elif not ho.passed:
                warnings.append(f"the calibration predicts held-out data slightly worse than nominal ({ho_text}); "
                                "written because it agrees with nominal within 2 sigma")
    held = None if ho is None else {
        "kind": ho.kind, "t0": ho.t0, "t1": ho.t1, "n": ho.n, "unit": ho.unit,
        "nominal": ho.nominal, "calibrated": ho.calibrated, "passed": ho.passed, "text": ho_text}
    return {"warnings": warnings, "unobservable": unobs, "held_out": held, "problems": problems}


def _with_fitted_noise(robot, est: Estimate, warnings: list, per_fix_gps: bool = False):
    """The robot with each GPS/range sigma widened by the scale the data asked
    for (pipeline._with_noise_scales), the wheel speeds' [encoders] sigma
    and the gyro's (_note_row_scales), and each velocity random-walk intensity ([process]
    accel, yaw_accel; _note_motion_scales) and the gyro-bias walk ([process]
    gyro_bias; _note_bias_walk): calibrate writes them back.
    ``per_fix_gps``: gps.csv has its own sigma column, which robot.toml's gps
    sigma does not stand for (LOG_FORMAT), so that one is left as it is; so
    is a sigma a filter widened from its predictions (analysis.noise.
    measured_from), with a line in ``warnings``."""
    from odomgraph.analysis.noise import ROW_WIDEN_ABOVE, with_row_sigmas
    for sensor, field_name in (("gps", "gps_sigma"), ("ranges", "range_sigma")):
        if sensor == "gps" and per_fix_gps:
            continue
        f = est.noise_scales.get(sensor, {}).get("applied", 1.0)
        if f > 1.0 and est.noise_scales[sensor].get("from") == "predictions":
            warnings.append(f"{sensor}: sigma not written: the filter widened it {f:.2g}x for its run from "
                            "its measurements' distance to its predicted path, which does not measure the "
                            "sensor (calibrate with --method batch to measure it)")
            continue
        if f > 1.0:
            robot = robot.with_(**{field_name: getattr(robot, field_name) * f})
    # the wheel rows' and gyro samples' scatter (_note_row_scales)
    robot = with_row_sigmas(robot, {k: est.noise_scales.get(k, {}).get("applied", 1.0) for k in ROW_WIDEN_ABOVE})
    from dataclasses import replace
    pn = robot.process
    grown = {k: getattr(pn, k) * est.noise_scales[k]["applied"] for k in ("accel", "yaw_accel", "gyro_bias")
             if est.noise_scales.get(k, {}).get("applied", 1.0) > 1.0}
    return robot.with_(process=replace(pn, **grown)) if grown else robot


def _is_calibration_file(path: Path) -> bool:
    """A robot.toml that ``calibrate_to_file`` wrote (its [calibration] record says so)."""
    import tomllib
    from odomgraph.errors import LogFormatError
    from odomgraph.io.csvtable import read_text
    try:
        return tomllib.loads(read_text(path)).get("calibration", {}).get("written_by") == "odomgraph calibrate"
    except (LogFormatError, tomllib.TOMLDecodeError, AttributeError):
        return False


def calibrate_to_file(log: Log, out: Path, schedule: Schedule = Schedule(calibrate_until=None),
                      method: Method = Method.batch, progress=None, tune: bool = True, force: bool = False,
                      **options):
    """``calibrate`` and write the calibrated robot.toml to ``out`` (atomically).

    The output is checked before the work starts: it must not lie inside the
    log (``-o LOG/robot.toml`` would overwrite the input), and an existing
    file is replaced only if an earlier calibration wrote it. Nothing is
    written when the checks find a problem (a mounting mistake, a calibration
    that predicts held-out data worse than nominal) unless ``force``: a
    CalibrationRejectedError says why. Returns (RobotConfig, report) as
    ``calibrate``."""
    from odomgraph.io.outdir import atomic_output_file, check_output_file
    from odomgraph.io.robot import robot_toml
    inputs = (log.path,) if log.path else ()
    # (a file odomgraph did not write is refused now, not after the work: a probe waited 8 s for it)
    check_output_file(out, inputs, is_ours=_is_calibration_file)
    _refuse_units(log)       # (a unit to fix, not a calibration to force)
    if not force:
        # A mounting mistake shows in the data before any fit: say it now.
        from odomgraph.analysis.mounting import mounting_warnings
        found = mounting_warnings(log)
        if found:
            raise CalibrationRejectedError(f"{out} not written: {'; '.join(found)} (--force calibrates and writes "
                                           "it anyway)")
    new, rep = calibrate(log, schedule, method, progress, tune, **options)
    if rep["problems"] and not force:
        raise CalibrationRejectedError(f"{out} not written: {'; '.join(rep['problems'])} (--force writes it anyway)")
    extra = {"calibration": {
        "written_by": "odomgraph calibrate",
        "from_log": str(log.path) if log.path else "", "method": rep["method"],
        "ticks_per_meter_left_sigma": rep["ticks_per_meter_left"]["sigma"],
        "ticks_per_meter_right_sigma": rep["ticks_per_meter_right"]["sigma"],
        "track_width_sigma": rep["track_width"]["sigma"],
        "unobservable": ", ".join(rep["unobservable"]) or "none",
        "held_out": rep["held_out"]["text"] if rep["held_out"] else "not checked",
        "forced": bool(rep["problems"])}}
    with atomic_output_file(out, inputs, is_ours=_is_calibration_file) as tmp:
        tmp.write_text(robot_toml(new, extra), encoding="utf-8")
    return new, rep


