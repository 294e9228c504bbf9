"""Reading and writing the log CSV files with errors that name file and line.

Format (LOG_FORMAT.md): comma separated, one header row, ``#`` starts a
comment line, and the file may start with a UTF-8 byte-order mark. The parse
is vectorised; only when it fails do we walk the rows to name the offending
line, so an hour-long log still reads in well under a second.
"""
from __future__ import annotations

import codecs
import re
from pathlib import Path

import numpy as np

from odomgraph.errors import LogFormatError


def shown(value: str, limit: int = 40) -> str:
    """``value`` as it can appear inside a one-line message: control and other
    unprintable characters escaped (a stray carriage return must not split the
    message), long values cut."""
    s = value if value.isprintable() else value.encode("unicode_escape").decode("ascii")
    return s if len(s) <= limit else s[:limit] + "..."


def read_text(path: Path | str) -> str:
    """A text file as str: UTF-8, a leading byte-order mark dropped.

    Raises LogFormatError when the file is missing or unreadable, and names
    the line and column of the first byte that is not UTF-8.
    """
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise LogFormatError(path, "file is missing") from None
    except IsADirectoryError:
        raise LogFormatError(path, "is a directory, not a file") from None
    except OSError as exc:
        raise LogFormatError(path, f"cannot be read ({exc.strerror})") from None
    if data.startswith(codecs.BOM_UTF8):
        data = data[len(codecs.BOM_UTF8):]
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        raise LogFormatError(path, f"is not UTF-8 text (byte 0x{data[exc.start]:02x} at column {col})", line) from None


def text_lines(text: str):
    """(line number, line) pairs, numbered as an editor numbers them: only
    newline ends a line (str.splitlines would also split at form feeds and
    other separators, and then every later line number would be off)."""
    for lineno, raw in enumerate(text.split("\n"), start=1):
        yield lineno, raw.rstrip("\r")


def header_of(path: Path | str) -> list[str]:
    """The column names of a CSV's header row ([] when it has none). Reads
    only up to the header (a file that is not UTF-8 there, or cannot be
    read, is refused as ``read_text`` refuses it)."""
    try:
        with open(path, "rb") as f:
            for lineno, raw in enumerate(f, start=1):
                if lineno == 1 and raw.startswith(codecs.BOM_UTF8):
                    raw = raw[len(codecs.BOM_UTF8):]
                s = raw.decode("utf-8").strip()
                if s and not s.startswith("#"):
                    return [c.strip() for c in s.split(",")]
    except (OSError, UnicodeDecodeError):
        read_text(path)                    # raises LogFormatError naming what is wrong
        raise
    return []


def read_table(path: Path, required: tuple[str, ...], optional: tuple[str, ...] = (),
               text_columns: tuple[str, ...] = (), equal_times: bool = False) -> dict[str, np.ndarray]:
    """Read a CSV with a header into {column: array}.

    Numeric columns must be finite; ``t`` (if required) must strictly increase,
    or, with ``equal_times``, never decrease (ranges.csv: several beacons may
    share a time stamp). Columns in ``text_columns`` are returned as arrays of
    str. Unknown extra columns are allowed and ignored. The arrays carry file
    line numbers in the special key ``"_line"`` for later error messages, and
    ``"_duplicates"`` counts exact repeats of the row before, which are dropped.
    """
    path = Path(path)
    text = read_text(path)
    fast = _read_plain(path, text, required, optional, text_columns)
    if fast is not None:
        out = fast
    else:
        out = _read_rows(path, text, required, optional, text_columns)
    if "t" in out and len(out["t"]) > 1:
        dt = np.diff(out["t"])
        wrong = dt < 0 if equal_times else dt <= 0
        if wrong.any():
            k = int(np.argmax(wrong)) + 1
            what = "decreases" if equal_times else "does not increase"
            # every digit written (real-clock stamps, 1.7e9 s, print alike at 9 significant digits)
            a, b = (np.format_float_positional(float(out["t"][i]), trim="-") for i in (k, k - 1))
            raise LogFormatError(path, f"time {what} (t = {a} after {b})", int(out["_line"][k]))
    return out


def _header(path: Path, text: str, required: tuple[str, ...]) -> tuple[list[str], int, int]:
    """(column names, the header's line number, offset of the text after it)."""
    pos, lineno = 0, 1
    while pos <= len(text):
        end = text.find("\n", pos)
        stop = len(text) if end < 0 else end
        s = text[pos:stop].strip()
        if s and not s.startswith("#"):
            header = [c.strip() for c in s.split(",")]
            missing = [c for c in required if c not in header]
            if missing:
                raise LogFormatError(path, f"missing column(s) {', '.join(missing)} (header is "
                                           f"'{shown(','.join(header), 80)}')", lineno)
            if len(set(header)) != len(header):
                raise LogFormatError(path, "duplicate column names in header", lineno)
            return header, lineno, stop + 1
        pos, lineno = stop + 1, lineno + 1
    raise LogFormatError(path, "has no header row")


