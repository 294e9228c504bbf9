"""How far off are the sensor sigmas in robot.toml? Noise scales from the data.

A real log's robot.toml often gets its GPS or range sigma wrong by a large
factor, and every sigma of the estimate inherits the error
(ESTIMATION-NOTES.md: a car log's GNSS sigma taken at face value gave 3.5 %
of positions inside 3 sigma). The scale of each absolute sensor is measured
robustly (medians, so outliers do not count): from the EKF's innovations,
which are independent of the update they feed (median NIS against the
chi-square median of their dimension), or from a smoother's post-fit
residuals (1.4826 MAD of the whitened residuals); a filter with too few
innovations, from its rows at the measurements' times, which are its
predictions: that scale is the run's only, not the sensor's
(``measured_from``). Post-fit residuals are
smaller than the noise by the share of each fix the smoother absorbs, so
from a smoother the scale errs low; ``pipeline.estimate`` only ever widens a
sigma with it, never narrows one. A scale far below 1 (NARROW_BELOW) is
said, not acted on.

Errors that persist from one measurement to the next (a UWB anchor's
offset, GNSS multipath, a mocap marker's drift) do not average out, however
many measurements the estimator combines, and a sigma that matches their
scatter still claims too much (``correlation_factors``). On the libRSF cut
(per-anchor range offsets of 0.07-0.15 m) the smoothers held only 85 % of
positions inside 3 sigma with the scatter's scale alone.

The velocity random walk's intensities ([process] accel and yaw_accel) are
checked the same way, before any estimator runs, against the wheels' own
speed and yaw rate (``motion_scales``). A walk far tighter than the robot's
real accelerations makes every estimator pay for the motion somewhere else:
on the libRSF cut (a small robot pivoting at 2.4 rad/s, wheels wandering
2.9 rad/s/sqrt(s) against a configured 0.3) the smoothers halved the yaw
rate by doubling the track scale, 37 prior sigmas away, and the estimate
took the slip model's mirror solution.
"""
from __future__ import annotations

import numpy as np

from odomgraph.factors._math import robust_sigma

#: Medians of chi-square with 1 and 2 degrees of freedom.
CHI2_MEDIAN = {1: 0.4549, 2: 1.3863}
#: A scale this far above 1 is acted on (and reported).
WIDEN_ABOVE = 1.3
#: A widening this large flags the estimate (pipeline._with_noise_scales):
#: an estimate that did not follow its fixes, more often than a sigma set
#: that wrong.
WIDEN_FLAG_ABOVE = 30.0
#: Fewest measurements a scale is estimated from.
MIN_COUNT = 20
#: A scale this far below 1, from NARROW_MIN_COUNT measurements or more
#: (measured_count), with persistence credited as the widening credits it
#: (correlation_factors), says the configured sigma (or a filter's process
#: noise) is too large: said, not acted on.
#: Right sigmas measured 0.71-1.0 from 150-1200 fixes (paper and yard
#: scenarios, fixes at 0.5-10 Hz, EKF innovations and smoother residuals
#: alike), but 0.52-0.69 from 25-30 (a second read); 3x too large measured
#: 0.32-0.35, 10x 0.11-0.12.
NARROW_BELOW = 0.4
NARROW_MIN_COUNT = 100


def noise_scales(est, log) -> dict[str, float]:
    """{sensor: scale} for GPS and ranges: the factor by which the configured
    sigma would have to grow to match what the data scatter (1: right);
    ``measured_from`` says from what."""
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    out = {}
    for sensor in ("gps", "ranges"):
        inn = est.innovations.get(sensor)
        if inn is not None and inn.nis.size >= MIN_COUNT:
            out[sensor] = float(np.sqrt(np.median(inn.nis) / CHI2_MEDIAN[inn.dof]))
            continue
        u = _whitened_residuals(est, log, sensor)
        if u is not None and u.size >= MIN_COUNT:
            out[sensor] = robust_sigma(u)
    return out


def measured_count(est, log, sensor: str) -> int:
    """How many measurements noise_scales measured ``sensor``'s scale from:
    a filter's innovations, or the residuals of the cleaned log's fixes or
    ranges inside the estimate's span (not the log's rows)."""
    inn = est.innovations.get(sensor)
    if inn is not None and inn.nis.size >= MIN_COUNT:
        return int(inn.nis.size)
    from odomgraph.estimators.measurements import clean
    u = _whitened_residuals(est, clean(log)[0], sensor)
    return 0 if u is None else int(u.size)


