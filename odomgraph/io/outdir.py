"""The output policy: write an output all at once or not at all, and never
destroy what odomgraph did not create.

* Files go to a hidden sibling directory ``.NAME.tmp-PID-XXXX``; only when
  everything is written is it renamed into place. A failure (or Ctrl-C, or
  SIGTERM) leaves the previous output, or nothing, never a half-written
  directory. Temporaries left by a killed run (its PID is gone) are removed
  by the next run that writes beside them.
* Every output directory carries a marker file, ``.odomgraph``, listing the
  files odomgraph wrote there, each with its sha256. An existing directory is
  replaced only if it is empty, or carries the marker and holds nothing but
  the files it lists, each unchanged since it was written (a hand-edited
  robot.toml is the user's). A file name alone (``robot.toml``,
  ``summary.json``) proves nothing: a log directory and a user's project both
  have one.
* A log directory (marker kind "log": what ``import`` and ``simulate``
  wrote) is data, and is never replaced: not by a report, an estimate, nor a
  new log (``compare LOG2 -o LOG1`` deleted LOG1's recording).
* An output is refused when it is an input, lies inside one or holds one
  (``estimate LOG -o LOG`` would delete the log), or is the current directory.
* Directories and files get the permissions the umask gives, like any file a
  shell command creates (``tempfile`` would make them private, mode 0700).
"""
from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import tempfile
from pathlib import Path

from odomgraph.errors import OutputDirError

MARKER = ".odomgraph"


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True          # someone else's live process
    return True


def _why(exc: OSError) -> str:
    return exc.strerror or type(exc).__name__


def _resolved(p: Path) -> Path:
    try:
        return p.expanduser().resolve()
    except (OSError, RuntimeError) as exc:   # a symlink loop
        raise OutputDirError(f"{p}: cannot resolve the path ({exc})") from None


def check_output(path: Path | str, inputs=(), directory: bool = True) -> Path:
    """Refuse an output path that could destroy what odomgraph did not create.

    ``inputs``: paths the command reads (a log directory, an imported file).
    Returns the path. Raises OutputDirError with a one-line reason.
    """
    p = Path(path)
    if str(path) == "":
        raise OutputDirError("the output path is empty")
    rp = _resolved(p)
    for inp in inputs:
        if inp is None:
            continue
        ri = _resolved(Path(inp))
        if rp == ri:
            raise OutputDirError(f"{p}: is an input of this command; choose another output")
        if ri in rp.parents:
            raise OutputDirError(f"{p}: lies inside the input {inp}; choose an output outside it")
        if rp in ri.parents:
            raise OutputDirError(f"{p}: holds the input {inp}, which writing it would destroy; "
                                 "choose another output")
    cwd = _resolved(Path.cwd())
    if directory and (rp == cwd or rp in cwd.parents):
        raise OutputDirError(f"{p}: is the current directory (or holds it); name a new directory for the output")
    if p.is_symlink():
        raise OutputDirError(f"{p}: is a symbolic link; give the real path")
    if not p.exists():
        bad = next((q for q in rp.parents if q.exists() and not q.is_dir()), None)
        if bad is not None:
            raise OutputDirError(f"{p}: cannot be created, {bad} is a file")
        return p
    if directory:
        if not p.is_dir():
            raise OutputDirError(f"{p}: exists and is not a directory")
        _refuse_to_replace(p)
    elif p.is_dir():
        raise OutputDirError(f"{p}: is a directory; give a file name")
    return p


def _entries(d: Path) -> list[str]:
    """Every file and directory under d, relative, '/'-separated."""
    out = []
    for root, dirs, files in os.walk(d):
        rel = Path(root).relative_to(d)
        for name in (*dirs, *files):
            out.append((rel / name).as_posix())
    return sorted(out)