def _read_plain(path: Path, text: str, required, optional, text_columns) -> dict[str, np.ndarray] | None:
    """``read_table``'s result by C-level parses (numpy.loadtxt, chunk by
    chunk into one preallocated array) when the rows after the header are
    plain: numbers only, no comment or blank line among them, every value
    finite, a text column absent. None for anything else, and ``_read_rows``
    then reads it row by row (and names the line of whatever is wrong).
    About 10x faster. The text is not copied (rows are found by offsets into
    it), and each column is a view of one (columns, rows) array: the numbers
    are held once, beside the text and one chunk's parse."""
    header, header_line, start = _header(path, text, required)
    if any(c in header for c in text_columns):
        return None
    if "\r" in text:
        text = text.replace("\r\n", "\n")   # a Windows file: one copy, then as any other
        if "\r" in text:
            return None                    # a carriage return inside a line: the slow path names it
        header, header_line, start = _header(path, text, required)
    if text.find("#", start) >= 0 or not text.isascii():
        return None                        # a comment among the rows, or text that holds no number
    lo = _LEAD.match(text, start).end()
    first = header_line + 1 + text.count("\n", start, lo)
    hi = len(text)
    while hi > lo and text[hi - 1].isspace():
        hi -= 1
    ncol = len(header)
    if hi == lo:
        a = np.zeros((ncol, 0))
    else:
        if text.find("\n\n", lo, hi) >= 0:
            return None                    # blank lines: the slow path numbers the rows
        a = _parse_numbers(text, lo, hi, ncol)
        if a is None:
            return None
    lines = first + np.arange(a.shape[1], dtype=np.int64)
    # A row written twice is dropped, as _read_rows drops it: the same text
    # (rows with equal numbers are the candidates; "0.1" and "0.10" are not a copy).
    dup = np.flatnonzero((a[:, 1:] == a[:, :-1]).all(0)) + 1 if a.shape[1] > 1 else np.zeros(0, np.int64)
    rows = None
    if dup.size:
        rows = text[lo:hi].split("\n")
        dup = np.array([k for k in dup if rows[k].strip() == rows[k - 1].strip()], dtype=np.int64)
    if dup.size:
        keep = np.ones(a.shape[1], bool)
        keep[dup] = False
        a, lines = a[:, keep], lines[keep]
    out: dict[str, np.ndarray] = {"_line": lines, "_duplicates": np.asarray(int(dup.size))}
    for name in (*required, *optional):
        if name in header:
            out[name] = a[header.index(name)]
    tt = out.get("t")
    if tt is not None and len(tt) and ORIGIN_ABOVE <= float(np.max(tt)) and float(np.max(np.abs(tt))) < ORIGIN_BELOW:
        # Real-clock stamps: split from their text, exact (split_stamps).
        j = header.index("t")
        rows = text[lo:hi].split("\n") if rows is None else rows
        col = [r.split(",", j + 1)[j].strip() for r in rows]
        if dup.size:
            col = [v for v, k in zip(col, keep) if k]
        out["_t_sec"], out["_t_frac"] = split_stamps(col)
    return out


#: Blank lines and spaces before the first row.
_LEAD = re.compile(r"\s*")
#: Characters of text numpy.loadtxt parses at a time (its transient copy is
#: about four bytes per character, so this bounds the parse's extra memory).
_CHUNK = 1 << 18


def _parse_numbers(text: str, lo: int, hi: int, ncol: int) -> np.ndarray | None:
    """(ncol, rows) floats of ``text[lo:hi]``, newline-separated rows of
    exactly ncol comma-separated finite numbers with no blank line; None when
    any row is otherwise (a field that is empty or no number, a row too long
    or too short, a line loadtxt would skip), so that the row-by-row reader
    names it. Column-major, so that each column is a contiguous view."""
    import io
    nrow = text.count("\n", lo, hi) + 1
    a = np.empty((ncol, nrow))
    pos, k = lo, 0
    while pos < hi:
        end = text.find("\n", min(pos + _CHUNK, hi), hi)
        end = hi if end < 0 else end
        try:
            part = np.loadtxt(io.StringIO(text[pos:end]), delimiter=",", comments=None, ndmin=2, dtype=float)
        except ValueError:                 # a field that is no number or empty, a row of another length
            return None
        if part.shape[1] != ncol or k + len(part) > nrow:
            return None
        a[:, k:k + len(part)] = part.T
        k += len(part)
        pos = end + 1
    # loadtxt skips lines of blanks: then fewer rows than lines, and the line numbers would be off.
    if k != nrow or not np.isfinite(a).all():
        return None
    return a