def measured_from(est, sensor: str) -> str:
    """What noise_scales measured ``sensor``'s scale from: "innovations" (a
    filter's, MIN_COUNT of them at least), "residuals" (a smoother's post-fit
    residuals) or "predictions" (a filter with fewer innovations, whose rows
    at a measurement's time are its prediction: the residuals there carry
    its dead reckoning's error as much as the sensor's).

    The last measures the fixes against the filter's path, not the sensor's
    noise: a probe's 0.2 Hz fixes (18 accepted) lay 16x further from the
    EKF's predicted path than the 0.02 m GPS sigma, and calibrate --method
    ekf wrote 0.317 m as the GPS's sigma; batch measured the sensor right."""
    inn = est.innovations.get(sensor)
    if inn is not None and inn.nis.size >= MIN_COUNT:
        return "innovations"
    return "predictions" if est.innovations else "residuals"


#: Rate [Hz] of the interval averages the wheels' accelerations are measured at
#: (the smoothers' keyframe rate).
MOTION_HZ = 5.0
#: Share of the largest steps left out (an encoder glitch is no acceleration).
MOTION_TRIM = 0.01
#: A random-walk intensity this far below the wheels' is acted on (and
#: reported): the walk's chi-square is then 9x its count. The threshold is
#: well above WIDEN_ABOVE because a Gaussian walk is a compromise for motion
#: that comes in bursts: the simulated scenarios' start-ups measure up to
#: 2.4x (paper, 20 s) with the defaults they are estimated well with, where
#: the libRSF cut's pivots measure 9.8x.
MOTION_WIDEN_ABOVE = 3.0
#: Slower rates [Hz] the measure falls back to, in turn, while the averages'
#: own noise is more than MOTION_MAX_NOISE of their steps' mean square.
MOTION_SLOWER = (2.0, 1.0, 0.5)
MOTION_MAX_NOISE = 0.5


def motion_scales(log) -> dict[str, float]:
    """{"accel": f, "yaw_accel": f}: the factor by which each velocity
    random-walk intensity of robot.toml's [process] would have to grow to
    match how fast the wheels' own speed and yaw rate wander (1: right).

    The wheel speeds are averaged over MOTION_HZ intervals (keyframes.py,
    nominal scale factors); for a random walk of intensity q, adjacent
    averages over intervals a and b differ by q^2 (a + b) / 3 in variance,
    plus the averages' own noise (enc_sigma), which is taken out. The
    largest MOTION_TRIM of the steps are left out; the rest give q as a root
    mean square, so that the walk's chi-square matches its count. Wheel speed
    is ground speed plus slip, so this bounds the ground's intensity from
    above; it is only used to widen. {} when the log has too few intervals.

    Where the averages' noise is most of their steps (coarse encoders: at
    20 ticks/m and 5 Hz a tick is 0.1 m/s), what is left after taking it out
    is mostly chance, and the measure is taken at a slower rate instead
    (MOTION_SLOWER): a walk's steps grow with the interval and the
    averages' quantisation noise shrinks with it.
    """
    from odomgraph.estimators.keyframes import build_keyframes
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    from odomgraph.errors import OdomgraphError
    pn = log.robot.process
    out = {}
    for name, conf in (("accel", pn.accel), ("yaw_accel", pn.yaw_accel)):
        for hz in (MOTION_HZ,) + MOTION_SLOWER:
            try:
                kf = build_keyframes(log, log.t_start, hz)
            except OdomgraphError:      # a log the estimators refuse, with their own message
                break
            if kf.n < MIN_COUNT + 2:
                break
            m, sg, track = kf.enc_m, kf.enc_sigma, log.robot.track_width
            if name == "accel":
                x, var = m.mean(1), 0.25 * (sg**2).sum(1)
            else:
                x, var = (m[:, 1] - m[:, 0]) / track, (sg**2).sum(1) / track**2
            step2, noise = np.diff(x) ** 2, var[:-1] + var[1:]
            ok = np.isfinite(step2) & np.isfinite(noise)
            if ok.sum() < MIN_COUNT:
                break
            span = ((kf.dt[:-1] + kf.dt[1:]) / 3.0)[ok]
            q2 = np.sort((step2[ok] - noise[ok]) / span)
            q2 = q2[: max(1, int((1.0 - MOTION_TRIM) * q2.size))]
            out[name] = float(np.sqrt(max(float(np.mean(q2)), 0.0)) / conf)
            if np.mean(noise[ok]) <= MOTION_MAX_NOISE * np.mean(step2[ok]):
                break
    return out


