"""Which results in benchmarks/results/ predate a change to the code they measure?

Each results JSON written since issue 18 records the hash of every project
source file its run imported (``_common.sources``). This lists, per results
file, the sources that changed since (or "no record" for older files).
python -m benchmarks.stale  (exit 1 when any is stale)
"""
from __future__ import annotations

import hashlib
import json
import sys

from benchmarks._common import RESULTS


def stale() -> dict[str, list[str]]:
    """{results file: [changed or removed sources]}, or ["no record"]."""
    root = RESULTS.parent.parent
    out = {}
    for p in sorted(RESULTS.glob("*.json")):
        rec = json.loads(p.read_text()).get("sources")
        if rec is None:
            out[p.name] = ["no record"]
            continue
        changed = []
        for rel, h in rec.items():
            f = root / rel
            if not f.exists() or hashlib.sha256(f.read_bytes()).hexdigest()[:16] != h:
                changed.append(rel)
        if changed:
            out[p.name] = changed
    return out


def main() -> int:
    s = stale()
    for name, changed in s.items():
        print(f"{name}: {', '.join(changed[:6])}{' ...' if len(changed) > 6 else ''}")
    if not s:
        print("every results file is current")
    return 1 if s else 0


if __name__ == "__main__":
    sys.exit(main())
