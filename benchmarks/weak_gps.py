"""Scale-factor error against its own sigma with a weak speed reference.

The paper scenario without slip events, 60 s, GPS at 2 Hz with 0.5 m noise
(configured truthfully, so only the estimators are judged), seeds 1-3, every
estimator with a 20 s calibration window and the noise model off. Writes
results/weak_gps.{json,md}; README "Known limitations" quotes it.

    python -m benchmarks.weak_gps
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from benchmarks._common import save
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import Method, estimate
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import paper

SEEDS = (1, 2, 3)
GPS_SIGMA, GPS_HZ = 0.5, 2.0


def main():
    rows = {}
    for m in Method:
        err, z = [], []
        for seed in SEEDS:
            base = paper(60.0).with_(slips=())
            sc = base.with_(robot=base.robot.with_(gps_sigma=GPS_SIGMA), rates=replace(base.rates, gps=GPS_HZ))
            log = inject(sc, Faults(), seed)
            est = estimate(log, m, Schedule(20.0), fit_noise=False)
            e = est.mean[-1, 8:11] / np.array(sc.scales) - 1.0
            err.append((100 * e).tolist())
            z.append((e / est.sigma[-1, 8:11]).tolist())
        rows[m.value] = {"error_pct": err, "z": z, "max_abs_z": float(np.max(np.abs(z)))}
    md = [f"# Scale factors with {GPS_SIGMA:g} m GPS at {GPS_HZ:g} Hz (paper, 60 s, seeds "
          f"{', '.join(map(str, SEEDS))})", "",
          "Final error % (ticks/m L, R, track) and error / own sigma, per seed.", "",
          "| estimator | error % | error / sigma | worst abs(error / sigma) |", "|---|---|---|---|"]
    for name, r in rows.items():
        md.append(f"| {name} | " + "; ".join(", ".join(f"{v:+.1f}" for v in e) for e in r["error_pct"]) + " | "
                  + "; ".join(", ".join(f"{v:+.1f}" for v in e) for e in r["z"]) + f" | {r['max_abs_z']:.1f} |")
    save("weak_gps", {"gps_sigma": GPS_SIGMA, "gps_hz": GPS_HZ, "seeds": list(SEEDS), "rows": rows}, "\n".join(md))


if __name__ == "__main__":
    main()