#: Lag [s] over which the estimated gyro bias's steps are compared with the
#: walk robot.toml allows ([process] gyro_bias), and the widening threshold:
#: the robust RMS of those steps, in units of the walk's sqrt(q^2 lag).
BIAS_LAG = 20.0
BIAS_WIDEN_ABOVE = 5.0


def bias_walk_scale(est, q: float) -> float | None:
    """The factor by which [process] gyro_bias ``q`` [(rad/s)/sqrt(s)] would
    have to grow for the estimate's own gyro-bias path to be one of its
    walks: the robust RMS (median of the squares against chi-square(1)'s) of
    its steps over BIAS_LAG seconds, taken every BIAS_LAG / 2, each in units
    of q sqrt(BIAS_LAG). An estimate follows the true bias only as far as the
    walk lets it, so this errs low, and a walk far too tight still shows: a
    probe's bias ramping 0.12 rad/s a minute (a MEMS gyro warming up)
    measured 12.6 from the EKF's path and batch's alike, and the EKF held 81 %
    of its headings outside 3 sigma. Walks that were right measured 0.1-1.8.
    None for an estimate spanning less than 2.5 BIAS_LAG.

    The steps start a quarter lag in: the first seconds hold the bias's
    convergence from its prior, no walk."""
    from odomgraph import state as S
    t, b = est.t, est.mean[:, S.BIAS]
    if t.size < 2 or t[-1] - t[0] < 2.5 * BIAS_LAG:
        return None
    at = np.arange(t[0] + 0.25 * BIAS_LAG, t[-1] - BIAS_LAG, 0.5 * BIAS_LAG)
    z = (np.interp(at + BIAS_LAG, t, b) - np.interp(at, t, b)) / (q * np.sqrt(BIAS_LAG))
    return float(np.sqrt(np.median(z**2) / CHI2_MEDIAN[1]))


def widened_motion(log, scales: dict[str, float]):
    """The log with [process] accel and yaw_accel multiplied by their scales
    (those above MOTION_WIDEN_ABOVE; an intensity is never narrowed)."""
    from dataclasses import replace
    pn = log.robot.process
    new = {k: getattr(pn, k) * f for k, f in scales.items() if f > MOTION_WIDEN_ABOVE}
    return log if not new else log.with_(robot=log.robot.with_(process=replace(pn, **new)))


#: A wheel_speeds.csv scatter this far above robot.toml's encoder sigma is
#: acted on (wheel_row_scale). Above WIDEN_ABOVE: the second differences
#: also hold the motion's own changes, and rows differenced from quantised
#: positions (moving-average noise) measure up to 1.29x their sigma; the
#: simulator's quantised speeds measured 1.10-1.17 at 10 Hz, the libRSF
#: cut's wheels 1.32 at 7.8 Hz, quantised ones at 50-200 Hz 1.4-8.8.
WHEEL_WIDEN_ABOVE = 1.5
#: Encoder rows are judged only where eq. 41's variance is at least this
#: share of the rows' noise at robot.toml's sigma (the rest is the ticks'
#: quantisation), in the median triplet...
ENCODER_EQ41_SHARE = 0.5
#: (or where the rows scatter this many times the ticks' quantisation alone:
#: counts alternating 1, 2, 1, 2 at a steady speed, the worst pattern, give
#: 2.3; uniform errors about 1)
ENCODER_OVER_QUANTISATION = 3.0
#: Wheel rows (encoders.csv and wheel_speeds.csv) are judged only when they
#: come at least this often [Hz]: slower, a stop-and-go robot's own speed
#: changes between rows pass for noise (a probe: 1.6-1.9 at 10 Hz, 3.6-6.1 at
#: 5 Hz; the libRSF cut's 7.8 Hz wheels measured 1.32).
ENCODER_MIN_HZ = 15.0
#: A gyro is judged only when its samples come at least this often [Hz]
#: (a probe: a 1 Hz gyro on fast pivots measured 72, at 2 Hz 2.4, at 10-25 Hz
#: 1.03-1.26 with step-like pivots).
GYRO_MIN_HZ = 10.0
#: The median period may exceed 1 / rate by this factor: a nominal 15 Hz log's
#: jittered median lands on either side of 1/15 (a second read: 2 of 6 seeds
#: at 15 Hz were not judged).
RATE_SLACK = 1.05
#: Encoder rows whose plain whitened scatter (eq. 41 and the ticks'
#: quantisation at robot.toml's sigma) is above this have the factor on the
#: sigma solved for (wheel_row_scale); below, the plain scatter is returned.
#: Rows at the configured sigma measure 1.0-1.12 in the simulator (10-100 Hz,
#: paper and yard); where quantisation dominates (yard at 100 Hz) the small
#: excess the motion adds would otherwise be solved into a factor of 1.7-1.9.
ENCODER_SCATTER_ABOVE = 1.25
#: A gyro's sample scatter this far above robot.toml's [gyro] sigma is acted on (gyro_row_scale).
GYRO_WIDEN_ABOVE = 1.5
#: Rows further apart than this many median periods end a run of rows (wheel_row_scale, gyro_row_scale).
WHEEL_MAX_GAP = 2.0
#: The largest factor wheel_row_scale solves for; a sigma further off is reported as at least this.
ROW_FACTOR_CAP = 1e4
#: Each sensor row_scales measures: the factor on its robot.toml sigma above which it is widened.
ROW_WIDEN_ABOVE = {"encoders": WHEEL_WIDEN_ABOVE, "gyro": GYRO_WIDEN_ABOVE}


