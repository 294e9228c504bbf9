"""The smoothers' sparse slip prior, checked and unchecked, on logs with slip events.

After a calibration window the smoothers hold slip near zero with a sparse
Cauchy prior on the joint slip norm (graph.slip_prior_rows). With weak fixes
it read one-wheel slips as too little common-mode slip and bent the whole
path, confidently (24th session). estimators.priorcheck checks it against
the prior-free solution. This benchmark measures, on the yard and paper
scenarios with their own slip events, over a grid of fix quality and seeds,
plus a common-mode push (both wheels slipping for 20 s) and controls
without slip events:

- the share of rows with x, y or heading outside 3 sigma, the largest
  error / sigma, and the position RMS, for the EKF, batch as shipped
  (checked), batch with the prior unchecked (``slip_check=False``), batch
  with no prior after the window (``slip_cauchy=None``, run_batch alone:
  no noise fit), isam2 and
  fixed-lag as shipped;
- the check's distance (95th percentile, sigma), and what it did: batch's
  prior-free switch, the incremental smoothers' flag;
- batch's wall time checked / unchecked (the second solve's cost).

Writes results/slip_prior.{json,md,png}; README "Known limitations" and
estimators/priorcheck.py quote it.

    python -m benchmarks.slip_prior
"""
from __future__ import annotations

import re
import time
from dataclasses import replace

import numpy as np

from benchmarks._common import RESULTS, save
from odomgraph import state as S
from odomgraph.estimators.batch import SmootherOptions, run_batch
from odomgraph.estimators.schedule import Schedule
from odomgraph.pipeline import estimate
from odomgraph.result import status_of
from odomgraph.sim.faults import Faults, inject
from odomgraph.sim.scenarios import SlipEvent, paper, yard

DURATION = 180.0
#: (GPS sigma [m], rate [Hz]): survey grade to a weak consumer receiver.
GPS = ((0.05, 5.0), (0.5, 2.0), (1.0, 1.0), (3.0, 1.0))
SEEDS = (11, 12)
#: A snowplow pushing snow: both wheels 0.3 m/s faster than the ground for 20 s, 2.5 m fixes at 1 Hz.
PUSH = {"gps_sigma": 2.5, "gps_hz": 1.0, "start": 60.0, "end": 80.0, "speed": 0.3, "seeds": (31, 32)}
#: Controls: no slip events, 0.5 m fixes at 2 Hz.
CONTROL = {"gps_sigma": 0.5, "gps_hz": 2.0, "seeds": (15, 16)}
#: (row name, method, options)
ROWS = (("ekf", "ekf", {}), ("batch", "batch", {}), ("batch, prior unchecked", "batch", {"slip_check": False}),
        # (run_batch itself: estimate() reads an option of None as its default)
        ("batch, no prior after the window", "run_batch", {"slip_cauchy": None}),
        ("isam2", "isam2", {}), ("fixed-lag", "fixed-lag", {}))
CHECKED = re.compile(r"slip prior checked \(([0-9.]+) sigma")


def _log(make, gps_sigma, gps_hz, seed, slips=None):
    sc = make(DURATION)
    sc = sc.with_(robot=sc.robot.with_(gps_sigma=gps_sigma), rates=replace(sc.rates, gps=gps_hz))
    if slips is not None:
        sc = sc.with_(slips=slips)
    return inject(sc, Faults(), seed)


def _score(est, log) -> dict:
    z = []
    for k in (S.X, S.Y, S.THETA):
        e = est.mean[:, k] - log.truth.at(S.NAMES[k], est.t)
        if k == S.THETA:
            e = np.angle(np.exp(1j * e))
        z.append(np.abs(e) / est.sigma[:, k])
    z = np.max(z, axis=0)
    ex, ey = est.mean[:, 0] - log.truth.at("x", est.t), est.mean[:, 1] - log.truth.at("y", est.t)
    d = [float(m.group(1)) for n in est.notes for m in [CHECKED.search(n)] if m]
    return {"outside": float(np.mean(z > 3.0)), "max_z": float(z.max()), "rms_m": float(np.sqrt(np.mean(ex**2 + ey**2))),
            "status": status_of(est)[0], "distance": d[-1] if d else None,
            "prior_free": any("prior-free solution is given" in w for w in est.warnings),
            "flagged": any("contradict the sparse zero-slip prior" in f for f in est.flags)}


def _case(name: str, log) -> dict:
    out = {"case": name, "rows": {}}
    for row, method, opts in ROWS:
        t0 = time.perf_counter()
        if method == "run_batch":
            est = run_batch(log, Schedule(20.0), SmootherOptions(**opts))
        else:
            est = estimate(log, method, Schedule(20.0), **opts)
        out["rows"][row] = {**_score(est, log), "wall_s": time.perf_counter() - t0}
    print(name, {k: (round(v["outside"], 3), v["distance"]) for k, v in out["rows"].items()}, flush=True)
    return out


