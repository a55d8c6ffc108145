"""CSV reading: the same numbers from pandas, numpy's C reader and the csv module, and strict checks
(short rows, extra fields, repeated names, units, BOM, non-UTF-8, NUL, not a regular file)."""

from __future__ import annotations

import os
import sys

import numpy as np
import pytest

import arxid
import arxid.data.csvio
from arxid import DataError
from arxid.data.csvio import CsvFile


@pytest.fixture(params=["pandas", "numpy"])
def reader(request, monkeypatch):
    """Run the test with pandas installed, and again as if it were not (numpy's C reader)."""
    if request.param == "pandas":
        pytest.importorskip("pandas")
    else:
        monkeypatch.setitem(sys.modules, "pandas", None)
    return request.param


def _write(tmp_path, text: str | bytes, name: str = "log.csv"):
    p = tmp_path / name
    p.write_bytes(text.encode("utf-8") if isinstance(text, str) else text)
    return p


def _read(p, **kw):
    return arxid.IOData.from_csv(p, output="y", inputs=["u"], ts=0.01, **kw)


def test_readers_agree_with_python_float_on_every_cell(tmp_path, reader):
    rng = np.random.default_rng(7)
    table = rng.standard_normal((500, 3)) * 10.0 ** rng.integers(-8, 8, (500, 3))
    lines = ["t,y,u"] + [",".join(repr(float(v)) for v in row) for row in table]
    d = _read(_write(tmp_path, "\n".join(lines) + "\n"), extra=["t"])
    np.testing.assert_array_equal(d.y, table[:, 1])  # exact, not approximately
    np.testing.assert_array_equal(d.u[:, 0], table[:, 2])
    np.testing.assert_array_equal(d.extra["t"], table[:, 0])


def test_missing_markers_are_nan_and_other_columns_may_hold_text(tmp_path, reader):
    p = _write(tmp_path, "y,u,mode\n1,2,hover\n,3,hover\nNaN,4,climb\nnull,5,\nNA,6,x\n2,nan,y\n")
    d = _read(p)
    assert np.isnan(d.y[1:5]).all() and d.y[0] == 1 and d.y[5] == 2 and np.isnan(d.u[5, 0])
    assert d.u[:5, 0].tolist() == [2, 3, 4, 5, 6]


def test_text_in_a_column_asked_for_names_row_and_column(tmp_path, reader):
    p = _write(tmp_path, "y,u\n1,2\n2,3\n3,oops\n")
    with pytest.raises(DataError, match="column 'u' row 4 holds 'oops', which is not a number"):
        _read(p)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("y,u,v\n1,2,3\n4,5\n6,7,8\n", "line 3 has 2 fields, fewer than the 3 of the header"),
        ("y,u\n1,2\n3,4,5\n", "line 3 has 3 fields, more than the 2 of the header"),
        ("y,u\n1,2\n3,4\n5\n", "line 4 has 1 fields, fewer"),  # the last line, no newline at the end
        ("y,u\r\n1,2\r\n\r\n3,4,\r\n", "line 4 has 3 fields, more"),  # CRLF, a blank line skipped
    ],
)
def test_rows_with_too_few_or_too_many_fields_are_refused(tmp_path, reader, text, message):
    with pytest.raises(DataError, match=message):
        _read(_write(tmp_path, text))


def test_row_check_holds_across_read_chunks(tmp_path, monkeypatch):
    """The streaming check finds the same first bad line whatever the chunk size (lines cut
    anywhere, CRLF split between chunks), as a line-by-line count does."""
    rng = np.random.default_rng(11)
    for trial in range(60):
        lines = ["y,u,v"]
        for _ in range(int(rng.integers(1, 30))):
            kind = rng.random()
            if kind < 0.1:
                lines.append("")
            else:
                n = 3 if kind < 0.93 else int(rng.integers(1, 6))
                lines.append(",".join(str(int(x)) for x in rng.integers(0, 10**6, n)))
        eol = "\r\n" if trial % 2 else "\n"
        text = eol.join(lines) + (eol if trial % 3 else "")
        bad = [i + 1 for i, line in enumerate(lines) if i and line and line.count(",") != 2]
        monkeypatch.setattr(arxid.data.csvio, "_CHUNK", int(rng.integers(1, 12)))
        p = _write(tmp_path, text)
        if bad:
            with pytest.raises(DataError, match=f"line {bad[0]} has"):
                CsvFile.open(p)
        else:
            CsvFile.open(p)


@pytest.mark.parametrize(
    ("header", "message"),
    [
        ("y,y,u", "columns 1 \\('y'\\) and 2 \\('y'\\) are both the signal 'y'"),
        ("y,u,vbat[V],vbat", "both the signal 'vbat'"),
    ],
)
def test_repeated_column_names_are_refused(tmp_path, header, message):
    n = header.count(",") + 1
    with pytest.raises(DataError, match=message):
        _read(_write(tmp_path, header + "\n" + ",".join(["1"] * n) + "\n"))


def test_units_in_brackets_and_a_byte_order_mark(tmp_path, reader):
    p = _write(tmp_path, b"\xef\xbb\xbfy [rad],u[N m],vbat[V]\n1,2,3.9\n2,3,3.8\n")
    d = arxid.IOData.from_csv(p, output="y", inputs=["u[N m]"], extra=["vbat"], ts=0.5)
    assert (d.output_name, d.output_unit, d.input_names, d.input_units) == ("y", "rad", ("u",), ("N m",))
    assert d.extra_units == {"vbat": "V"} and d.extra["vbat"].tolist() == [3.9, 3.8]