def wheel_row_scale(log) -> float | None:
    """The factor by which robot.toml's [encoders] sigma (paper eq. 41,
    a + b |v|) would have to grow to match the scatter of the wheels' rows
    (about 1: right), from wheel_speeds.csv or encoders.csv; None for fewer
    than MIN_COUNT triplets of moving rows.

    Measured from the log alone, before any estimate: the second
    difference v[k+1] - 2 v[k] + v[k-1] of each wheel's rows leaves little
    of a speed that changes smoothly (nothing of a constant acceleration).
    Its variance, of eq. 41's white noise sigma_k, is sigma_{k-1}^2 +
    4 sigma_k^2 + sigma_{k+1}^2 (S); encoder rows add the ticks'
    quantisation (_quantisation_var, Q). The factor g solves
    MAD(d2 / sqrt(g^2 S + Q)) = 1 (robust scale, over triplets with no gap
    and a wheel moving); it is returned when the plain scatter
    MAD(d2 / sqrt(S + Q)) exceeds ENCODER_SCATTER_ABOVE, else that scatter
    (for wheel_speeds rows, Q = 0, the two are one number).

    Wheel speeds an importer differenced from a JointState's quantised
    positions (or a driver's own Odometry twist) carry noise that grows as
    the rate: a probe's 100 Hz rows scattered 2-4x the configured sigma,
    and the EKF, weighing each row whole, gave a track scale 0.005 off at
    z -3.2, status ok (at 200 Hz it diverged). Encoder rows with wheel
    noise 5-10x robot.toml's sigma gave batch scale factors 5-9 sigma off,
    status ok (a probe); the quantisation, which the estimators model,
    must not count against the sigma: with it the simulator's rows at the
    configured sigma measure 1.0-1.12, and g finds 2, 5 and 10 for noise
    2, 5 and 10 times it (tests/test_wheel_speed_noise.py).

    Not judged (None): rows slower than ENCODER_MIN_HZ (the motion's own
    changes pass for noise), and encoder rows whose noise is mostly the
    ticks' quantisation (ENCODER_EQ41_SHARE, ENCODER_OVER_QUANTISATION:
    its patterns fool the measure, and the factor solved from a small
    excess was 13-100 on logs at their true sigma, a probe's)."""
    from odomgraph.estimators.measurements import despike
    if log.encoders is None and (log.wheel_speeds is None or len(log.wheel_speeds.t) < MIN_COUNT + 2):
        return None
    if log.encoders is not None and len(log.encoders.t) < MIN_COUNT + 3:
        return None
    # the wheels' own rows, as every estimator reads them (the gyro's spikes do not matter here)
    clean = despike(log.with_(gyro=None))[0]
    a, b = log.robot.encoder_sigma
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # rows written twice (dt 0) make non-finite speeds, left out (np.isfinite)
        return _row_scale(clean, a, b)