def _cases() -> list[dict]:
    cases = []
    for make in (yard, paper):
        for gs, hz in GPS:
            for seed in SEEDS:
                cases.append(_case(f"{make.__name__}, {gs:g} m at {hz:g} Hz, seed {seed}", _log(make, gs, hz, seed)))
    for seed in PUSH["seeds"]:
        push = tuple(SlipEvent(w, PUSH["start"], PUSH["end"], PUSH["speed"]) for w in ("left", "right"))
        cases.append(_case(f"yard, push {PUSH['speed']:g} m/s both wheels {PUSH['start']:g}-{PUSH['end']:g} s, "
                           f"{PUSH['gps_sigma']:g} m at {PUSH['gps_hz']:g} Hz, seed {seed}",
                           _log(yard, PUSH["gps_sigma"], PUSH["gps_hz"], seed, slips=push)))
    for make, seed in zip((paper, yard), CONTROL["seeds"]):
        cases.append(_case(f"{make.__name__}, no slip events, {CONTROL['gps_sigma']:g} m at {CONTROL['gps_hz']:g} Hz, "
                           f"seed {seed}", _log(make, CONTROL["gps_sigma"], CONTROL["gps_hz"], seed, slips=())))
    return cases


def _summary(cases: list[dict]) -> dict:
    out = {}
    for row, _, _ in ROWS:
        r = [c["rows"][row] for c in cases]
        out[row] = {"worst_outside": max(x["outside"] for x in r), "median_rms_m": float(np.median([x["rms_m"] for x in r])),
                    "over_5pct_ok": sum(x["outside"] > 0.05 and x["status"] == "ok" for x in r), "n": len(r),
                    "prior_free": sum(x["prior_free"] for x in r), "flagged": sum(x["flagged"] for x in r)}
    b = [c["rows"]["batch"]["wall_s"] / c["rows"]["batch, prior unchecked"]["wall_s"] for c in cases]
    out["batch_wall_ratio"] = {"median": float(np.median(b)), "max": float(np.max(b))}
    return out


def _plot(cases: list[dict]) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    rows = [r for r, _, _ in ROWS]
    fig, ax = plt.subplots(figsize=(12, 5.5))
    w = 0.8 / len(rows)
    x = np.arange(len(cases))
    for i, r in enumerate(rows):
        ax.bar(x + (i - len(rows) / 2 + 0.5) * w, [100 * c["rows"][r]["outside"] for c in cases], w, label=r)
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xticks(x, [c["case"].replace(", seed", "\nseed").replace(" both wheels", "\nboth wheels") for c in cases],
                  rotation=90, fontsize=7)
    ax.set_ylabel("rows with x, y or heading outside 3 sigma [%]")
    ax.set_title("Sparse slip prior after the window: checked (as shipped) against unchecked, no prior, the EKF")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(RESULTS / "slip_prior.png", dpi=110)


def main():
    cases = _cases()
    summ = _summary(cases)
    md = [f"# The sparse slip prior, checked ({DURATION:g} s logs, 20 s window, the scenarios' slip events)", "",
          "Rows outside 3 sigma (x, y or heading) %, largest error / sigma, position RMS m; the check's distance "
          "(95th percentile, sigma; '-': not run: no slip after the window); P: batch gave the prior-free solution; "
          "F: flagged (isam2, fixed-lag).", "",
          "| case | " + " | ".join(r for r, _, _ in ROWS) + " | distance |", "|---" * (len(ROWS) + 2) + "|"]
    for c in cases:
        cells = []
        for r, _, _ in ROWS:
            v = c["rows"][r]
            mark = (" P" if v["prior_free"] else "") + (" F" if v["flagged"] else "")
            cells.append(f"{100 * v['outside']:.1f} / {v['max_z']:.1f} / {v['rms_m']:.2f}{mark}")
        dist = c["rows"]["batch"]["distance"]
        md.append(f"| {c['case']} | " + " | ".join(cells) + f" | {'-' if dist is None else f'{dist:.1f}'} |")
    md += ["", "| estimator | worst % outside | logs over 5 % with status ok | median position RMS m | "
           "prior-free given | flagged |", "|---|---|---|---|---|---|"]
    for r, _, _ in ROWS:
        s = summ[r]
        md.append(f"| {r} | {100 * s['worst_outside']:.1f} | {s['over_5pct_ok']} of {s['n']} | {s['median_rms_m']:.2f} | "
                  f"{s['prior_free']} | {s['flagged']} |")
    md += ["", f"batch's wall time, checked / unchecked (the second solve): median {summ['batch_wall_ratio']['median']:.2f}x, "
           f"worst {summ['batch_wall_ratio']['max']:.2f}x."]
    _plot(cases)
    save("slip_prior", {"duration_s": DURATION, "gps": GPS, "seeds": SEEDS, "push": PUSH, "control": CONTROL,
                        "cases": cases, "summary": summ}, "\n".join(md))


if __name__ == "__main__":
    main()
