"""Write an output directory all at once, or not at all.

Files go to a hidden sibling directory; only when everything is written is it
renamed into place. A failure (or Ctrl-C) leaves the previous output, or
nothing, never a half-written directory.
"""
from __future__ import annotations

import contextlib
import shutil
import tempfile
from pathlib import Path

from odomgraph.errors import OutputDirError

# Files whose presence marks a directory as one odomgraph wrote, so that
# overwriting it cannot destroy unrelated user data.
_OURS = ("summary.json", "robot.toml", "report.html", "results.json", "figure.png")


@contextlib.contextmanager
def atomic_output_dir(path: Path | str):
    """Context manager yielding a temporary directory that becomes ``path``."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise OutputDirError(f"{path}: exists and is not a directory")
        if any(path.iterdir()) and not any((path / f).exists() for f in _OURS):
            raise OutputDirError(f"{path}: exists, is not empty and was not written by odomgraph; "
                                 "choose another output directory")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-", dir=path.parent))
    try:
        yield tmp
        if path.exists():
            old = path.with_name(f".{path.name}.old-{tmp.name[-8:]}")
            path.rename(old)
            tmp.rename(path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