def _row_scale(clean, a: float, b: float) -> float | None:
    """wheel_row_scale's measure on the despiked log ``clean``."""
    r = clean.robot
    d2s, ss, qs = [], [], []
    if clean.encoders is not None:
        e = clean.encoders
        dt = np.diff(e.t)
        rows = []
        for ticks, tpm in ((e.ticks_left, r.ticks_per_meter_left), (e.ticks_right, r.ticks_per_meter_right)):
            c = 1.0 / (tpm * dt)                # m/s per tick, each interval
            rows.append((ticks[1:] * c, ticks[1:] != 0, _quantisation_var(c)))
    else:
        w = clean.wheel_speeds
        dt = np.diff(w.t)
        rows = [(v, v != 0, 0.0) for v in (w.v_left, w.v_right)]
    if dt.size < 3:
        return None
    med = float(np.median(dt))
    if med > RATE_SLACK / ENCODER_MIN_HZ:
        # the motion's own changes between rows pass for noise (a probe's stop-and-go at 5 Hz: 3.6-6.1)
        return None
    # encoder rows: the rows' own three intervals; speed rows: the two between them
    ok = _gap_free(dt, 3 if clean.encoders is not None else 2)
    for v, moving, q in rows:
        s2 = (a + b * np.abs(v)) ** 2
        d2 = v[2:] - 2.0 * v[1:-1] + v[:-2]
        sel = ok & (moving[2:] | moving[1:-1] | moving[:-2]) & np.isfinite(d2) & np.isfinite(q)
        d2s.append(d2[sel])
        ss.append((s2[2:] + 4.0 * s2[1:-1] + s2[:-2])[sel])
        qs.append(np.broadcast_to(q, d2.shape)[sel])
    d2, s, q = np.concatenate(d2s), np.concatenate(ss), np.concatenate(qs)
    if d2.size < MIN_COUNT:
        return None
    if (clean.encoders is not None and np.median(s / (s + q)) < ENCODER_EQ41_SHARE
            and robust_sigma(d2 / np.sqrt(q)) < ENCODER_OVER_QUANTISATION):
        # The ticks' quantisation is most of the rows' noise: its pattern at a
        # steady speed (counts alternating 1, 2, 1, 2) is not the uniform error
        # the variance assumes, and its lattice fools the MAD; solving eq. 41's
        # factor from the small excess then gave 13-100 on logs at their true
        # sigma (a probe: yard at 400 Hz, or 100 ticks/m at 50 Hz; isam2's
        # scale factors then z +5 to +6, status ok). Unless the rows scatter
        # far beyond what the ticks alone could make: then eq. 41's part is
        # most of the data's noise, whatever robot.toml says.
        return None
    ad = np.abs(d2)

    def scatter(g: float) -> float:
        return robust_sigma(ad / np.sqrt(g * g * s + q))
    plain = scatter(1.0)
    if plain <= ENCODER_SCATTER_ABOVE or not np.any(q > 0) or not np.any(s > 0):
        return plain     # no quantisation: plain is the factor itself (scatter(g) = plain / g)
    # scatter(g) falls as g grows; bisect in log g on [1, ROW_FACTOR_CAP]
    lo, hi = 1.0, ROW_FACTOR_CAP
    if scatter(hi) > 1.0:
        return ROW_FACTOR_CAP     # said as "at least" (pipeline._row_scale_line)
    for _ in range(50):
        mid = np.sqrt(lo * hi)
        lo, hi = (mid, hi) if scatter(mid) > 1.0 else (lo, mid)
    return float(hi)


def _quantisation_var(c: np.ndarray) -> np.ndarray:
    """(K - 2,) variance [(m/s)^2] of the second difference of speeds from
    tick counts, from the counts' quantisation alone. ``c`` (K,) is each
    interval's m/s per tick, 1 / (tpm dt). The count of interval k is the
    distance plus e_k - e_{k-1}, e the floor() error of the cumulative
    count (uniform, variance 1/12 tick^2): neighbouring intervals share one,
    so v[k+1] - 2 v[k] + v[k-1] carries e_{k+1} c_{k+1} - e_k (c_{k+1} +
    2 c_k) + e_{k-1} (2 c_k + c_{k-1}) - e_{k-2} c_{k-1} (20/12 tick^2 at
    one rate, not the (1 + 4 + 1) / 6 of independent intervals that
    factors.encoder.speed_sigma's per-row 1/6 would give)."""
    c0, c1, c2 = c[:-2], c[1:-1], c[2:]
    return (c2**2 + (c2 + 2.0 * c1) ** 2 + (2.0 * c1 + c0) ** 2 + c0**2) / 12.0


