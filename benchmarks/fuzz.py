"""The fuzz suite of tests/test_fuzz.py run long, on a fresh random seed:
damaged log files, robot.toml edits, importer inputs and CLI options. Every
case must end in a valid result or one ``odomgraph: error:`` line with exit 1,
with no input file changed. Writes results/fuzz.{json,md}: the cases tried
per target, their outcomes, the most frequent error classes, and any failure.

    python -m benchmarks.fuzz [--scale 20]
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from benchmarks._common import save

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scale", type=float, default=20.0, help="multiple of the CI suite's examples")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        report = Path(tmp) / "tally.json"
        env = dict(os.environ, ODOMGRAPH_FUZZ_SCALE=str(args.scale), ODOMGRAPH_FUZZ_REPORT=str(report))
        t0 = time.perf_counter()
        proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "tests/test_fuzz.py",
                               "-x"], cwd=ROOT, env=env, capture_output=True, text=True)
        wall = time.perf_counter() - t0
        tally = json.loads(report.read_text()) if report.exists() else {"outcomes": {}, "errors": {}}
    outcomes = tally["outcomes"]
    total = sum(outcomes.values())
    passed = proc.returncode == 0
    targets = {}
    for k, n in outcomes.items():
        target, result = k.rsplit(": ", 1)
        targets.setdefault(target, {"ok": 0, "error": 0})[result] += n
    rows = "\n".join(f"| {t} | {v['ok'] + v['error']} | {v['ok']} | {v['error']} |" for t, v in sorted(targets.items()))
    errs = "\n".join(f"| {e or '(blank)'} | {n} |" for e, n in list(tally["errors"].items())[:25])
    failure = "" if passed else "\n\n**FAILED**:\n\n```\n" + proc.stdout[-4000:] + "\n```"
    md = f"""# Fuzz run (`python -m benchmarks.fuzz --scale {args.scale:g}`)

{total} cases in {wall:.0f} s, every one {'kept' if passed else 'did NOT keep'} the contract (a valid result, or
one `odomgraph: error:` line with exit 1; no input file changed; no NaN in an output).

| target | cases | valid result | one-line error |
|---|---|---|---|
{rows}

Most frequent error classes (numbers, paths and quoted values removed):

| error | cases |
|---|---|
{errs}{failure}"""
    save("fuzz", {"scale": args.scale, "cases": total, "wall_s": wall, "passed": passed, "targets": targets,
                  "errors": tally["errors"]}, md, ran=(Path(__file__).resolve().parent.parent / "tests" / "test_fuzz.py",))
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
