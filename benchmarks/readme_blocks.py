"""README numbers written from benchmarks/results/, never by hand (issue 18).

A block in README.md or benchmarks/README.md is

    <!-- results:NAME -->
    ...generated text...
    <!-- /results:NAME -->

and NAME is one of BLOCKS below: a function of the results directory that
returns the block's markdown. ``python -m benchmarks.readme_blocks`` rewrites
every block; ``--check`` exits 1 naming each block that differs, which
``tests/test_readme.py`` runs in the default suite. Each block ends with the
results file and the commit it was produced at, so a reader can tell how old
a number is.
"""
from __future__ import annotations

import json
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
READMES = (ROOT / "README.md", ROOT / "benchmarks" / "README.md")
BLOCK = re.compile(r"(<!-- results:(?P<name>[a-z0-9_]+) -->\n)(?P<body>.*?)(<!-- /results:(?P=name) -->)", re.S)


def _load(name: str, results: Path) -> dict:
    return json.loads((results / f"{name}.json").read_text())


def _source(name: str, d: dict) -> str:
    m = d.get("machine", {})
    return f"(`benchmarks/results/{name}.json`, commit {m.get('commit') or '?'}, {m.get('date', '?')[:10]})"


def ekf_accuracy(results: Path) -> str:
    d = _load("ekf_accuracy", results)
    t = d["targets"]
    out = []
    for key, label in (("paper", "Paper scenario"), ("yard", "Unseen `yard` scenario")):
        s = d[key]
        cov = min(v for k, v in s["coverage_min"].items()
                  if k in ("x", "y", "slip_left", "slip_right", "scale_left", "scale_right", "scale_track"))
        out += [f"- **{label}, {s['seeds']} seeds:** worst scale-factor error "
                f"{100 * max(s['scale_rel_error_max']):.2f} % (target < {100 * t['scale']:.1f} %); slip RMS after the "
                f"calibration window {max(s['slip_rms_pooled']):.3f} m/s per wheel over all seeds' rows (target < "
                f"{t['slip']:.2f}; worst single seed {max(s['slip_rms_worst_seed']):.3f}); at least {100 * cov:.1f} % "
                "of rows inside ±3σ for x, y, the slips and the scale factors on the worst seed."]
    return "\n".join(out) + f"\n\n{_source('ekf_accuracy', d)}"


def ekf_throughput(results: Path) -> str:
    d = _load("ekf_throughput", results)
    best = [d[k]["speedup_best"] for k in ("paper", "yard")]
    med = [d[k]["speedup_median_pairwise"] for k in ("paper", "yard")]
    diff = max(d[k]["max_abs_state_difference"] for k in ("paper", "yard"))
    return (f"- **Throughput:** {min(best):.2f}–{max(best):.2f}× the updates per second of the same filter built on "
            f"FilterPy's `ExtendedKalmanFilter` (best of interleaved runs; median pairs {min(med):.2f}–"
            f"{max(med):.2f}×), on the paper and yard logs. The outputs agree to {diff:.1e}.\n\n"
            f"{_source('ekf_throughput', d)}")


def smoother_accuracy(results: Path) -> str:
    d = _load("smoother_accuracy", results)
    e, b, on, tf = d["ekf"], d["batch"], d["isam2 online"], d["track_floor"]
    rel = [x / y for x, y in zip(b["scale_rel_error_rms"], e["scale_rel_error_rms"])]
    slip = max(x / y for x, y in zip(b["slip_rms_pooled"], e["slip_rms_pooled"]))
    oslip = max(x / y for x, y in zip(on["slip_rms_pooled"], e["slip_rms_pooled"]))
    track_e, track_b = e["scale_rel_error_rms"][2], b["scale_rel_error_rms"][2]
    oracle = tf["same_seeds_rms"][0]
    others = {k: d[k]["rms_position"] / b["rms_position"] for k in ("isam2", "fixed-lag")}
    return (f"- **Smoothers against the EKF, on the same {e['seeds']} paper logs:**\n"
            f"  - the batch smoother's ticks-per-metre errors are {min(rel[:2]):.2f}–{max(rel[:2]):.2f}× the EKF's; "
            f"its track-width error is {rel[2]:.2f}× ({100 * track_b:.3f} % against {100 * track_e:.3f} %);\n"
            f"  - an oracle that knows the true heading, the slip-free stretches and both wheel scales gets "
            f"{oracle / track_e:.2f}× the EKF's track error on the same seeds ({100 * tf['expected_rms'][0]:.3f} % "
            f"expected over 200 seeds): the encoder noise of eq. 41 sets that floor (`odomgraph.analysis.bounds`), "
            f"and the smoother is {track_b / oracle:.2f}× the oracle;\n"
            f"  - slip RMS is {slip:.2f}× the EKF's and position error {b['rms_position'] / e['rms_position']:.2f}×;\n"
            f"  - the iSAM2 online (causal) estimate's slip RMS is {oslip:.2f}× the EKF's;\n"
            f"  - iSAM2 and fixed-lag position RMS are "
            + " and ".join(f"{v:.2f}×" for v in others.values()) + " the batch solution's.\n\n"
            + _source("smoother_accuracy", d))