def gyro_row_scale(log) -> float | None:
    """The factor by which robot.toml's [gyro] sigma (paper eq. 40, white
    noise on each sample [rad/s]) would have to grow to match the scatter
    of the gyro's samples (about 1: right); None without a gyro or with
    fewer than MIN_COUNT triplets.

    As wheel_row_scale: the second difference of the despiked samples,
    with variance 6 sigma^2, robust scale (MAD), over triplets with no gap.
    The yaw rate's own changes hardly enter at a gyro's rates: the
    simulator's samples measure 0.96-1.22 at 10-400 Hz (the most at 10 Hz),
    2.9 and 9.7 for noise 3 and 10 times the sigma; the Jackal's IMU 1.05. A gyro 10x noisier than its
    sigma gave the EKF a mean gyro NIS 5.4 and batch a track scale at z
    3.5, status ok (tests/test_wheel_speed_noise.py). A gyro that filters
    its samples (a low-pass inside the IMU) measures less: never narrowed."""
    from odomgraph.estimators.measurements import despike
    if log.gyro is None or len(log.gyro.t) < MIN_COUNT + 2 or not log.robot.gyro_sigma > 0:
        return None
    g = despike(log.with_(encoders=None, wheel_speeds=None))[0].gyro
    dt = np.diff(g.t)
    if dt.size < 2 or not 0.0 < float(np.median(dt)) <= RATE_SLACK / GYRO_MIN_HZ:
        return None
    d2 = (g.omega[2:] - 2.0 * g.omega[1:-1] + g.omega[:-2])[_gap_free(dt, 2)]
    d2 = d2[np.isfinite(d2)]
    if d2.size < MIN_COUNT:
        return None
    return float(robust_sigma(d2) / (np.sqrt(6.0) * log.robot.gyro_sigma))


def _gap_free(dt: np.ndarray, span: int) -> np.ndarray:
    """(len(dt) - span + 1,) True where ``span`` consecutive intervals
    ``dt`` [s] are each at most WHEEL_MAX_GAP median intervals: a second
    difference across a gap mixes two stretches of motion."""
    ok = dt <= WHEEL_MAX_GAP * float(np.median(dt))
    return np.all([ok[i:ok.size - span + 1 + i] for i in range(span)], axis=0)


def row_scales(log) -> dict[str, float]:
    """{"encoders": wheel_row_scale, "gyro": gyro_row_scale} of the log, the
    ones it can measure: each sensor's scatter against robot.toml's sigma,
    from the rows alone (before any estimate)."""
    out = {"encoders": wheel_row_scale(log), "gyro": gyro_row_scale(log)}
    return {k: v for k, v in out.items() if v is not None}


def applied_row_scale(sensor: str, f: float | None) -> float:
    """The factor a run applies to ``sensor``'s ("encoders", "gyro") sigma
    for its measured row scale ``f``: f above ROW_WIDEN_ABOVE, else 1 (a
    sigma is never narrowed)."""
    return f if f is not None and f > ROW_WIDEN_ABOVE[sensor] else 1.0


def with_row_sigmas(robot, factors: dict[str, float]):
    """``robot`` with its [encoders] sigma (a, b) and [gyro] sigma
    multiplied by ``factors["encoders"]`` and ``factors["gyro"]`` (missing:
    1; a factor of 1 or less changes nothing: a sigma is never narrowed).
    Shared by the widened run (widened_rows) and calibrate's write-back
    (pipeline._with_fitted_noise)."""
    fe, fg = factors.get("encoders", 1.0), factors.get("gyro", 1.0)
    if fe > 1.0:
        robot = robot.with_(encoder_sigma=tuple(v * fe for v in robot.encoder_sigma))
    if fg > 1.0:
        robot = robot.with_(gyro_sigma=robot.gyro_sigma * fg)
    return robot


def widened_rows(log, scales: dict[str, float | None]):
    """The log with robot.toml's [encoders] and [gyro] sigma multiplied by
    their ``scales`` (row_scales, or the factors a run applied) where they
    are above ROW_WIDEN_ABOVE (applied_row_scale)."""
    factors = {k: applied_row_scale(k, f) for k, f in scales.items() if k in ROW_WIDEN_ABOVE}
    if not any(f > 1.0 for f in factors.values()):
        return log
    return log.with_(robot=with_row_sigmas(log.robot, factors))


#: The largest lag-1 correlation credited: a constant offset is correlation 1,
#: which no finite sigma covers (sqrt(1.9 / 0.1) = 4.4 at most).
MAX_CORRELATION = 0.9
#: A pair of measurements further apart than this many of the channel's
#: median periods is not a neighbour.
MAX_PAIR_GAP = 5.0


