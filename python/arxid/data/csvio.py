"""Reading measured signals from a CSV file: fast, and strict about what it accepts.

The numbers are parsed by pandas' C reader when pandas is installed and by numpy's C reader
(``numpy.loadtxt``) otherwise; only the columns asked for are converted. Before that, one streaming
pass over the bytes (constant memory) checks what those readers would let through silently: text
that is not UTF-8 (a byte order mark is fine), NUL bytes, repeated column names, and rows with fewer
or more fields than the header. A file with quoted cells, cells neither reader takes (`` nan ``,
``NULL``) or text in a column asked for goes through Python's :mod:`csv` module instead, which is
slower and reports the row and column of a cell that is not a number.
"""

from __future__ import annotations

import codecs
import csv
import itertools
import math
import re
import stat
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..exceptions import DataError

__all__ = ["CsvFile", "MISSING_MARKERS"]

# Cells that mark a missing sample (NaN), in any letter case.
MISSING_MARKERS = ("", "nan", "na", "null")
_NA_VALUES = sorted(
    {"".join(c) for m in MISSING_MARKERS for c in itertools.product(*[(x.lower(), x.upper()) for x in m])}
)
_CHUNK = 1 << 20  # bytes per read of the checking pass
_BOM = codecs.BOM_UTF8
_DELIMITERS = (",", ";", "\t", " ")


@dataclass(frozen=True)
class CsvFile:
    """A checked CSV file with a header row: its delimiter, signal names and units.

    Parameters
    ----------
    path : Path
    delimiter : str
        Column separator.
    names : tuple of str
        Signal name of each header cell (``""`` for a cell without one): the text before a unit in
        brackets, with characters that cannot appear in an effect replaced by ``_``.
    units : dict of str to str
        Units given in brackets in the header (``vbat[V]``), by signal name.
    rename : dict of str to str
        Raw header text to signal name (so ``output="vbat[V]"`` works too).
    quoted : bool
        Whether a cell below the header is quoted (then only :mod:`csv` reads it correctly).
    """

    path: Path
    delimiter: str
    names: tuple[str, ...]
    units: dict[str, str]
    rename: dict[str, str]
    quoted: bool

    @classmethod
    def open(cls, path: str | Path, delimiter: str | None = None) -> CsvFile:
        """Check a CSV file and read its header.

        Parameters
        ----------
        path : str or Path
        delimiter : str, optional
            Column separator; when omitted, the most frequent of ``, ; tab space`` in the header.

        Returns
        -------
        CsvFile

        Raises
        ------
        DataError
            The file is missing, not a regular file, empty, not UTF-8 text, holds a NUL byte,
            repeats a column name, or has a row with fewer or more fields than the header.
        """
        path = Path(path)
        _check_regular_file(path)
        header_line, cr_only = _first_line(path)
        if delimiter is None:
            counts = [header_line.count(c) for c in _DELIMITERS]
            delimiter = _DELIMITERS[counts.index(max(counts))] if max(counts) else ","
        raw = [h.strip() for h in next(csv.reader([header_line], delimiter=delimiter))]
        names, units, rename = _clean_header(raw)
        _check_unique(names, raw, path.name)
        # old Mac line endings (CR only): the csv module, which takes any of CR, LF, CRLF, reads them
        quoted = _check_body(path, delimiter, len(raw), count_lines=not cr_only) or cr_only
        return cls(path, delimiter, tuple(names), units, rename, quoted)

    def read(self, wanted: Iterable[str]) -> dict[str, np.ndarray]:
        """The named columns as float arrays; missing cells (empty, ``nan``, ``na``, ``null``) are NaN.

        Parameters
        ----------
        wanted : iterable of str
            Signal names (as in :attr:`names`).

        Returns
        -------
        dict of str to ndarray of shape (n_rows,)

        Raises
        ------
        DataError
            A name is not a column, or a cell of a wanted column is not a number.
        """
        wanted = list(dict.fromkeys(wanted))
        missing = [c for c in wanted if c not in self.names]
        if missing:
            raise DataError(
                f"{self.path.name} has no column(s) {missing}; available: {sorted(n for n in self.names if n)}"
            )
        index = {name: self.names.index(name) for name in wanted}
        table = None if self.quoted else _read_fast(self.path, self.delimiter, sorted(index.values()))
        if table is None:
            return _read_with_csv_module(self, index)
        return {name: table[j] for name, j in index.items()}


