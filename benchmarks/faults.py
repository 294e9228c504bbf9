"""The fault suite (issue 11): every estimator on every fault of
odomgraph.analysis.faults.CASES, against the same log without the fault.
Writes results/faults.{json,md,png}: per fault and estimator, finished or
not, position RMS and its ratio to the clean run, 3-sigma coverage, the
worst scale-factor error, status, and the case's own numbers (slip over a
stall, coverage through an outage), with the acceptance checks of the issue.

    python -m benchmarks.faults [--seeds 11 12] [--duration 150]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from benchmarks._common import RESULTS, save
from odomgraph.analysis.faults import CASES, METHODS
from odomgraph.runs import run_case


def checks(r: dict) -> list[str]:
    """The issue's acceptance checks this row fails (empty: passes)."""
    bad = []
    if not r["finished"]:
        return ["did not finish: " + r["reason"][:80]]
    if r["nan"]:
        bad.append("NaN")
    c, m = r["case"], r["method"]
    if c == "outliers":
        if r["rms_ratio"] is not None and r["rms_ratio"] > 1.5:
            bad.append(f"RMS {r['rms_ratio']:.2f}x clean > 1.5")
        if r["worst_scale_error"] is not None and r["worst_scale_error"] > 0.01:
            bad.append(f"scale error {100 * r['worst_scale_error']:.2f} % > 1 %")
        if r["coverage_3sigma_xy"] < 0.95:
            bad.append(f"coverage {r['coverage_3sigma_xy']:.2f} < 0.95")
    if c == "outage":
        if (r.get("outage_coverage_3sigma") or 0) < 0.95:
            bad.append(f"outage coverage {r.get('outage_coverage_3sigma'):.2f} < 0.95")
        if r.get("reconverged_after_s", 0) > 10.0:
            bad.append(f"reconverged after {r['reconverged_after_s']:.0f} s > 10")
        if not r.get("sigma_grows_in_outage"):
            bad.append("sigma did not grow in the outage")
    if c == "stall":
        f = 2.0 if m == "ekf" else 1.0
        if r["stall_slip_rms_mps"] >= 0.1 * f:
            bad.append(f"stall slip RMS {r['stall_slip_rms_mps']:.3f} >= {0.1 * f:g}")
        if r["stall_position_rms_m"] > 0.1 * f:
            bad.append(f"stall position RMS {r['stall_position_rms_m']:.3f} > {0.1 * f:g}")
    if c in ("still", "rotation"):
        if not r["unobservable"]:
            bad.append("nothing reported unobservable")
    return bad


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seeds", type=int, nargs="+", default=[11, 12])
    ap.add_argument("--duration", type=float, default=150.0)
    args = ap.parse_args(argv)
    rows = []
    t0 = time.perf_counter()
    for name in CASES:
        for method in METHODS:
            for seed in args.seeds:
                r = run_case(name, method, seed, args.duration)
                r["failed_checks"] = checks(r)
                rows.append(r)
                print(f"{name:16s} {method:9s} seed {seed}: " + ("ok" if not r["failed_checks"] else
                                                                 "; ".join(r["failed_checks"])), flush=True)
    wall = time.perf_counter() - t0

    def cell(rs, key, fmt):
        vals = [r.get(key) for r in rs if r["finished"] and r.get(key) is not None]
        return "–" if not vals else " / ".join(fmt(v) for v in vals)
    lines = ["| fault | estimator | finished | RMS m | × clean | 3σ cov | worst scale % | status | extra | checks |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for name, case in CASES.items():
        for method in METHODS:
            rs = [r for r in rows if r["case"] == name and r["method"] == method]
            fin = sum(r["finished"] for r in rs)
            extra = ""
            if name == "stall":
                extra = "slip " + cell(rs, "stall_slip_rms_mps", lambda v: f"{v:.3f}") + " m/s, pos " + \
                        cell(rs, "stall_position_rms_m", lambda v: f"{v:.3f}") + " m"
            if name == "outage":
                extra = "cov " + cell(rs, "outage_coverage_3sigma", lambda v: f"{v:.2f}") + ", back in " + \
                        cell(rs, "reconverged_after_s", lambda v: f"{v:.0f}") + " s"
            if name in ("still", "rotation"):
                extra = "unobservable: " + ", ".join(sorted({u for r in rs if r["finished"] for u in r["unobservable"]}))
            failed = sorted({f for r in rs for f in r["failed_checks"]})
            lines.append(f"| {name} | {method} | {fin}/{len(rs)} | {cell(rs, 'rms_position_m', lambda v: f'{v:.3f}')} "
                         f"| {cell(rs, 'rms_ratio', lambda v: f'{v:.2f}')} "
                         f"| {cell(rs, 'coverage_3sigma_xy', lambda v: f'{v:.2f}')} "
                         f"| {cell(rs, 'worst_scale_error', lambda v: f'{100 * v:.2f}')} "
                         f"| {', '.join(sorted({r.get('status', 'stopped') for r in rs}))} | {extra} "
                         f"| {'pass' if not failed else '; '.join(failed)} |")
    n_fail = sum(bool(r["failed_checks"]) for r in rows)
    desc = "\n".join(f"- **{c.name}**: {c.description}" for c in CASES.values())
    md = f"""# Fault suite (`python -m benchmarks.faults`)

Seeds {', '.join(map(str, args.seeds))}; the paper's robot without its slip events, {args.duration:g} s, GPS 10 Hz,
gyro 25 Hz, encoders 20 Hz, a 20 s calibration window; each fault against the same seed without it
(odomgraph.analysis.faults). Values per seed, separated by '/'. {len(rows)} runs in {wall:.0f} s;
{n_fail} fail an acceptance check of issue 11.

{desc}

{chr(10).join(lines)}
"""
    save("faults", {"seeds": args.seeds, "duration": args.duration, "wall_s": wall, "rows": rows}, md)
    _plot(rows)
    return 0


def _plot(rows):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    names = list(CASES)
    ratio = np.full((len(names), len(METHODS)), np.nan)
    for i, n in enumerate(names):
        for j, m in enumerate(METHODS):
            v = [r["rms_ratio"] for r in rows if r["case"] == n and r["method"] == m and r["finished"]
                 and r.get("rms_ratio") is not None]
            if v:
                ratio[i, j] = max(v)
    fig, ax = plt.subplots(figsize=(6.5, 0.42 * len(names) + 1.2))
    im = ax.imshow(np.log10(np.clip(ratio, 0.5, 100)), cmap="RdYlGn_r", vmin=-0.3, vmax=1.0, aspect="auto")
    for i in range(len(names)):
        for j in range(len(METHODS)):
            fails = any(r["failed_checks"] for r in rows if r["case"] == names[i] and r["method"] == METHODS[j])
            txt = "stop" if np.isnan(ratio[i, j]) else f"{ratio[i, j]:.2f}"
            ax.text(j, i, txt + (" ✗" if fails else ""), ha="center", va="center", fontsize=8)
    ax.set_xticks(range(len(METHODS)), METHODS)
    ax.set_yticks(range(len(names)), names)
    ax.set_title("position RMS against the fault-free run (worst seed); ✗ fails a check")
    fig.colorbar(im, ax=ax, label="log10 ratio")
    fig.tight_layout()
    fig.savefig(RESULTS / "faults.png", dpi=110)


if __name__ == "__main__":
    raise SystemExit(main())