def correlation_factors(est, log) -> dict[str, tuple[float, float]]:
    """{sensor: (rho, factor)} for GPS and ranges: rho the lag-1
    autocorrelation of the sensor's whitened residuals against ``est``, pooled
    over its channels (GPS east and north; each beacon), and factor =
    sqrt((1 + rho) / (1 - rho)), by which the sigma must grow for an
    estimator that treats the errors as independent to weigh them right (the
    variance of a mean of AR(1) errors is (1 + rho) / (1 - rho) times the
    independent one's). The mean is not taken out: a channel's constant
    offset is error that persists. Measurements held out as a jump
    (Estimate.held_out) and residuals beyond 4 robust sigmas are left out,
    with the pairs they are in: a multipath burst is an outlier, rejected as
    one, not the noise of the rest. factor 1 when rho is not above 2/sqrt(n).

    Post-fit residuals follow part of a persistent error (the estimate bends
    towards it), so rho errs low: the widening errs small, never large.
    """
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    out = {}
    for sensor in ("gps", "ranges"):
        chans = _residual_channels(est, log, sensor)
        if not chans or sum(c.size for _, c in chans) < MIN_COUNT:
            continue
        u = np.concatenate([c[np.isfinite(c)] for _, c in chans])
        if u.size < MIN_COUNT:
            continue
        cap = 4.0 * max(robust_sigma(u), 1e-12)
        num = den = 0.0
        n = 0
        for t, c in chans:
            ok = np.abs(c) <= cap          # NaN (held out) and outliers fail
            # neighbours only: a pair across an outage is no persistence
            gap = np.diff(t)
            pair = ok[1:] & ok[:-1] & (gap <= MAX_PAIR_GAP * max(float(np.median(gap)), 1e-9))
            num += float(np.sum((c[1:] * c[:-1])[pair]))
            den += float(np.sum(c[ok] ** 2))
            n += int(pair.sum())
        rho = num / den if den > 0 and n > 0 else 0.0
        if n <= 0 or rho <= 2.0 / np.sqrt(n):
            out[sensor] = (rho, 1.0)
            continue
        r = min(rho, MAX_CORRELATION)
        out[sensor] = (rho, float(np.sqrt((1.0 + r) / (1.0 - r))))
    return out


def _residual_channels(est, log, sensor: str) -> list[tuple[np.ndarray, np.ndarray]]:
    """The sensor's whitened residuals against ``est``: one time-ordered
    (t, u) pair of arrays per channel (GPS: east, north; ranges: each
    beacon). A held-out measurement's u is NaN."""
    from odomgraph.analysis.metrics import gps_residuals, range_residuals
    held = est.held_out.get(sensor) if est.held_out else None
    if sensor == "gps":
        res = gps_residuals(est, log)
        if res is None or not res[0].size:
            return []
        u = res[1] / res[2][:, None]
        if held is not None and held.size:
            u[np.isin(res[0], held)] = np.nan
        return [(res[0], u[:, 0]), (res[0], u[:, 1])]
    res = range_residuals(est, log)
    if res is None or not res[0].size:
        return []
    r = log.ranges
    beacon = r.beacon[(r.t >= est.t[0]) & (r.t <= est.t[-1])]
    u = res[1] / log.robot.range_sigma
    if held is not None and held.size:
        # held-out times name no beacon: a stamp shared by several anchors
        # masks them all, which only drops data
        u[np.isin(res[0], held)] = np.nan
    return [(res[0][beacon == b], u[beacon == b]) for b in np.unique(beacon)]


def _whitened_residuals(est, log, sensor: str) -> np.ndarray | None:
    """Residuals of one sensor against the estimate's rows, divided by their
    sigma (per axis), from the residuals the metrics use (analysis.metrics):
    post-fit for a smoother, mostly the prediction's for a filter
    (measured_from)."""
    from odomgraph.analysis.metrics import gps_residuals, range_residuals
    if sensor == "gps":
        res = gps_residuals(est, log)
        return None if res is None or not res[0].size else (res[1] / res[2][:, None]).ravel()
    res = range_residuals(est, log)
    return None if res is None or not res[0].size else res[1] / log.robot.range_sigma


#: Per-fix sigmas (gps.csv's column) are judged in this many groups, by
#: quantile of the claimed sigma, when they spread more than SPREAD...
SIGMA_GROUPS = 4
SIGMA_SPREAD = 2.0
#: ...and a floor is fitted when the groups' scatter-to-claim factors differ
#: more than this (one factor for all would be far off for some).
FACTOR_SPREAD = 2.0


