"""Helpers shared by the benchmark scripts: where results go, and the machine."""
from __future__ import annotations

import ast
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


def _module_file(root: Path, name: str) -> Path | None:
    """The project file of module ``name`` (odomgraph.factors is factors/);
    the benchmarks' and tests' own modules are followed for what they import."""
    parts = name.split(".")
    if parts[:2] == ["odomgraph", "factors"]:
        parts = ["factors", *parts[2:]]
    elif parts[0] not in ("odomgraph", "factors", "benchmarks", "tests"):
        return None
    base = root.joinpath(*parts)
    for f in (base.with_suffix(".py"), base / "__init__.py"):
        if f.is_file():
            return f
    return None


def _walk_with_code_strings(tree):
    """ast.walk, and into string constants that parse as Python with an
    import in them: the code a benchmark hands to ``python -c`` in a child
    process (benchmarks.online, benchmarks.log_io), whose imports would
    otherwise be invisible and its results never stale."""
    import ast
    for node in ast.walk(tree):
        yield node
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and "import " in node.value:
            try:
                inner = ast.parse(node.value)
            except SyntaxError:
                continue
            yield from _walk_with_code_strings(inner)


def static_sources(*paths: Path) -> dict[str, str]:
    """{path: code_hash} of every project file that ``paths`` import, read
    from their syntax trees (every import statement, also those inside
    functions), transitively. For benchmarks whose work runs in other
    processes (a pool, a pytest subprocess), where this process's modules
    are not what ran; it errs on the side of listing too much."""
    root = RESULTS.parent.parent
    seen: set[Path] = set()
    todo = [Path(p).resolve() for p in paths]
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        for node in _walk_with_code_strings(ast.parse(f.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                names = [node.module] + [f"{node.module}.{a.name}" for a in node.names]
            for n in names:
                # a package's __init__ runs too when a submodule is imported
                for k in range(1, n.count(".") + 2):
                    g = _module_file(root, ".".join(n.split(".")[:k]))
                    if g is not None and g.resolve() not in seen:
                        todo.append(g.resolve())
    out = {}
    for f in seen:
        rel = f.relative_to(root)
        if rel.parts[0] in ("odomgraph", "factors"):
            out[str(rel)] = code_hash(f)
    return dict(sorted(out.items()))


def save(name: str, data: dict, markdown: str, ran: tuple[Path, ...] = ()) -> None:
    """Write results/<name>.json and results/<name>.md (and print the markdown).
    The JSON records the machine, the commit and the hashes of the sources
    the run imported, and of what the benchmark's script and the files
    ``ran`` import (static_sources: the code that ran in other processes)."""
    import sys
    RESULTS.mkdir(exist_ok=True)
    # The benchmark's own script too: its seeds, grid points or log lengths
    # run in pools whose imports this process never sees.
    main = getattr(sys.modules.get("__main__"), "__file__", None)
    if main and Path(main).resolve().parent == RESULTS.parent:
        ran = (Path(main), *ran)
    src = {**static_sources(*ran), **sources()}
    data = {"machine": machine(), "sources": dict(sorted(src.items())), "sources_kind": "code", **data}
    (RESULTS / f"{name}.json").write_text(json.dumps(data, indent=2) + "\n")
    (RESULTS / f"{name}.md").write_text(markdown + "\n")
    print(markdown)