def _read_rows(path: Path, text: str, required, optional, text_columns) -> dict[str, np.ndarray]:
    """``read_table`` row by row: every row split in Python (the general
    path: comments, blank lines, text columns, and any error, named by line)."""
    header, header_line, rows, lines = None, 0, [], []
    for lineno, raw in text_lines(text):
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
        raise LogFormatError(path, f"missing column(s) {', '.join(missing)} (header is "
                                   f"'{shown(','.join(header), 80)}')", header_line)
    if len(set(header)) != len(header):
        raise LogFormatError(path, "duplicate column names in header", header_line)
    ncol = len(header)
    fields = [r.split(",") for r in rows]
    for f, ln in zip(fields, lines):
        if len(f) != ncol:
            raise LogFormatError(path, f"expected {ncol} fields, found {len(f)}", ln)
    # A row written twice (same stamp, same values) is a logging fault that
    # carries no conflicting information: drop the copy and count it.
    dup = [k for k in range(1, len(rows)) if rows[k] == rows[k - 1]]
    if dup:
        drop = set(dup)
        fields = [f for k, f in enumerate(fields) if k not in drop]
        lines = [ln for k, ln in enumerate(lines) if k not in drop]
    lines_arr = np.asarray(lines, dtype=np.int64)
    out: dict[str, np.ndarray] = {"_line": lines_arr, "_duplicates": np.asarray(len(dup))}
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
                    raise LogFormatError(path, f"column '{name}': '{shown(v)}' is not a number", ln) from None
            raise
        bad = ~np.isfinite(arr)
        if bad.any():
            k = int(np.argmax(bad))
            raise LogFormatError(path, f"column '{name}': {shown(col[k])} is not a finite number", lines[k])
        out[name] = arr
        # (beyond ORIGIN_BELOW a stamp is no seconds; the clock check says so)
        if name == "t" and len(arr) and ORIGIN_ABOVE <= float(np.max(arr)) and float(np.max(np.abs(arr))) < ORIGIN_BELOW:
            out["_t_sec"], out["_t_frac"] = split_stamps(col)
    return out


#: Stamps from this many seconds on are on a real clock (1.7e9 s since 1970),
#: where a float64 keeps only 0.24 us: they are split into integer seconds and
#: a fraction as they are read, and the log counts from an integer origin.
ORIGIN_ABOVE = 1e6
ORIGIN_BELOW = 1e15


def split_stamps(col: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Decimal time stamps as (integer seconds int64, fraction float in [0, 1)),
    exact to the fraction's float precision: "1700000012.345678" gives
    (1700000012, 0.345678), where float("1700000012.345678") is 2e-7 off.
    A stamp in exponent notation carries no more digits than its float."""
    sec = np.empty(len(col), dtype=np.int64)
    frac = np.empty(len(col))
    for k, v in enumerate(col):
        head, dot, tail = v.partition(".")
        if head.lstrip("+").isdigit() and (not tail or tail.isdigit()):
            sec[k], frac[k] = int(head), float("0." + tail) if tail else 0.0
        else:
            x = float(v)
            sec[k] = int(np.floor(x))
            frac[k] = x - sec[k]
    return sec, frac


def stamp_text(t: np.ndarray, origin: int = 0, decimals: int = 6) -> np.ndarray:
    """Times ``t`` [s since ``origin``, an integer second] as decimal strings of
    the absolute stamp with ``decimals`` places, exact in the integer part:
    (12.345678, 1700000000) gives "1700000012.345678"."""
    t = np.asarray(t, dtype=float)
    if not origin:
        return np.char.mod(f"%.{decimals}f", t) if len(t) else np.zeros(0, dtype=str)
    # t - floor(t) is exact in float64, so each fraction rounds to the digits
    # "%.{decimals}f" gives t itself on a small clock (round half to even included).
    whole = np.floor(t)
    frac = np.char.mod(f"%.{decimals}f", t - whole)
    carry = np.char.startswith(frac, "1")  # 0.9999996 -> "1.000000"
    sec = (whole + carry).astype(np.int64) + np.int64(origin)
    return np.asarray([f"{s}{f[1:]}" for s, f in zip(sec.tolist(), frac.tolist())], dtype=str)


def write_table(path: Path, columns: dict[str, np.ndarray], formats: dict[str, str] | None = None,
                comment: str | None = None) -> None:
    """Write {name: 1-D array} as CSV with a header. Floats use repr precision
    unless ``formats`` gives a %-format for a column."""
    formats = formats or {}
    names = list(columns)
    n = len(next(iter(columns.values()))) if columns else 0
    # Each column becomes a list of strings, formatted and joined by C-level
    # iteration (map, zip, str.join): no Python loop per row or per value.
    # Floats without a format are written as repr (shortest round trip).
    cols = []
    for name in names:
        a = np.asarray(columns[name])
        fmt = formats.get(name)
        if a.dtype.kind in "US":
            cols.append(a.astype(str).tolist())
        elif fmt:
            cols.append(np.char.mod(fmt, a).tolist())
        elif a.dtype.kind in "iu":
            cols.append(list(map(str, a.tolist())))
        else:
            cols.append(list(map(repr, a.astype(np.float64).tolist())))
    if any(len(c) != n for c in cols):
        raise ValueError(f"write_table {path}: columns of unequal length {[len(c) for c in cols]}")
    head = "".join(f"# {ln}\n" for ln in comment.splitlines()) if comment else ""
    body = "\n".join(map(",".join, zip(*cols))) + "\n" if n else ""
    Path(path).write_text(head + ",".join(names) + "\n" + body, encoding="utf-8")