def gps_sigma_floor(est, log) -> tuple[float, float] | None:
    """(f, floor [m]) for per-fix GPS sigmas that are not all off by one
    factor: the fixes scatter as sqrt((f sigma_i)^2 + floor^2). A receiver's
    reported sigma is often optimistic for its best fixes and about right for
    its poor ones: one factor from the median (noise_scales) then misses the
    good fixes (a probe: 0.01 m claimed, 0.05 m scattered, beside honest
    0.3 m fixes; the EKF widened 1.4x held 74-88 % inside 3 sigma).

    Fixes are grouped by quantile of their claimed sigma (SIGMA_GROUPS); in
    each group the robust scatter of the post-fit residuals (1.4826 MAD per
    axis, outliers beyond 4 robust sigmas out) is set against the group's
    median claim, and s^2 = f^2 sigma^2 + floor^2 fitted by least squares
    (f^2, floor^2 >= 0; f at least 1). None when the log has no per-fix
    sigma, they spread less than SIGMA_SPREAD, the groups agree on one
    factor within FACTOR_SPREAD, or the floor is below the best fixes' own
    sigma."""
    from odomgraph.analysis.metrics import gps_residuals
    from odomgraph.estimators.measurements import clean
    log = clean(log)[0]
    g = log.gps
    if g is None or g.sigma is None or len(g.t) < SIGMA_GROUPS * MIN_COUNT:
        return None
    res = gps_residuals(est, log)
    if res is None or res[0].size < SIGMA_GROUPS * MIN_COUNT:
        return None
    t, r, sig = res
    held = est.held_out.get("gps") if est.held_out else None
    keep = np.isfinite(r).all(1) & np.isfinite(sig) & (sig > 0)
    if held is not None and np.size(held):
        keep &= ~np.isin(t, held)
    r, sig = r[keep], sig[keep]
    if sig.size < SIGMA_GROUPS * MIN_COUNT or np.quantile(sig, 0.9) < SIGMA_SPREAD * np.quantile(sig, 0.1):
        return None
    # Receivers often report a few fixed sigmas (RTK fixed / float): those
    # values are the groups; otherwise quantile bins, without repeated edges
    # (a bin of 0.01 m claims next to one of 0.3 m must not overlap).
    vals = np.unique(sig)
    if vals.size <= 2 * SIGMA_GROUPS:
        label = np.searchsorted(vals, sig)
    else:
        edges = np.unique(np.quantile(sig, np.linspace(0.0, 1.0, SIGMA_GROUPS + 1)))
        label = np.clip(np.searchsorted(edges, sig, side="right") - 1, 0, edges.size - 2)
    claim, scatter = [], []
    for lab in np.unique(label):
        sel = label == lab
        if sel.sum() < MIN_COUNT:
            continue
        x = r[sel].ravel()
        s = robust_sigma(x - np.median(x))
        x = x[np.abs(x - np.median(x)) <= 4.0 * max(s, 1e-12)]
        claim.append(float(np.median(sig[sel])))
        scatter.append(robust_sigma(x - np.median(x)))
    if len(claim) < 2:
        return None
    claim, scatter = np.array(claim), np.array(scatter)
    ratio = scatter / claim
    if ratio.max() < FACTOR_SPREAD * ratio.min():
        return None
    # s^2 = a sigma^2 + c, a = f^2, c = floor^2, both >= 0: the unconstrained
    # fit, else each one-parameter fit, the best that is feasible.
    A = np.stack([claim**2, np.ones_like(claim)], -1)
    y = scatter**2
    cands = []
    sol = np.linalg.lstsq(A, y, rcond=None)[0]
    if np.all(sol >= 0):
        cands.append(sol)
    cands.append(np.array([float(np.sum(claim**2 * y) / np.sum(claim**4)), 0.0]))
    cands.append(np.array([0.0, float(np.mean(y))]))
    a, c = min(cands, key=lambda v: float(np.sum((A @ v - y) ** 2)))
    f, floor = max(float(np.sqrt(a)), 1.0), float(np.sqrt(c))
    # A floor below the best fixes' own sigma changes nothing that matters:
    # one factor (noise_scales) is then the model. (A fit that follows its
    # best fixes closely leaves them small residuals, so the groups can
    # disagree with honest sigmas too.)
    return (f, floor) if floor > f * float(claim.min()) else None


def floored(log, f: float, floor: float):
    """The log with each fix's sigma taken to sqrt((f sigma_i)^2 + floor^2)
    (gps_sigma_floor; never narrower)."""
    from dataclasses import replace
    g = log.gps
    return log.with_(gps=replace(g, sigma=np.sqrt((f * g.sigma) ** 2 + floor**2)))


def widened(log, scales: dict[str, float]):
    """The log with the GPS and range sigmas multiplied by their scales
    (those above WIDEN_ABOVE; a sigma is never narrowed)."""
    from dataclasses import replace
    robot, gps = log.robot, log.gps
    s = scales.get("gps", 1.0)
    if s > WIDEN_ABOVE:
        robot = robot.with_(gps_sigma=robot.gps_sigma * s)
        if gps is not None and gps.sigma is not None:
            gps = replace(gps, sigma=gps.sigma * s)
    s = scales.get("ranges", 1.0)
    if s > WIDEN_ABOVE:
        robot = robot.with_(range_sigma=robot.range_sigma * s)
    return log.with_(robot=robot, gps=gps)