def faults(results: Path) -> str:
    d = _load("faults", results)
    rows = d["rows"]
    cases = list(dict.fromkeys(r["case"] for r in rows))
    out = ["| fault | runs finished | worst RMS × clean | worst ±3σ coverage (x, y) | runs failing a check |",
           "|---|---|---|---|---|"]
    for c in cases:
        rs = [r for r in rows if r["case"] == c]
        fin = [r for r in rs if r["finished"]]
        ratio = max((r["rms_ratio"] for r in fin if r.get("rms_ratio") is not None), default=None)
        cov = min((r["coverage_3sigma_xy"] for r in fin if r.get("coverage_3sigma_xy") is not None), default=None)
        bad = [f"{r['method']} {r['seed']}" for r in rs if r["failed_checks"]]
        out.append(f"| {c} | {len(fin)}/{len(rs)} | " + (f"{ratio:.2f}" if ratio is not None else "–") + " | "
                   + (f"{cov:.2f}" if cov is not None else "–") + " | " + (", ".join(bad) or "none") + " |")
    seeds = ", ".join(str(s) for s in d["seeds"])
    return (f"Every estimator on every fault, seeds {seeds}, {d['duration']:g} s logs, {len(rows)} runs in "
            f"{d['wall_s'] / 60:.0f} min:\n\n" + "\n".join(out) + f"\n\n{_source('faults', d)}")


HONESTY_HEAD = ["| log | estimator | status | RMS m | ±3σ coverage x / y | noise scale applied | warnings |",
                "|---|---|---|---|---|---|---|"]


def honesty_row(log: str, method: str, r: dict, warnings_shown: int = 0) -> str:
    """One row of the real-log honesty table (benchmarks.real_data writes the
    same rows with the first ``warnings_shown`` warnings spelled out)."""
    if not r["finished"]:
        why = f": {r['error'][:90]}" if warnings_shown else ""
        return f"| {log} | {method} | stopped{why} | | | | |"
    cov = r["coverage_3sigma"]
    said = f"{len(r['warnings'])}" + (": " + "; ".join(w[:60] for w in r["warnings"][:warnings_shown])
                                      if warnings_shown else "")
    return (f"| {log} | {method} | {r['status']} | "
            + (f"{r['rms_position_m']:.3f}" if r["rms_position_m"] is not None else "–") + " | "
            + (f"{cov['x']:.2f} / {cov['y']:.2f}" if cov else "–") + " | "
            + (", ".join(f"{k} ×{v:.2g}" for k, v in r["noise_scales"].items()) or "–") + f" | {said} |")


def real_data_honesty(results: Path) -> str:
    d = _load("real_data", results)
    out = list(HONESTY_HEAD)
    for key, r in d["honesty"].items():
        log, method = key.rsplit(" / ", 1)
        out.append(honesty_row(log, method, r))
    tr = ["| calibrated on | held-out check | tested on | share of the oracle's improvement |", "|---|---|---|---|"]
    for key, r in d["honesty_transfer"].items():
        if "error" in r:
            tr.append(f"| {key} | stopped | | |")
            continue
        src, dst = key.split("->")
        h = r["held_out"]
        check = (("passed" if h["passed"] else "failed") + f" ({h['nominal']:.3g} → {h['calibrated']:.3g} "
                 f"{h['unit']})") if h else "none"
        tr.append(f"| {src} | {check} | {dst} | {100 * r['share']:.0f} % |")
    return ("No `[initial]` pose, default options:\n\n" + "\n".join(out)
            + "\n\nCalibrate on one OptiOdom run (1 Hz fixes, no `[initial]`), dead-reckon the others:\n\n"
            + "\n".join(tr) + f"\n\n{_source('real_data', d)}")


BLOCKS = {f.__name__: f for f in (ekf_accuracy, ekf_throughput, smoother_accuracy, faults, real_data_honesty)}


def render(text: str, results: Path = RESULTS) -> str:
    """``text`` with every results block rewritten."""
    def one(m):
        name = m.group("name")
        if name not in BLOCKS:
            raise KeyError(f"unknown results block {name!r} (known: {', '.join(BLOCKS)})")
        return m.group(1) + BLOCKS[name](results).rstrip("\n") + "\n" + m.group(4)
    return BLOCK.sub(one, text)


def differing(results: Path = RESULTS) -> list[str]:
    """"FILE: block NAME" for each block that is not what the results give."""
    out = []
    for p in READMES:
        text = p.read_text(encoding="utf-8")
        new = render(text, results)
        if new != text:
            old_blocks = {m.group("name"): m.group(0) for m in BLOCK.finditer(text)}
            for m in BLOCK.finditer(new):
                if old_blocks.get(m.group("name")) != m.group(0):
                    out.append(f"{p.relative_to(ROOT)}: block {m.group('name')}")
    return out


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if "--check" in argv:
        bad = differing()
        for b in bad:
            print(f"{b} differs from benchmarks/results/ (python -m benchmarks.readme_blocks rewrites it)")
        return 1 if bad else 0
    for p in READMES:
        text = p.read_text(encoding="utf-8")
        new = render(text)
        if new != text:
            p.write_text(new, encoding="utf-8")
            print(f"rewrote {p.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
