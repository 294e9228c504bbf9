"""Helpers shared by the benchmark scripts: where results go, and the machine."""
from __future__ import annotations

import json
import os
import platform
import subprocess
from datetime import datetime, timezone
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"


def _git(*args) -> str:
    try:
        return subprocess.run(["git", *args], capture_output=True, text=True, cwd=RESULTS.parent).stdout.strip()
    except OSError:
        return ""


#: The commit when the benchmark started (the code it imports is read then),
#: and whether the project's sources differed from it.
START = {"commit": _git("rev-parse", "--short", "HEAD"),
         "dirty": bool(_git("status", "--porcelain", "--", "odomgraph", "factors")),
         "time": datetime.now(timezone.utc).timestamp()}


def machine() -> dict:
    import numpy
    return {"date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "cpus": os.cpu_count(),
            "python": platform.python_version(), "numpy": numpy.__version__, "commit": START["commit"],
            "sources_dirty": START["dirty"]}


def code_hash(path: Path) -> str:
    """sha256[:16] of a Python file's code: its syntax tree without
    docstrings, so that comments, docstrings and layout do not make a result
    stale, and any change to what runs does."""
    import ast
    import hashlib
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if (isinstance(body, list) and body and isinstance(body[0], ast.Expr)
                and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str)):
            node.body = body[1:] or [ast.Pass()]
    return hashlib.sha256(ast.dump(tree, include_attributes=False).encode()).hexdigest()[:16]


def sources() -> dict[str, str]:
    """{path: code_hash} of every project source file this process has
    imported: what the results depend on (benchmarks.stale, and the suite's
    tests/test_readme.py, compare them with the files as they are now)."""
    import sys
    root = RESULTS.parent.parent
    out = {}
    for mod in list(sys.modules.values()):
        f = getattr(mod, "__file__", None)
        if not f:
            continue
        p = Path(f).resolve()
        try:
            rel = p.relative_to(root)
        except ValueError:
            continue
        if rel.parts[0] in ("odomgraph", "factors") and p.suffix == ".py":
            # A file edited while the benchmark ran is not what it ran: no hash.
            changed = p.stat().st_mtime > START["time"]
            out[str(rel)] = "changed during the run" if changed else code_hash(p)
    return dict(sorted(out.items()))


def save(name: str, data: dict, markdown: str) -> None:
    """Write results/<name>.json and results/<name>.md (and print the markdown).
    The JSON records the machine, the commit and the hashes of the sources
    the run imported."""
    RESULTS.mkdir(exist_ok=True)
    data = {"machine": machine(), "sources": sources(), "sources_kind": "code", **data}
    (RESULTS / f"{name}.json").write_text(json.dumps(data, indent=2) + "\n")
    (RESULTS / f"{name}.md").write_text(markdown + "\n")
    print(markdown)
