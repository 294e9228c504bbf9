"""Re-run every benchmark, one at a time (they share the cores), then
regenerate the README blocks from the results.

    python -m benchmarks.run_all            # every benchmark
    python -m benchmarks.run_all --stale    # only those benchmarks.stale lists
    python -m benchmarks.run_all --only faults real_data

Each writes benchmarks/results/<name>.json with the commit and the code hash
of every source it imported; tests/test_readme.py fails while a results file
is older than the code it ran (benchmarks.stale). Wall time on this 2-core
machine: about 80 minutes, most of it the fault table (22 min) and the
Monte-Carlo study (20 min).
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time

#: Timing-sensitive benchmarks first, so that nothing else has warmed or
#: fragmented the machine; then the long studies.
ORDER = ("ekf_throughput", "ekf_vectorised", "smoother_scaling", "online", "log_io", "report_size", "ekf_accuracy",
         "smoother_accuracy", "speed_shrinkage", "track_bias", "velocity_means", "real_data",
         "calibration_transfer", "weak_gps", "slip_prior", "outrun", "faults", "fuzz", "montecarlo_study")


#: Arguments other than the defaults: the fuzz run the README quotes.
ARGS = {"fuzz": ["--scale", "3"]}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--stale", action="store_true", help="only the benchmarks whose results are stale")
    ap.add_argument("--only", nargs="*", default=None, help="these benchmarks (names in ORDER)")
    args = ap.parse_args(argv)
    names = list(ORDER)
    if args.only:
        unknown = set(args.only) - set(ORDER)
        if unknown:
            ap.error(f"unknown benchmark(s) {sorted(unknown)}; known: {', '.join(ORDER)}")
        names = [n for n in ORDER if n in args.only]
    if args.stale:
        from benchmarks.stale import stale
        old = {k.removesuffix(".json") for k in stale()}
        names = [n for n in names if n in old]
    failed = []
    for n in names:
        t0 = time.perf_counter()
        print(f"== {n}", flush=True)
        r = subprocess.run([sys.executable, "-m", f"benchmarks.{n}", *ARGS.get(n, [])])
        print(f"== {n}: exit {r.returncode} in {time.perf_counter() - t0:.0f} s", flush=True)
        if r.returncode:
            failed.append(n)
    subprocess.run([sys.executable, "-m", "benchmarks.readme_blocks"])
    if failed:
        print(f"failed: {', '.join(failed)}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
