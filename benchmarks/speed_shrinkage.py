"""The speed-shrinkage bias of the scale factors when GPS is the only speed
reference, and what wheel-speed units in the batch smoother's random walks do
about it.

Monte-Carlo configuration 1 (GPS + gyro, 60 s, the paper's calibration
window), gyro 0.005 rad/s, GPS sigma swept; 16 seeds per point. Mean and
spread of the final scale-factor errors for the EKF, the batch smoother as
shipped, the batch smoother with plain random walks
(SmootherOptions(wheel_speed_units=False)), and isam2 and fixed-lag as
shipped (wheel-speed units as linear factors). A mean far outside the
spread is a bias. Writes results/speed_shrinkage.{json,md}.

    python -m benchmarks.speed_shrinkage
"""
from __future__ import annotations

from concurrent.futures import ProcessPoolExecutor

import numpy as np

from benchmarks._common import save

GPS = (0.05, 0.15, 0.34, 0.7)
SEEDS = 16
VARIANTS = {"ekf": ("ekf", {}), "ekf, paper's encoder gain": ("ekf", {"encoder_scale_gain": True}),
            "batch": ("batch", {}),
            "batch, plain walks": ("batch", {"wheel_speed_units": False}),
            "isam2": ("isam2", {}), "fixed-lag": ("fixed-lag", {})}


def _one(args):
    from odomgraph.estimators.schedule import Schedule
    from odomgraph.pipeline import Method, estimate
    from odomgraph.sim.sensor_configs import study_scenario
    from odomgraph.sim.simulate import simulate
    gps, seed, name = args
    method, options = VARIANTS[name]
    sc = study_scenario(1, gps, 0.005)
    est = estimate(simulate(sc, seed), Method(method), Schedule(sc.calibrate_until), **options)
    return est.mean[-1, 8:11] / np.array(sc.scales) - 1


def main():
    out, rows = {}, []
    with ProcessPoolExecutor() as pool:
        for gps in GPS:
            for name in VARIANTS:
                err = 100 * np.array(list(pool.map(_one, [(gps, s, name) for s in range(SEEDS)])))
                mean, spread = err.mean(0), err.std(0)
                out[f"{gps}/{name}"] = {"gps_sigma": gps, "variant": name, "mean_pct": mean.tolist(),
                                        "spread_pct": spread.tolist()}
                rows.append(f"| {gps:g} | {name} | " + " | ".join(f"{m:+.2f} ± {s:.2f}" for m, s in zip(mean, spread))
                            + " |")
                print(rows[-1], flush=True)
    md = "\n".join([
        f"# Scale-factor errors with GPS as the only speed reference (config 1, {SEEDS} seeds)", "",
        "Mean ± spread over seeds of the final error, %.", "",
        "| GPS σ m | estimator | ticks/m L | ticks/m R | track |", "|---|---|---|---|---|", *rows])
    save("speed_shrinkage", {"seeds": SEEDS, "results": out}, md)


if __name__ == "__main__":
    main()
