"""Reading and writing the log CSV files with errors that name file and line.

Format (LOG_FORMAT.md): comma separated, one header row, ``#`` starts a
comment line. The parse is vectorised; only when it fails do we walk the rows
to name the offending line, so an hour-long log still reads in well under a
second.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from odomgraph.errors import LogFormatError


def read_table(path: Path, required: tuple[str, ...], optional: tuple[str, ...] = (),
               text_columns: tuple[str, ...] = ()) -> dict[str, np.ndarray]:
    """Read a CSV with a header into {column: array}.

    Numeric columns must be finite; ``t`` (if required) must strictly increase.
    Columns in ``text_columns`` are returned as arrays of str. Unknown extra
    columns are allowed and ignored. The arrays carry file line numbers in the
    special key ``"_line"`` for later error messages.
    """
    path = Path(path)
    if not path.is_file():
        raise LogFormatError(path, "file is missing")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise LogFormatError(path, "is not UTF-8 text") from None
    header, header_line, rows, lines = None, 0, [], []
    for lineno, raw in enumerate(text.splitlines(), start=1):
        s = raw.strip()
        if not s or s.startswith("#"):
            continue
        if header is None:
            header, header_line = [c.strip() for c in s.split(",")], lineno
            continue
        rows.append(s)
        lines.append(lineno)
    if header is None:
        raise LogFormatError(path, "has no header row")
    missing = [c for c in required if c not in header]
    if missing:
        raise LogFormatError(path, f"missing column(s) {', '.join(missing)} (header is '{','.join(header)}')",
                             header_line)
    if len(set(header)) != len(header):
        raise LogFormatError(path, "duplicate column names in header", header_line)
    ncol = len(header)
    fields = [r.split(",") for r in rows]
    for f, ln in zip(fields, lines):
        if len(f) != ncol:
            raise LogFormatError(path, f"expected {ncol} fields, found {len(f)}", ln)
    lines_arr = np.asarray(lines, dtype=np.int64)
    out: dict[str, np.ndarray] = {"_line": lines_arr}
    for name in (*required, *optional):
        if name not in header:
            continue
        j = header.index(name)
        col = [f[j].strip() for f in fields]
        if name in text_columns:
            for v, ln in zip(col, lines):
                if not v:
                    raise LogFormatError(path, f"empty value in column '{name}'", ln)
            out[name] = np.asarray(col, dtype=str)
            continue
        try:
            arr = np.asarray(col, dtype=float) if col else np.zeros(0)
        except ValueError:
            for v, ln in zip(col, lines):
                try:
                    float(v)
                except ValueError:
                    raise LogFormatError(path, f"column '{name}': '{v}' is not a number", ln) from None
            raise
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad))
            raise LogFormatError(path, f"column '{name}': {col[k]} is not a finite number", lines[k])
        out[name] = arr
    if "t" in out and len(out["t"]) > 1:
        dt = np.diff(out["t"])
        if (dt <= 0).any():
            k = int(np.argmax(dt <= 0)) + 1
            raise LogFormatError(path, f"time does not increase (t = {out['t'][k]!r} after {out['t'][k - 1]!r})",
                                 lines[k])
    return out


def write_table(path: Path, columns: dict[str, np.ndarray], formats: dict[str, str] | None = None,
                comment: str | None = None) -> None:
    """Write {name: 1-D array} as CSV with a header. Floats use repr precision
    unless ``formats`` gives a %-format for a column."""
    formats = formats or {}
    names = list(columns)
    n = len(next(iter(columns.values()))) if columns else 0
    cols = []
    for name in names:
        a = np.asarray(columns[name])
        fmt = formats.get(name)
        if a.dtype.kind in "US":
            cols.append(a.astype(str))
        elif fmt:
            cols.append(np.char.mod(fmt, a))
        elif a.dtype.kind in "iu":
            cols.append(a.astype(str))
        else:
            cols.append(np.asarray([repr(float(x)) for x in a]) if n else np.zeros(0, dtype=str))
    buf = io.StringIO()
    if comment:
        for line in comment.splitlines():
            buf.write(f"# {line}\n")
    buf.write(",".join(names) + "\n")
    for i in range(n):
        buf.write(",".join(c[i] for c in cols) + "\n")
    Path(path).write_text(buf.getvalue(), encoding="utf-8")

