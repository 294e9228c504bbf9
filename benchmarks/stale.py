"""Which results in benchmarks/results/ predate a change to the code they measure?

Each results JSON records the code hash (syntax tree without docstrings,
``_common.code_hash``) of every project source file its run imported
(``_common.sources``). This lists, per results
file, the sources that changed since (or "no record" for older files).
python -m benchmarks.stale  (exit 1 when any is stale)
"""
from __future__ import annotations

import json
import sys

from benchmarks._common import RESULTS, code_hash


def stale() -> dict[str, list[str]]:
    """{results file: [changed or removed sources]}, or ["no record"] (also
    for an empty record: a benchmark whose work ran in other processes and
    recorded none of it, before _common.static_sources)."""
    root = RESULTS.parent.parent
    out = {}
    for p in sorted(RESULTS.glob("*.json")):
        data = json.loads(p.read_text())
        rec = data.get("sources")
        if not rec or data.get("sources_kind") != "code":
            out[p.name] = ["no record of the code it ran"]
            continue
        changed = []
        for rel, h in rec.items():
            f = root / rel
            if not f.exists() or code_hash(f) != h:
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
