"""The table constructors of :class:`~arxid.IOData`: :meth:`~TableReaders.from_pandas` and
:meth:`~TableReaders.from_csv`, by column names, with one output or several. :class:`~arxid.IOData`
inherits them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TypeVar

import numpy as np

from ..exceptions import DataError
from .csvio import CsvFile
from .outputs import GridBuilt, output_list
from .samples import freeze_owned

__all__ = ["TableReaders"]

_T = TypeVar("_T", bound="TableReaders")


class TableReaders(GridBuilt):
    """Constructors of :class:`~arxid.IOData` from tables (the class inherits them)."""

    @classmethod
    def from_pandas(
        cls: type[_T],
        df,
        *,
        output: str | Sequence[str],
        inputs: Sequence[str],
        extra: Sequence[str] = (),
        ts: float | None = None,
        time: str | None = None,
        units: Mapping[str, str] | None = None,
        resample: bool = False,
    ) -> _T:
        """Build from a pandas DataFrame by column names.

        Parameters
        ----------
        df : pandas.DataFrame
        output : str or sequence of str
            Output column, or several (``["p", "q", "r"]``) for data of several outputs.
        inputs : sequence of str
            Input columns.
        extra : sequence of str
            Logged signals kept for diagnostics.
        ts : float, optional
            Sampling time; when omitted, ``time`` must name a time column sampled uniformly.
        time : str, optional
            Time column (seconds).
        units : mapping of str to str, optional
            Unit of each column, by name.
        resample : bool
            Put jittered samples onto a uniform grid of step ``ts`` (default: the median step of
            ``time``): inputs held between samples, the other columns interpolated linearly, gaps
            longer than 3 steps NaN (see :func:`arxid.data.resample.resample`). Needs ``time``.

        Returns
        -------
        IOData
        """
        columns = {str(c): np.asarray(df[c]) for c in df.columns}
        return cls._from_columns(
            columns,
            output=output,
            inputs=inputs,
            extra=extra,
            ts=ts,
            time=time,
            units=units,
            source="DataFrame",
            resample=resample,
        )

    @classmethod
    def from_csv(
        cls: type[_T],
        path,
        *,
        output: str | Sequence[str],
        inputs: Sequence[str],
        extra: Sequence[str] = (),
        ts: float | None = None,
        time: str | None = None,
        delimiter: str | None = None,
        units: Mapping[str, str] | None = None,
        resample: bool = False,
    ) -> _T:
        """Read a CSV file with a header row.

        Empty cells and ``nan`` are missing samples (NaN). A header ``vbat[V]`` names the signal
        ``vbat`` with unit ``V``; other characters that cannot appear in an effect are replaced by
        ``_`` (the raw header text is accepted too when selecting columns).

        Parameters
        ----------
        path : str or Path
        output, inputs, extra, ts, time
            As in :meth:`from_pandas`.
        delimiter : str, optional
            Column separator; sniffed from the header when omitted.
        units : mapping of str to str, optional
            Unit of each column, by name.
        resample : bool
            Put a time column with jitter onto a uniform grid, as in :meth:`from_pandas`.

        Returns
        -------
        IOData

        Examples
        --------
        A log whose time stamps jitter by a tenth of a step:

        >>> import numpy as np, tempfile, os
        >>> t = np.arange(500) * 0.01 + np.random.default_rng(1).uniform(-1e-3, 1e-3, 500)
        >>> path = os.path.join(tempfile.mkdtemp(), "log.csv")
        >>> np.savetxt(path, np.column_stack([t, np.sin(t), np.cos(t)]), delimiter=",", header="t,y,u", comments="")
        >>> from arxid import IOData
        >>> d = IOData.from_csv(path, output="y", inputs=["u"], time="t", resample=True)
        >>> round(d.ts, 3), d.n_samples > 490
        (0.01, True)
        """
        table = CsvFile.open(path, delimiter, check=False)  # read() checks the whole file in the same pass
        # "vbat[V]" becomes the signal "vbat" with unit "V", so effects such as "u1*vbat" can name it;
        # the raw header text is still accepted in output=/inputs=/extra=/time=.
        rename = table.rename
        output = [rename.get(c, c) for c in output_list(output)]
        time = rename.get(time, time) if time else time
        inputs = [rename.get(c, c) for c in ([inputs] if isinstance(inputs, str) else inputs)]
        extra = [rename.get(c, c) for c in ([extra] if isinstance(extra, str) else extra)]
        units = {**table.units, **{rename.get(k, k): v for k, v in (units or {}).items()}}
        # The columns were read just now and nobody else holds them: IOData takes them without a copy.
        columns = {
            c: freeze_owned(v) for c, v in table.read([*output, *inputs, *extra] + ([time] if time else [])).items()
        }
        return cls._from_columns(
            columns,
            output=output,
            inputs=inputs,
            extra=extra,
            ts=ts,
            time=time,
            units=units,
            source=table.path.name,
            resample=resample,
        )

    @classmethod
    def _from_columns(cls: type[_T], columns, *, output, inputs, extra, ts, time, units, source, resample=False) -> _T:
        outputs = output_list(output)
        inputs = [inputs] if isinstance(inputs, str) else list(inputs)
        extra = [extra] if isinstance(extra, str) else list(extra)
        wanted = [*outputs, *inputs, *extra] + ([time] if time else [])
        missing = [c for c in wanted if c not in columns]
        if missing:
            raise DataError(f"{source} has no column(s) {missing}; available: {sorted(columns)}")
        if not inputs:
            raise DataError("name at least one input column")
        units = dict(units or {})
        names = [*outputs, *inputs, *extra]
        if not resample and ts is None:
            ts = _uniform_step(columns, time)
        repeated = sorted({c for c in names if names.count(c) > 1})
        if repeated:  # before the columns go into a mapping by name
            raise DataError(f"signal names must be unique; repeated: {repeated}")
        if resample:
            return cls._resampled(columns, names, len(inputs), len(outputs), ts, time, units, source)
        return cls._from_grid(
            {c: columns[c] for c in names}, {c: units.get(c, "") for c in names}, ts, len(inputs), len(outputs)
        )

    @classmethod
    def _resampled(cls: type[_T], columns, names, n_inputs, n_outputs, ts, time, units, source) -> _T:
        """Columns sampled at the times of column ``time`` (with jitter) on a uniform grid."""
        from .resample import resample

        if not time:
            raise DataError("resample=True needs the time column: pass time=... (CLI: --time COL)")
        t = np.asarray(columns[time], dtype=np.float64)
        inputs = names[n_outputs : n_outputs + n_inputs]
        grid = resample({c: (t, columns[c]) for c in names}, hold=inputs, ts=ts, source=source)
        return cls._from_grid(grid.values, {c: units.get(c, "") for c in names}, grid.ts, n_inputs, n_outputs)


def _uniform_step(columns, time) -> float:
    """The sampling time of a uniformly sampled time column, or a DataError saying what to do."""
    if not time:
        raise DataError("give the sampling time ts=... or the name of a time column time=...")
    t = columns[time]
    with np.errstate(over="ignore", invalid="ignore"):
        dt = np.diff(t)
    if len(dt) == 0 or not np.all(np.isfinite(t)):
        raise DataError(f"time column {time!r} must be finite and hold at least two samples")
    # Finite times have finite steps unless one overflows, which the smallest or largest shows.
    lo, hi = float(dt.min()), float(dt.max())
    if not (np.isfinite(lo) and np.isfinite(hi)):
        raise DataError(
            f"the steps of time column {time!r} overflow (times from {t.min():g} to {t.max():g} s); "
            "give the time in seconds"
        )
    ts = _median(dt)
    # The largest |step - ts| is at the smallest or the largest step (rounding is monotonic).
    if ts <= 0 or max(hi - ts, ts - lo) > 1e-6 * max(abs(ts), 1.0) + 1e-3 * ts:
        raise DataError(
            f"time column {time!r} is not uniformly sampled (steps from {lo:g} to {hi:g}); "
            "pass resample=True (CLI: --resample) to put it on a uniform grid (inputs held, the other "
            "signals interpolated, long gaps missing)"
        )
    return ts


def _median(x: np.ndarray) -> float:
    """``numpy.median`` of finite values, to the bit, from one partition (the median's own also
    looks for NaN, at three times the cost on a long log)."""
    k = len(x) // 2
    if len(x) % 2:
        return float(np.partition(x, k)[k])
    part = np.partition(x, [k - 1, k])
    return float((part[k - 1] + part[k]) / 2)