def _check_regular_file(path: Path) -> None:
    try:
        mode = path.stat().st_mode
    except OSError:
        raise DataError(f"CSV file {str(path)!r} does not exist") from None
    if not stat.S_ISREG(mode):
        raise DataError(
            f"{str(path)!r} is not a regular file (a directory, device or pipe); pass the path of a CSV file"
        )
    if path.stat().st_size == 0:
        raise DataError(f"CSV file {str(path)!r} is empty")


def _first_line(path: Path) -> tuple[str, bool]:
    """The header line, decoded (without a byte order mark), and whether lines end with a lone
    carriage return (old Mac files)."""
    with path.open("rb") as fh:
        head = fh.read(1 << 16)
    if head.startswith(_BOM):
        head = head[len(_BOM) :]
    cr, lf = head.find(b"\r"), head.find(b"\n")
    cr_only = cr >= 0 and (lf < 0 or lf > cr + 1)
    end = cr if cr_only else lf
    head = head if end < 0 else head[:end]
    try:
        return head.decode("utf-8").rstrip("\r\n"), cr_only
    except UnicodeDecodeError as exc:
        raise _not_utf8(path, exc.reason, exc.start, 1) from None


def _not_utf8(path: Path, reason: str, offset: int, line: int) -> DataError:
    return DataError(
        f"{path.name} is not a UTF-8 text CSV file ({reason} at byte {offset}, line {line}); "
        "export it as CSV (UTF-8) with a header row"
    )


def _clean_header(raw_header: list[str]) -> tuple[list[str], dict[str, str], dict[str, str]]:
    """Signal names of CSV header cells (``""`` for a cell without one), the units given in
    brackets (``vbat[V]``), and the map from raw header text to signal name."""
    header: list[str] = []
    header_units: dict[str, str] = {}
    rename: dict[str, str] = {}
    for h in raw_header:
        m = re.fullmatch(r"(.*?)\s*\[(.*)\]", h)
        base = m[1] if m else h
        clean = re.sub(r"\W+", "_", base).strip("_") if base else ""
        if clean and clean[0].isdigit():
            clean = "_" + clean
        header.append(clean)
        rename[h] = clean
        if m and clean:
            header_units[clean] = m[2]
    return header, header_units, rename


def _check_unique(names: list[str], raw: list[str], source: str) -> None:
    seen: dict[str, int] = {}
    for j, name in enumerate(names):
        if not name:
            continue
        if name in seen:
            i = seen[name]
            raise DataError(
                f"{source}: columns {i + 1} ({raw[i]!r}) and {j + 1} ({raw[j]!r}) are both the signal {name!r}; "
                "rename one of them in the header"
            )
        seen[name] = j


class _LineCounter:
    """Fields per line over a stream of chunks: delimiters between newlines, a line carried over
    from one chunk to the next. Blank lines (empty, or a lone carriage return) are skipped."""

    def __init__(self, delimiter: str, n_fields: int, source: str):
        self.delim, self.n_fields, self.source = ord(delimiter), n_fields, source
        self.line = 0  # lines completed so far (the header is line 1)
        self.carry_fields, self.carry_len, self.last = 0, 0, 0

    def feed(self, chunk: bytes) -> None:
        buf = np.frombuffer(chunk, dtype=np.uint8)
        marks = np.flatnonzero((buf == 10) | (buf == self.delim))  # newlines and delimiters, one scan
        k = np.flatnonzero(buf[marks] == 10)
        ends = marks[k]
        fields = np.diff(k - np.arange(len(k)), prepend=0) + 1  # delimiters between newlines, plus one
        lengths = np.diff(ends, prepend=-1)  # bytes of each line with its newline, in this chunk
        if len(ends):
            fields[0] += self.carry_fields
            lengths[0] += self.carry_len
            lf_cr = buf[ends - 1] == 13 if ends[0] > 0 else np.r_[self.last == 13, buf[ends[1:] - 1] == 13]
            blank = (lengths == 1) | ((lengths == 2) & lf_cr)
            self._check(fields, blank)
            self.carry_fields = len(marks) - int(k[-1]) - 1
            self.carry_len = len(chunk) - int(ends[-1]) - 1
        else:
            self.carry_fields += len(marks)
            self.carry_len += len(chunk)
        if len(chunk):
            self.last = chunk[-1]

    def finish(self) -> None:
        if self.line and self.carry_len and not (self.carry_len == 1 and self.last == 13):
            self._check(np.array([self.carry_fields + 1]), np.array([False]))

    def _check(self, fields: np.ndarray, blank: np.ndarray) -> None:
        first = 1 if self.line == 0 else 0  # the header line itself
        bad = np.flatnonzero((fields[first:] != self.n_fields) & ~blank[first:])
        if bad.size:
            k = int(bad[0]) + first
            line, got = self.line + k + 1, int(fields[k])
            what = "fewer" if got < self.n_fields else "more"
            raise DataError(
                f"{self.source}: line {line} has {got} fields, {what} than the {self.n_fields} of the header; "
                "every row needs one cell per column (leave a cell empty for a missing sample)"
            )
        self.line += len(fields)


