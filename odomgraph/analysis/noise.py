"""How far off are the sensor sigmas in robot.toml? Noise scales from the data.

A real log's robot.toml often gets its GPS or range sigma wrong by a large
factor, and every sigma of the estimate inherits the error
(ESTIMATION-NOTES.md: a car log's GNSS sigma taken at face value gave 3.5 %
of positions inside 3 sigma). The scale of each absolute sensor is measured
robustly (medians, so outliers do not count): from the EKF's innovations,
which are independent of the update they feed (median NIS against the
chi-square median of their dimension), or from a smoother's post-fit
residuals (1.4826 MAD of the whitened residuals). Post-fit residuals are
smaller than the noise by the share of each fix the smoother absorbs, so
from a smoother the scale errs low; ``pipeline.estimate`` only ever widens a
sigma with it, never narrows one.
"""
from __future__ import annotations

import numpy as np

#: Medians of chi-square with 1 and 2 degrees of freedom.
CHI2_MEDIAN = {1: 0.4549, 2: 1.3863}
#: A scale this far above 1 is acted on (and reported).
WIDEN_ABOVE = 1.3
#: Fewest measurements a scale is estimated from.
MIN_COUNT = 20


def noise_scales(est, log) -> dict[str, float]:
    """{sensor: scale} for GPS and ranges: the factor by which the configured
    sigma would have to grow to match what the data scatter (1: right)."""
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
            out[sensor] = float(1.4826 * np.median(np.abs(u)))
    return out


def _whitened_residuals(est, log, sensor: str) -> np.ndarray | None:
    """Post-fit residuals of one sensor against the estimate, divided by their
    sigma (per axis), from the residuals the metrics use (analysis.metrics)."""
    from odomgraph.analysis.metrics import gps_residuals, range_residuals
    if sensor == "gps":
        res = gps_residuals(est, log)
        return None if res is None or not res[0].size else (res[1] / res[2][:, None]).ravel()
    res = range_residuals(est, log)
    return None if res is None or not res[0].size else res[1] / log.robot.range_sigma


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
