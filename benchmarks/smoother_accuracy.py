"""Issue 3 accuracy: EKF, batch, iSAM2 (smoothed and online) and fixed-lag side
by side on the paper scenario, 20 seeds, same logs.

Targets: batch scale-factor errors at most half the EKF's and slip RMS at most
0.7x; the iSAM2 online estimate no worse than the EKF; every estimator
consistent (>= 95 % of rows inside +-3 sigma). Writes results/smoother_accuracy.*

Beside them, the track-width floor (odomgraph.analysis.bounds): an oracle that
knows the true heading, the slip-free intervals and both wheel scale factors,
on the same seeds (realised) and over 200 seeds (its expected RMS and the
Cramer-Rao sigma). Plot: results/smoother_accuracy_track.png.

    python -m benchmarks.smoother_accuracy [--seeds 20]
"""
from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from benchmarks._common import RESULTS, save
from odomgraph.analysis.bounds import track_width_bound
from odomgraph.analysis.study import summarize
from odomgraph.runs import run_study
from odomgraph.sim.scenarios import paper

BOUND_SEEDS = 200

STATES = ("x", "y", "slip_left", "slip_right", "scale_left", "scale_right", "scale_track")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, default=20)
    args = ap.parse_args(argv)
    sc = paper()
    seeds = range(args.seeds)
    summaries, results = {}, {}
    for method in ("ekf", "batch", "isam2", "fixed-lag"):
        res = run_study(sc, seeds, method=method)
        results[method] = res
        summaries[method] = summarize(res)
        if method == "isam2":
            results["isam2 online"] = [r.online for r in res]
            summaries["isam2 online"] = summarize(results["isam2 online"])
    ekf = summaries["ekf"]
    bound = _track_floor(sc, args.seeds)
    per_seed = {m: [r.scale_rel_error[2] for r in res] for m, res in results.items()}
    rows = []
    for name, s in summaries.items():
        cov = min(s.coverage_min[k] for k in STATES)
        ratio_scale = "/".join(f"{a / b:.2f}" for a, b in zip(s.scale_rel_error_rms, ekf.scale_rel_error_rms))
        ratio_slip = "/".join(f"{a / b:.2f}" for a, b in zip(s.slip_rms_pooled, ekf.slip_rms_pooled))
        rows.append(f"| {name} | {s.rms_position:.4f} | "
                    + " / ".join(f"{100 * v:.3f}" for v in s.scale_rel_error_rms) + f" | {ratio_scale} | "
                    + f"{s.slip_rms_pooled[0]:.4f} / {s.slip_rms_pooled[1]:.4f} | {ratio_slip} | {100 * cov:.1f} |")
    track_ekf = ekf.scale_rel_error_rms[2]
    b_rows = [
        ("oracle, whole log", bound["same_seeds_rms"][0], bound["expected_rms"][0], bound["crlb"][0]),
        ("oracle, calibration window only (what the EKF uses)", bound["same_seeds_rms"][1],
         bound["expected_rms"][1], bound["crlb"][1]),
    ]
    md = "\n".join([
        f"Paper scenario, {args.seeds} seeds, identical logs for every estimator.", "",
        "| estimator | RMS position m | scale error RMS % (L / R / track) | vs EKF | slip RMS L / R m/s | vs EKF "
        "| worst 3σ coverage % |",
        "|---|---|---|---|---|---|---|", *rows, "",
        "Targets: batch scale ≤ 0.5× and slip ≤ 0.7× the EKF; isam2 online ≤ 1× the EKF; coverage ≥ 95 % "
        "(x, y, slips, scale factors, worst seed).", "",
        "Track-width floor: an oracle that knows the true heading, which intervals are slip-free and both wheel "
        "scale factors, so only encoder noise is left (odomgraph.analysis.bounds).", "",
        f"| oracle | track RMS %, same {args.seeds} seeds | vs EKF | expected RMS % ({BOUND_SEEDS} seeds) "
        "| Cramér–Rao σ % |",
        "|---|---|---|---|---|",
        *[f"| {n} | {100 * a:.3f} | {a / track_ekf:.2f} | {100 * e:.3f} | {100 * c:.3f} |" for n, a, e, c in b_rows],
        "",
        f"The target for track (≤ 0.5× the EKF, {100 * 0.5 * track_ekf:.3f} %) lies below the whole-log oracle "
        f"({100 * bound['same_seeds_rms'][0]:.3f} % on the same seeds, {100 * bound['expected_rms'][0]:.3f} % "
        "expected).",
    ])
    _plot(per_seed, bound, track_ekf)
    save("smoother_accuracy", {**{k: dataclasses.asdict(v) for k, v in summaries.items()}, "track_floor": bound}, md)


def _track_floor(sc, seeds: int) -> dict:
    """The oracle's track error on the first ``seeds`` seeds and over BOUND_SEEDS (whole log, window only)."""
    from odomgraph.sim.simulate import simulate
    err, crlb = [], []
    for seed in range(BOUND_SEEDS):
        log = simulate(sc, seed)
        whole = track_width_bound(log)
        window = track_width_bound(log, t_end=log.encoders.t[0] + sc.calibrate_until)
        err.append((whole.error, window.error))
        crlb.append((whole.sigma, window.sigma))
    err, crlb = np.array(err), np.array(crlb)
    return {"per_seed": np.abs(err[:seeds, 0]).tolist(),
            "same_seeds_rms": np.sqrt(np.mean(err[:seeds] ** 2, 0)).tolist(),
            "expected_rms": np.sqrt(np.mean(err**2, 0)).tolist(),
            "expected_mean": np.mean(err, 0).tolist(),
            "crlb": np.sqrt(np.mean(crlb**2, 0)).tolist()}


def _plot(per_seed: dict, bound: dict, track_ekf: float) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = [*per_seed, "oracle"]
    vals = [*per_seed.values(), bound["per_seed"]]
    fig, ax = plt.subplots(figsize=(8, 4))
    rng = np.random.default_rng(0)
    for i, v in enumerate(vals):
        v = 100 * np.asarray(v)
        ax.plot(i + rng.uniform(-0.15, 0.15, v.size), v, "o", ms=4, alpha=0.7)
        ax.plot([i - 0.3, i + 0.3], [np.sqrt(np.mean(v**2))] * 2, "k-", lw=2)
    ax.axhline(100 * 0.5 * track_ekf, color="C3", ls="--", label="target: 0.5 × EKF RMS")
    ax.axhline(100 * bound["expected_rms"][0], color="0.4", ls=":", label="oracle expected RMS (200 seeds)")
    ax.set_xticks(range(len(names)), names)
    ax.set_ylabel("|track-width error| %")
    ax.set_title("Paper scenario: final track-width error per seed (bar: RMS)")
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    fig.savefig(RESULTS / "smoother_accuracy_track.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