def _check_body(path: Path, delimiter: str, n_fields: int, count_lines: bool = True) -> bool:
    """One streaming pass: UTF-8, no NUL byte, each row as many fields as the header (unless a
    cell is quoted or ``count_lines`` is false; then the csv module checks). Returns whether a
    quote was seen."""
    decoder = codecs.getincrementaldecoder("utf-8")()
    counter = _LineCounter(delimiter, n_fields, path.name)
    offset, quoted = 0, False
    with path.open("rb") as fh:
        while chunk := fh.read(_CHUNK):
            if offset == 0 and chunk.startswith(_BOM):
                chunk, offset = chunk[len(_BOM) :], len(_BOM)
            if not chunk.isascii() or decoder.getstate()[0]:  # (a character may straddle two chunks)
                try:
                    decoder.decode(chunk)
                except UnicodeDecodeError as exc:
                    line = counter.line + chunk.count(b"\n", 0, max(exc.start, 0)) + 1
                    raise _not_utf8(path, exc.reason, offset + max(exc.start, 0), line) from None
            if b"\x00" in chunk:
                at = chunk.index(b"\x00")
                line = counter.line + chunk.count(b"\n", 0, at) + 1
                raise DataError(
                    f"{path.name} holds a NUL byte at byte {offset + at} (line {line}); "
                    "it is a binary file, not a CSV text file"
                )
            quoted = quoted or b'"' in (chunk if counter.line else chunk.partition(b"\n")[2])
            if not quoted and count_lines:
                counter.feed(chunk)
            offset += len(chunk)
    try:
        decoder.decode(b"", final=True)
    except UnicodeDecodeError as exc:
        raise _not_utf8(path, exc.reason, offset, counter.line + 1) from None
    if not quoted and count_lines:
        counter.finish()
    return quoted


def _read_fast(path: Path, delimiter: str, columns: list[int]) -> dict[int, np.ndarray] | None:
    """The columns (by position) with pandas or numpy's C reader; None when a cell is not a number
    either reader takes (the caller then reads with the csv module, which says where)."""
    try:
        import pandas as pd
    except ImportError:
        pd = None
    try:
        if pd is not None:
            frame = pd.read_csv(
                path, sep=delimiter, header=None, skiprows=1, usecols=columns, dtype=np.float64, encoding="utf-8-sig",
                keep_default_na=False, na_values=_NA_VALUES, index_col=False, engine="c", quoting=csv.QUOTE_NONE,
            )  # fmt: skip
            return {j: frame[j].to_numpy() for j in columns}
        table = np.loadtxt(
            path, delimiter=delimiter, skiprows=1, usecols=columns, comments=None, ndmin=2, encoding="utf-8-sig"
        )
    except (ValueError, TypeError):
        return None
    return {j: np.ascontiguousarray(table[:, k]) for k, j in enumerate(columns)}


def _read_with_csv_module(table: CsvFile, index: dict[str, int]) -> dict[str, np.ndarray]:
    """Python's csv module, cell by cell: quoted cells, markers with spaces, and a useful error for a
    cell that is not a number (the row and column)."""
    with table.path.open(newline="", encoding="utf-8-sig") as fh:
        rows = csv.reader(fh, delimiter=table.delimiter)
        next(rows)
        values: dict[str, list[float]] = {name: [] for name in index}
        n_fields = len(table.names)
        for line, row in enumerate(rows, start=2):
            if not row or (len(row) == 1 and not row[0].strip()):
                continue
            if len(row) != n_fields:
                what = "fewer" if len(row) < n_fields else "more"
                raise DataError(
                    f"{table.path.name}: row {line} has {len(row)} fields, {what} than the {n_fields} of the header; "
                    "every row needs one cell per column (leave a cell empty for a missing sample)"
                )
            for name, j in index.items():
                values[name].append(_number(row[j], name, line, table.path.name))
    return {name: np.array(v, dtype=np.float64) for name, v in values.items()}


def _number(cell: str, name: str, line: int, source: str) -> float:
    cell = cell.strip()
    if cell.lower() in MISSING_MARKERS:
        return math.nan
    try:
        return float(cell)
    except ValueError:
        raise DataError(f"{source}: column {name!r} row {line} holds {cell!r}, which is not a number") from None
