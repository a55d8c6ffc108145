"""Reading measured signals from a CSV file: fast, and strict about what it accepts.

The Rust core reads the file (on every core, in tasks of whole lines, without the GIL and
interruptible with Ctrl-C; the ``csv`` crate splits the records that hold quotes): quoted fields,
CR / LF / CRLF line endings and a byte order mark are fine. It refuses what would change the data
silently: text that is not UTF-8, NUL bytes, and rows with fewer or more fields than the header.
Python reads the header (signal names, units in brackets, repeated names) and words every problem:
the line and column of a cell that is not a number, and a decimal comma by name.
"""

from __future__ import annotations

import csv
import re
import stat
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from .._base import _core
from .._base.records import record
from ..exceptions import DataError

__all__ = ["CsvFile", "MISSING_MARKERS"]

# Cells that mark a missing sample (NaN), in any letter case (the Rust reader knows the same list).
MISSING_MARKERS = ("", "nan", "na", "null")
_CHUNK = 1 << 16  # bytes per read while looking for the end of the header line
_BOM = b"\xef\xbb\xbf"
_DELIMITERS = (",", ";", "\t", " ")


@record
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
        Whether a field below the header is quoted (``False`` when the body was not checked).
    """

    path: Path
    delimiter: str
    names: tuple[str, ...]
    units: dict[str, str]
    rename: dict[str, str]
    quoted: bool

    @classmethod
    def open(cls, path: str | Path, delimiter: str | None = None, check: bool = True) -> CsvFile:
        """Check a CSV file and read its header.

        Parameters
        ----------
        path : str or Path
        delimiter : str, optional
            Column separator; when omitted, the most frequent of ``, ; tab space`` in the header.
        check : bool
            Check the whole file now (UTF-8, NUL bytes, fields per row); :meth:`read` checks it too,
            so a caller that reads at once can skip this pass.

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
        header_line = _first_line(path)
        if delimiter is None:
            counts = [header_line.count(c) for c in _DELIMITERS]
            delimiter = _DELIMITERS[counts.index(max(counts))] if max(counts) else ","
        if len(delimiter) != 1 or not delimiter.isascii() or delimiter in '\r\n"':
            raise DataError(f"the delimiter must be one character other than a quote or line end, got {delimiter!r}")
        raw = [h.strip() for h in next(csv.reader([header_line], delimiter=delimiter))]
        names, units, rename = _clean_header(raw)
        _check_unique(names, raw, path.name)
        table = cls(path, delimiter, tuple(names), units, rename, False)
        if not check:
            return table
        _, quoted = table._read_columns([])
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
            A name is not a column, or the file breaks a rule of :meth:`open`, or a cell of a wanted
            column is not a number.
        """
        wanted = list(dict.fromkeys(wanted))
        missing = [c for c in wanted if c not in self.names]
        if missing:
            self._read_columns([])  # a broken file (binary, not UTF-8) is the problem to report first
            raise DataError(
                f"{self.path.name} has no column(s) {missing}; available: {sorted(n for n in self.names if n)}"
            )
        columns, _ = self._read_columns([self.names.index(name) for name in wanted])
        return dict(zip(wanted, columns, strict=True))

    def _read_columns(self, positions: list[int]) -> tuple[list[np.ndarray], bool]:
        """The columns at ``positions`` (all rows checked) and whether a field was quoted."""
        columns, quoted, problem = _core.csv_read(self.path, self.delimiter, len(self.names), positions)
        if problem is not None:
            raise self._problem(*problem)
        assert columns is not None
        return columns, quoted

    def _problem(self, kind: str, line: int, offset: int, got: int, column: int, text: str) -> DataError:
        """The :class:`DataError` of a problem the Rust reader found (see ``rust/python/csv.rs``)."""
        source = self.path.name
        if kind == "not_utf8":
            return _not_utf8(self.path, text, offset, line)
        if kind == "nul":
            return DataError(
                f"{source} holds a NUL byte at byte {offset} (line {line}); it is a binary file, not a CSV text file"
            )
        if kind == "fields":
            n_fields = len(self.names)
            what = "fewer" if got < n_fields else "more"
            where = "row" if _has_quotes(self.path) else "line"
            hint = _decimal_comma_hint(self, got)
            return DataError(
                f"{source}: {where} {line} has {got} fields, {what} than the {n_fields} of the header; "
                f"every row needs one cell per column (leave a cell empty for a missing sample){hint}"
            )
        if kind == "number":
            name = self.names[column]
            message = f"{source}: column {name!r} row {line} holds {text!r}, which is not a number"
            if re.fullmatch(r"[+-]?\d*,\d+([eE][+-]?\d+)?", text):
                message += (
                    f"; it has a decimal comma: export the file with a decimal point "
                    f"({text.replace(',', '.')!r}), for example with the English (US) number format"
                )
            return DataError(message)
        if kind == "io":
            return DataError(f"cannot read CSV file {str(self.path)!r}: {text}")
        return DataError(f"{source}: line {line} cannot be read as CSV ({text}); export it again as CSV (UTF-8)")


def _has_quotes(path: Path) -> bool:
    """Whether the file holds a quote (only read to word an error)."""
    with path.open("rb") as fh:
        return any(b'"' in chunk for chunk in iter(lambda: fh.read(1 << 20), b""))


def _decimal_comma_hint(table: CsvFile, got: int) -> str:
    """A hint when a comma-separated file may write numbers with a decimal comma (``1,5``)."""
    if table.delimiter == "," and got > len(table.names):
        return "; if the numbers use a decimal comma (1,5), separate the columns with ';' and pass delimiter=';'"
    return ""


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


def _first_line(path: Path) -> str:
    """The header line, decoded (without a byte order mark); it ends at LF, CRLF or a lone CR."""
    head = b""
    with path.open("rb") as fh:
        while (chunk := fh.read(_CHUNK)) and not re.search(rb"[\r\n]", head + chunk):
            head += chunk
        head += chunk
    if head.startswith(_BOM):
        head = head[len(_BOM) :]
    head = re.split(rb"[\r\n]", head, maxsplit=1)[0]
    try:
        return head.decode("utf-8")
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