def _sha256(f: Path) -> str:
    import hashlib
    h = hashlib.sha256()
    with open(f, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _marker(d: Path) -> dict | None:
    """The marker's contents, or None when there is none (or it is unreadable)."""
    try:
        m = json.loads((d / MARKER).read_text(encoding="utf-8"))
        return m if isinstance(m, dict) and isinstance(m.get("files"), list) else None
    except (OSError, ValueError):
        return None


def _foreign_entries(d: Path) -> list[str]:
    """Entries of d that its marker does not list, or whose contents changed
    since it was written ([] when d may be replaced)."""
    try:
        present = _entries(d)
    except OSError as exc:
        raise OutputDirError(f"{d}: cannot be read ({_why(exc)})") from None
    if not present:
        return []
    m = _marker(d)
    if m is None:
        return [e for e in present if "/" not in e] or present
    listed = set(m["files"])
    out = [e for e in present if e != MARKER and e not in listed]
    # Markers before the hashes were recorded have none: their names are all there is to check.
    hashes = m.get("sha256")
    if hashes is not None and not isinstance(hashes, dict):
        return [MARKER + " (not one odomgraph wrote)"]
    for name, h in (hashes or {}).items():
        f = d / name
        try:
            if f.is_file() and _sha256(f) != h:
                out.append(f"{name} (changed since odomgraph wrote it)")
        except OSError as exc:
            raise OutputDirError(f"{f}: cannot be read ({_why(exc)})") from None
    return out


def _refuse_to_replace(p: Path) -> None:
    """OutputDirError unless the existing directory ``p`` may be replaced."""
    foreign = _foreign_entries(p)
    if foreign:
        raise OutputDirError(f"{p}: exists and holds files odomgraph did not write ({', '.join(foreign[:3])}"
                             f"{', ...' if len(foreign) > 3 else ''}); choose another output directory")
    m = _marker(p)
    if m is not None and m.get("kind") == "log":
        raise OutputDirError(f"{p}: holds a log (written by odomgraph import or simulate), and a log is never "
                             "replaced; choose another output directory, or delete it yourself first")


_TEMP = re.compile(r"^\.(?P<name>.+)\.(tmp|old)-(?P<pid>\d+)-[^/]+$")


def clean_stale(parent: Path, name: str) -> None:
    """Remove the temporaries a killed run left beside ``parent/name`` (their PID is gone)."""
    try:
        candidates = list(parent.iterdir())
    except OSError:
        return
    for c in candidates:
        m = _TEMP.match(c.name)
        if not m or m.group("name") != name or _alive(int(m.group("pid"))):
            continue
        if c.is_dir() and (c / MARKER).exists():
            shutil.rmtree(c, ignore_errors=True)
        elif c.is_file():
            with contextlib.suppress(OSError):
                c.unlink()


def _write_marker(d: Path, kind: str) -> None:
    from odomgraph import __version__
    files = [e for e in _entries(d) if e != MARKER]
    hashes = {e: _sha256(d / e) for e in files if (d / e).is_file()}
    (d / MARKER).write_text(json.dumps({"written_by": "odomgraph", "version": __version__, "kind": kind,
                                        "files": files, "sha256": hashes}, indent=1) + "\n", encoding="utf-8")


@contextlib.contextmanager
def atomic_output_dir(path: Path | str, inputs=(), kind: str = "output"):
    """Context manager yielding a temporary directory that becomes ``path``.

    See the module doc for what may be replaced. ``kind`` names the output in
    the marker (log, estimate, report).
    """
    path = check_output(path, inputs)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(path.parent, path.name)
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.tmp-{os.getpid()}-", dir=path.parent))
        os.chmod(tmp, 0o777 & ~_umask())
        _write_marker(tmp, kind)
    except OSError as exc:
        raise OutputDirError(f"{path}: cannot be created ({_why(exc)})") from None
    try:
        yield tmp
        _write_marker(tmp, kind)
        if path.exists():
            try:
                _refuse_to_replace(path)          # it may have changed while we computed
            except OutputDirError as exc:
                raise OutputDirError(f"{exc} (it changed while this ran; nothing was replaced)") from None
            old = path.with_name(f".{path.name}.old-{os.getpid()}-{tmp.name[-8:]}")
            path.rename(old)
            tmp.rename(path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(path)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise OutputDirError(f"{path}: cannot be written ({_why(exc)}); nothing was written") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def check_output_file(path: Path | str, inputs=(), is_ours=lambda p: False) -> Path:
    """check_output for a file: besides, an existing file is replaced only
    if ``is_ours(path)`` says odomgraph wrote it. Returns the path."""
    path = check_output(path, inputs, directory=False)
    if path.exists() and not is_ours(path):
        raise OutputDirError(f"{path}: exists and was not written by odomgraph; choose another output file")
    return path


@contextlib.contextmanager
def atomic_output_file(path: Path | str, inputs=(), is_ours=lambda p: False):
    """Context manager yielding a temporary file path that becomes ``path``
    (check_output_file first)."""
    path = check_output_file(path, inputs, is_ours)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        clean_stale(path.parent, path.name)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.tmp-{os.getpid()}-", dir=path.parent)
        os.close(fd)
        os.chmod(tmp, 0o666 & ~_umask())
    except OSError as exc:
        raise OutputDirError(f"{path}: cannot be created ({_why(exc)})") from None
    try:
        yield Path(tmp)
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise OutputDirError(f"{path}: cannot be written ({_why(exc)}); nothing was written") from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise
