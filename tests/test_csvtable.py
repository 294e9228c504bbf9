"""The two CSV readers agree: the one-parse path (csvtable._read_plain) gives
exactly what the row-by-row path gives, or declines; and the writer's
vectorised number formatting is Python's repr."""
from __future__ import annotations

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from odomgraph.io import csvtable as C

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def tables(draw):
    """CSV text of a plain numeric table with the quirks the contract allows:
    CRLF, a byte-order mark is read_text's, comment and blank lines before
    the header, blank lines after it, rows written twice, real-clock stamps."""
    ncol = draw(st.integers(1, 5))
    n = draw(st.integers(0, 30))
    epoch = draw(st.booleans())
    t0 = 1_700_000_000.0 if epoch else draw(st.floats(-100, 100))
    t = t0 + np.cumsum(draw(st.lists(st.floats(0.001, 2.0), min_size=n, max_size=n)) or [0.0])[:n]
    cols = [np.char.mod("%.6f", t) if n else []]
    for _ in range(ncol - 1):
        cols.append([repr(x) for x in draw(st.lists(finite, min_size=n, max_size=n))])
    rows = [",".join(c[i] for c in cols) for i in range(n)]
    if rows and draw(st.booleans()):
        k = draw(st.integers(0, len(rows) - 1))
        rows.insert(k, rows[k])                       # a row written twice
    nl = "\r\n" if draw(st.booleans()) else "\n"
    head = draw(st.sampled_from(["", "# a comment\n", "\n# c\n\n"]))
    gap = draw(st.sampled_from(["", nl, nl + nl]))
    names = ["t"] + [f"c{j}" for j in range(1, ncol)]
    return head + ",".join(names) + nl + gap + nl.join(rows) + draw(st.sampled_from(["", nl, nl + nl])), names


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(tables())
def test_plain_read_equals_row_by_row(tmp_path_factory, case):
    text, names = case
    p = tmp_path_factory.mktemp("csv") / "f.csv"
    fast = C._read_plain(p, text, ("t",), tuple(names[1:]), ())
    slow = C._read_rows(p, text, ("t",), tuple(names[1:]), ())
    assert fast is not None                           # plain tables take the fast path
    assert fast.keys() == slow.keys()
    for k in fast:
        assert np.array_equal(fast[k], slow[k]), k


def test_plain_read_declines_what_it_cannot_name(tmp_path):
    p = tmp_path / "f.csv"
    for text in ("t,a\n1,2\n3,4,5\n",        # a long row
                 "t,a\n1,2,3\n4\n",          # a long row and a short one: the same total
                 "t,a\n1,nan\n", "t,a\n1,\n", "t,a\n1,x\n", "t,a\n1,2\n# late comment\n3,4\n",
                 "t,a\n1,2\n   \n3,4\n",
                 "t,a,b\n0.0, ,2\n1.0,3,4\n",   # a blank field (numpy.fromstring reads -1)
                 "t,a\n0.0,2, \n",
                 "t\n1\n \n3\n",                # a line of blanks in a one-column file
                 "t,a\n0.1,2\r3\n"):              # a carriage return inside a line
        assert C._read_plain(p, text, ("t",), (), ()) is None, text


def test_errors_name_the_line_on_either_path(tmp_path):
    import pytest

    from odomgraph.errors import LogFormatError
    p = tmp_path / "gyro.csv"
    p.write_text("t,omega\n0.0,0.1\n0.1,0.2\n0.1,0.3\n")
    with pytest.raises(LogFormatError, match=r"gyro.csv:4: time does not increase"):
        C.read_table(p, ("t", "omega"))
    p.write_text("t,omega\n0.0,0.1\n\n0.1,0.2\n0.1,0.3\n")
    with pytest.raises(LogFormatError, match=r"gyro.csv:5: time does not increase"):
        C.read_table(p, ("t", "omega"))
    # real-clock stamps a few ms apart are shown whole, not both as 1.7e+09 (a probe's)
    p.write_text("t,omega\n1700000000.125,0.1\n1700000000.005,0.2\n")
    with pytest.raises(LogFormatError, match=r"\(t = 1700000000.005 after 1700000000.125\)"):
        C.read_table(p, ("t", "omega"))


@settings(max_examples=50, deadline=None)
@given(st.lists(finite, min_size=0, max_size=50))
def test_written_floats_are_repr(tmp_path_factory, xs):
    p = tmp_path_factory.mktemp("w") / "f.csv"
    C.write_table(p, {"t": np.arange(len(xs), dtype=float), "x": np.asarray(xs, float)},
                  {"t": "%.3f"})
    want = "t,x\n" + "".join(f"{k:.3f},{float(x)!r}\n" for k, x in enumerate(xs))
    assert p.read_text() == want


def test_a_copy_is_the_same_text_on_either_path(tmp_path):
    """"0.1,5" then "0.10,5" are equal numbers but no copy: both readers keep both rows."""
    p = tmp_path / "f.csv"
    text = "t,x\n0.1,5\n0.10,5\n0.2,6\n0.2,6\n"
    fast = C._read_plain(p, text, ("t", "x"), (), ())
    slow = C._read_rows(p, text, ("t", "x"), (), ())
    assert fast["_duplicates"] == slow["_duplicates"] == 1
    assert np.array_equal(fast["t"], slow["t"]) and np.array_equal(fast["_line"], slow["_line"])


def test_a_sensor_file_with_a_header_and_no_rows_is_said(tmp_path):
    """A gps.csv (or gyro.csv) holding only its header read as no sensor
    without a word (a probe): the log now says so, one warning each."""
    from odomgraph.io.log import read_log, write_log
    from odomgraph.sim.scenarios import paper
    from odomgraph.sim.simulate import simulate
    d = write_log(simulate(paper(10.0), 5), tmp_path / "log")
    for name in ("gps.csv", "gyro.csv"):
        head = (d / name).read_text().splitlines()[0]
        (d / name).write_text(head + "\n")
    log = read_log(d)
    assert [w for w in log.warnings if "a header and no rows" in w] == [
        "gps.csv: a header and no rows: the log has no gps measurements",
        "gyro.csv: a header and no rows: the log has no gyro measurements"]