def test_text_that_is_not_utf8_is_refused_with_its_line(tmp_path):
    p = _write(tmp_path, b"y,u\n1,2\n" + "3,caf\xe9\n".encode("latin-1"))
    with pytest.raises(DataError, match=r"not a UTF-8 text CSV file \(invalid continuation byte at byte 13, line 3\)"):
        _read(p)


def test_nul_bytes_are_a_binary_file(tmp_path):
    with pytest.raises(DataError, match="NUL byte at byte 9 \\(line 3\\)"):
        _read(_write(tmp_path, b"y,u\n1,2\n3\x00,4\n"))


def test_not_a_regular_file_is_refused_without_reading(tmp_path):
    with pytest.raises(DataError, match="not a regular file"):
        _read(tmp_path)
    fifo = tmp_path / "pipe.csv"
    os.mkfifo(fifo)  # opening it for reading would block for ever
    with pytest.raises(DataError, match="not a regular file"):
        _read(fifo)
    with pytest.raises(DataError, match="does not exist"):
        _read(tmp_path / "nope.csv")
    with pytest.raises(DataError, match="is empty"):
        _read(_write(tmp_path, b""))


def test_quoted_cells_are_read_by_the_csv_module(tmp_path, reader):
    p = _write(tmp_path, '"y","u","note"\n"1","2","a, b"\n3,4,"c"\n')
    d = _read(p)
    assert d.y.tolist() == [1, 3] and d.u[:, 0].tolist() == [2, 4]
    with pytest.raises(DataError, match="row 3 has 2 fields, fewer than the 3"):
        _read(_write(tmp_path, '"y","u","note"\n"1","2","a, b"\n3,4\n', "short.csv"))


def test_semicolon_and_tab_delimiters_are_sniffed(tmp_path, reader):
    for sep in (";", "\t"):
        d = _read(_write(tmp_path, f"y{sep}u\n1{sep}2\n3{sep}4\n"))
        assert d.y.tolist() == [1, 3] and d.u[:, 0].tolist() == [2, 4]


@pytest.mark.parametrize("eol", ["\r", "\n", "\r\n"])
def test_old_mac_unix_and_windows_line_endings_read_the_same(tmp_path, reader, eol):
    lines = ["t,y,u", "0,1.5,2", "0.1,,3", "0.2,nan,4e-3", "", "0.3,-7,5"]
    for end in ("", eol):  # with and without a line ending after the last row
        p = _write(tmp_path, eol.join(lines) + end)
        d = arxid.IOData.from_csv(p, output="y", inputs=["u"], time="t")
        np.testing.assert_array_equal(d.y, [1.5, np.nan, np.nan, -7])
        np.testing.assert_array_equal(d.u[:, 0], [2, 3, 4e-3, 5])
        assert d.ts == pytest.approx(0.1)


def test_old_mac_line_endings_with_a_bad_cell_name_its_row(tmp_path, reader):
    with pytest.raises(DataError, match="column 'u' row 3 holds 'x', which is not a number"):
        _read(_write(tmp_path, "y,u\r1,2\r3,x\r"))
    with pytest.raises(DataError, match="line 3 has 1 fields, fewer than the 2 of the header"):
        _read(_write(tmp_path, "y,u\r1,2\r3\r", "short.csv"))


def test_a_decimal_comma_is_named(tmp_path):
    with pytest.raises(DataError, match=r"column 'u' row 2 holds '2,5', which is not a number; it has a decimal comma"):
        _read(_write(tmp_path, "y;u\n1;2,5\n3;4\n"))
    with pytest.raises(DataError, match=r"line 2 has 4 fields, more than the 2 of the header.*decimal comma \(1,5\)"):
        _read(_write(tmp_path, "y,u\n1,5,2,5\n", "comma.csv"))


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (b"y,u\n", None),  # a header and no row: an IOData cannot be empty
        (b"\xef\xbb\xbf", "no column"),
        (b"y,u\n   \n", None),
        ("y,u\n1,2\n".encode("utf-16"), "not a UTF-8 text CSV file"),
    ],
)
def test_empty_and_header_only_files_are_refused_with_a_sentence(tmp_path, text, message):
    with pytest.raises(DataError, match=message or "empty"):
        _read(_write(tmp_path, text))


def test_a_single_row_file_is_read(tmp_path):
    p = _write(tmp_path, "y,u\r\n1.5,-2\r\n")
    cols = CsvFile.open(p).read(["y", "u"])
    assert cols["y"].tolist() == [1.5] and cols["u"].tolist() == [-2.0]


@pytest.mark.parametrize("n_rows", [400, 401])
def test_sampling_time_of_a_time_column_is_the_median_step(tmp_path, n_rows):
    """ts is numpy's median of the steps to the bit, for an odd and an even number of steps, with
    jitter at a tenth of the tolerance and steps that repeat."""
    rng = np.random.default_rng(n_rows)
    t = np.round(np.arange(n_rows) * 0.004 + rng.uniform(-4e-7, 4e-7, n_rows), 9)
    lines = ["t,y,u"] + [f"{repr(float(v))},{i % 7},{i % 3}" for i, v in enumerate(t)]
    d = arxid.IOData.from_csv(_write(tmp_path, "\n".join(lines) + "\n"), output="y", inputs=["u"], time="t")
    assert d.ts == float(np.median(np.diff(t)))
    assert d.y.tolist() == [i % 7 for i in range(n_rows)]
