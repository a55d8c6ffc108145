"""Measured input/output data: :class:`IOData`."""

from __future__ import annotations

import math
import numbers
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import field
from typing import TYPE_CHECKING, Any

import numpy as np

from .._base.records import record
from ..exceptions import DataError
from .flight_logs import FlightLogReaders, selector_lists
from .outputs import OutputField, SeveralOutputs, checked_outputs, output_list
from .samples import as_float_samples, check_sampling_time, freeze_owned
from .tables import TableReaders

__all__ = ["IOData"]


def _sample_at(time: float, ts: float, n: int) -> int:
    """The first sample at or after ``time`` seconds, clamped to ``[0, n]``."""
    k = time / ts - 1e-9
    return 0 if k <= 0 else n if k >= n else int(math.ceil(k))


@record(eq=False)
class IOData(SeveralOutputs, TableReaders, FlightLogReaders):
    """Sampled output(s) and inputs of one or more experiments.

    Parameters
    ----------
    y : array_like of shape (n_samples,) or (n_samples, n_outputs)
        Measured output, or several outputs as columns (then name them in ``output_name``).
    u : array_like of shape (n_samples,) or (n_samples, n_inputs)
        Measured inputs.
    ts : float
        Sampling time in seconds, > 0.
    output_name : str or sequence of str
        Output name (default ``"y"``), or one name per output column of ``y``.
    input_names : sequence of str
        Input names (default ``"u1"``, ``"u2"``, ...).
    output_unit : str or sequence of str
        Unit of the output, or of each output (one string: the same for all).
    input_units : sequence of str
        Units of the inputs, for printing and plots.
    extra : mapping of str to array_like of shape (n_samples,), optional
        Logged signals that are not model inputs but that diagnostics and effects can use
        (battery voltage, temperature).
    extra_units : mapping of str to str, optional
    experiment_starts : sequence of int, optional
        First sample of each experiment (default ``[0]``). No regressor crosses a start.

    Notes
    -----
    NaN marks a missing sample. Regression rows whose regressors touch a NaN are left out, and
    counted in the fit report. Infinite values are refused.

    Data of several outputs feed :func:`arxid.ssest` and the checks of a state-space model. Their
    ``y``, ``output_name`` and ``output_unit`` mean one output, so reading them is an error that
    says to pick one with ``data.output(name)``; ``outputs``, ``output_names`` and
    ``output_units`` give all of them.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> d = arxid.IOData(np.zeros(100), np.ones(100), ts=0.01, output_name="roll")
    >>> d.n_samples, d.n_inputs
    (100, 1)
    >>> rates = arxid.IOData(np.zeros((100, 3)), np.ones((100, 4)), ts=0.01, output_name=["p", "q", "r"])
    >>> rates.n_outputs, rates.output("q").output_name
    (3, 'q')
    """

    if TYPE_CHECKING:
        y: np.ndarray
    else:  # a field without a default (the guard's class access raises AttributeError)
        y: OutputField[np.ndarray] = OutputField()
    u: np.ndarray
    ts: float
    output_name: OutputField[str] = OutputField("y")
    input_names: tuple[str, ...] = ()
    output_unit: OutputField[str] = OutputField("")
    input_units: tuple[str, ...] = ()
    extra: Mapping[str, np.ndarray] = field(default_factory=dict)
    extra_units: Mapping[str, str] = field(default_factory=dict)
    experiment_starts: tuple[int, ...] = (0,)

    def __post_init__(self):
        self._check_optional_fields()
        raw = self.__dict__  # the output fields as given (reading them checks for one output)
        y, output_name, output_unit = checked_outputs(raw["y"], raw["output_name"], raw["output_unit"])
        u = as_float_samples("u (inputs)", self.u, 2)
        n = y.shape[0]
        if n == 0:
            raise DataError("the data are empty (0 samples); pass at least a few hundred samples")
        if u.shape[0] != n:
            raise DataError(
                f"y has {n} samples but u has {u.shape[0]}; y and u must have the same length "
                "(for several inputs pass u with shape (n_samples, n_inputs))"
            )
        try:
            ts = float(self.ts)
        except (TypeError, ValueError):
            raise DataError(f"ts must be a number of seconds, got {self.ts!r}") from None
        if not math.isfinite(ts) or ts <= 0:
            raise DataError(f"ts must be a positive sampling time in seconds, got {self.ts!r}")
        check_sampling_time(ts)
        m = u.shape[1]
        names = tuple(self.input_names) if self.input_names else tuple(f"u{i + 1}" for i in range(m))
        if len(names) != m:
            raise DataError(f"{len(names)} input names given for {m} inputs")
        units = tuple(self.input_units) if self.input_units else ("",) * m
        if len(units) != m:
            raise DataError(f"{len(units)} input units given for {m} inputs")
        extra = {}
        for k, v in dict(self.extra).items():
            arr = as_float_samples(f"extra signal {k!r}", v, 1)
            if arr.shape[0] != n:
                raise DataError(f"extra signal {k!r} has {arr.shape[0]} samples but the data have {n}")
            extra[str(k)] = arr
        all_names = (output_name if isinstance(output_name, tuple) else (output_name,)) + names + tuple(extra)
        dup = {x for x in all_names if all_names.count(x) > 1}
        if dup:
            raise DataError(f"signal names must be unique; repeated: {sorted(dup)}")
        starts = tuple(int(s) for s in self.experiment_starts) or (0,)
        if starts[0] != 0 or any(b <= a for a, b in zip(starts, starts[1:], strict=False)) or starts[-1] >= n:
            raise DataError(f"experiment_starts must begin with 0 and increase inside the data, got {starts}")
        for arr in (y, u, *extra.values()):
            arr.setflags(write=False)
        object.__setattr__(self, "y", y)
        object.__setattr__(self, "u", u)
        object.__setattr__(self, "ts", ts)
        object.__setattr__(self, "output_name", output_name)
        object.__setattr__(self, "output_unit", output_unit)
        object.__setattr__(self, "input_names", tuple(str(x) for x in names))
        object.__setattr__(self, "input_units", units)
        object.__setattr__(self, "extra", extra)
        object.__setattr__(self, "extra_units", dict(self.extra_units))
        object.__setattr__(self, "experiment_starts", starts)

    def _check_optional_fields(self) -> None:
        """None means "not given" for the optional fields; other wrong types are DataErrors (not a
        TypeError from deep inside the constructor)."""
        defaults = {"input_names": (), "input_units": (), "extra": {}, "extra_units": {}, "experiment_starts": (0,)}
        for name, default in defaults.items():
            if getattr(self, name) is None:
                object.__setattr__(self, name, default)
        for name in ("extra", "extra_units"):
            if not isinstance(getattr(self, name), Mapping):
                raise DataError(f"{name} must be a mapping from signal name to values, got {getattr(self, name)!r:.80}")
        for name in ("input_names", "input_units"):
            value = getattr(self, name)
            if isinstance(value, str) or not isinstance(value, Iterable):
                raise DataError(f"{name} must be a sequence of strings (one per input), got {value!r:.80}")
        starts = self.experiment_starts
        if isinstance(starts, str) or not isinstance(starts, Iterable):
            raise DataError(f"experiment_starts must be a sequence of sample indices, got {starts!r:.80}")
        if not all(isinstance(v, numbers.Integral) and not isinstance(v, bool) for v in starts):
            raise DataError(f"experiment_starts must hold integer sample indices, got {list(starts)!r:.80}")

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_arrays(cls, y, u, ts, **kwargs) -> IOData:
        """Same as the constructor; for symmetry with :meth:`from_pandas` and :meth:`from_csv`.

        Parameters
        ----------
        y, u, ts
            Output, inputs and sampling time as in :class:`IOData`.
        **kwargs
            The other :class:`IOData` fields (``output_name``, ``extra``, ...).

        Returns
        -------
        IOData
        """
        return cls(y, u, ts, **kwargs)

    @classmethod
    def from_ulog(
        cls,
        path,
        *,
        output: str | Sequence[str],
        inputs: Sequence[str],
        extra: Sequence[str] = (),
        ts: float | None = None,
        max_gap: float | None = None,
    ) -> IOData:
        """Read a PX4 flight log (ULog) onto one time grid (needs ``pip install 'arxid[px4]'``).

        Commands (the inputs, setpoint and actuator topics) are held between samples, measurements
        interpolated linearly; a dropout longer than ``max_gap`` becomes a NaN gap, never bridged
        (see :mod:`arxid.data.ulog`). A command is placed at its ``timestamp`` (when it was issued), a
        measurement at its ``timestamp_sample`` (when it was sampled). Names are the selectors with
        ``.`` and brackets replaced by ``_`` (``vehicle_angular_velocity_xyz_0``); units come from the
        PX4 message definitions.

        Parameters
        ----------
        path : str or Path
            A ``.ulg`` file.
        output : str or sequence of str
            ``topic.field``, e.g. ``"vehicle_angular_velocity.xyz[0]"``, or several for data of
            several outputs.
        inputs : sequence of str
            Command fields, e.g. ``["actuator_controls_0.control[0]"]``.
        extra : sequence of str
            Other fields kept for diagnostics and instruments (``"vehicle_rates_setpoint.roll"``,
            ``"battery_status.voltage_v"``).
        ts : float, optional
            Grid step [s]; default the output topic's median sample interval.
        max_gap : float, optional
            Longest interval between samples bridged [s]; default 3 times each topic's own.

        Returns
        -------
        IOData
        """
        from .ulog import read_ulog

        inputs, extra = selector_lists(inputs, extra)
        outputs = output_list(output)
        sig = read_ulog(path, [*outputs, *inputs, *extra], hold=inputs, ts=ts, max_gap=max_gap)
        return cls._from_grid(sig.values, sig.units, sig.ts, len(inputs), len(outputs))

    @classmethod
    def _from_grid(
        cls, values: Mapping[str, np.ndarray], units: Mapping[str, str], ts: float, n_inputs: int, n_outputs: int = 1
    ) -> IOData:
        """An IOData of signals on one grid: ``n_outputs`` outputs first, then ``n_inputs`` inputs,
        then extras."""
        names = list(values)
        outs, ins, ext = names[:n_outputs], names[n_outputs : n_outputs + n_inputs], names[n_outputs + n_inputs :]
        # column_stack makes new arrays, which IOData may take without a copy.
        return cls(
            freeze_owned(np.column_stack([values[c] for c in outs])),
            freeze_owned(np.column_stack([values[c] for c in ins])),
            ts,
            output_name=outs,
            input_names=tuple(ins),
            output_unit=[units[c] for c in outs],
            input_units=tuple(units[c] for c in ins),
            extra={c: values[c] for c in ext},
            extra_units={c: units[c] for c in ext},
        )

    # ------------------------------------------------------------------ shape and lookup
    @property
    def n_samples(self) -> int:
        """Number of samples (all experiments together)."""
        return int(self.u.shape[0])

    @property
    def n_inputs(self) -> int:
        """Number of model inputs (columns of ``u``)."""
        return int(self.u.shape[1])

    @property
    def n_experiments(self) -> int:
        """Number of experiments (entries of ``experiment_starts``)."""
        return len(self.experiment_starts)

    @property
    def segments(self) -> list[tuple[int, int]]:
        """Half-open sample ranges of the experiments."""
        ends = list(self.experiment_starts[1:]) + [self.n_samples]
        return list(zip(self.experiment_starts, ends, strict=True))

    @property
    def time(self) -> np.ndarray:
        """Time of each sample in seconds, restarting at 0 in each experiment."""
        t = np.empty(self.n_samples)
        for a, b in self.segments:
            np.multiply(np.arange(b - a), self.ts, out=t[a:b])
        return t

    @property
    def n_missing(self) -> int:
        """Number of samples where an output or an input is NaN."""
        return int((np.isnan(self.outputs).any(axis=1) | np.isnan(self.u).any(axis=1)).sum())

    @property
    def output_measured(self) -> bool:
        """Whether any output sample is measured (not NaN)."""
        return bool(np.isfinite(self.outputs).any())

    @property
    def signal_names(self) -> tuple[str, ...]:
        """Output, input and extra signal names, in that order."""
        return self.output_names + self.input_names + tuple(self.extra)

    def signal(self, name: str) -> np.ndarray:
        """The output, an input or an extra signal by name.

        Parameters
        ----------
        name : str
            A signal name; ``"y"`` is the output and ``"u1"``, ``"u2"``, ... the inputs whatever
            their names.

        Returns
        -------
        ndarray of shape (n_samples,)
            The samples (read-only).
        """
        if name in self.output_names:
            return self.outputs[:, self.output_names.index(name)]
        if name == "y":
            return self.y
        if name in self.input_names:
            return self.u[:, self.input_names.index(name)]
        if name in self.extra:
            return self.extra[name]
        if name.startswith("u") and name[1:].isdigit() and 1 <= int(name[1:]) <= self.n_inputs:
            return self.u[:, int(name[1:]) - 1]
        raise DataError(f"no signal named {name!r}; the data have {list(self.signal_names)}")

    def unit(self, name: str) -> str:
        """Unit of a signal.

        Parameters
        ----------
        name : str
            Signal name (``"y"`` is the output).

        Returns
        -------
        str
            The unit, ``""`` when none was given.
        """
        if name in self.output_names:
            return self.output_units[self.output_names.index(name)]
        if name == "y":
            return self.output_unit
        if name in self.input_names:
            return self.input_units[self.input_names.index(name)]
        return self.extra_units.get(name, "")

    # ------------------------------------------------------------------ transformations
    def _take(self, idx: np.ndarray | slice, starts: Iterable[int]) -> IOData:
        return self.with_samples(
            y=self.outputs[idx],
            u=self.u[idx],
            extra={k: v[idx] for k, v in self.extra.items()},
            experiment_starts=tuple(starts),
        )

    def __getitem__(self, key) -> IOData:
        """Samples by slice (step 1): ``data[1000:5000]``. Experiment boundaries are kept."""
        if not isinstance(key, slice) or key.step not in (None, 1):
            raise DataError("index IOData with a slice of samples, e.g. data[100:2000]")
        a, b, _ = key.indices(self.n_samples)
        if b <= a:
            raise DataError(f"the slice [{key.start}:{key.stop}] selects no samples")
        starts = [0] + [s - a for s in self.experiment_starts if a < s < b]
        return self._take(slice(a, b), starts)  # views of the frozen samples, not copies

    def time_slice(self, start: float | None = None, stop: float | None = None) -> IOData:
        """Samples with ``start <= time < stop`` of single-experiment data.

        Parameters
        ----------
        start, stop : float, optional
            Times in seconds (default: the first and past the last sample).

        Returns
        -------
        IOData
        """
        if self.n_experiments > 1:
            raise DataError("time_slice works on a single experiment; slice by sample index instead")
        for name, v in (("start", start), ("stop", stop)):
            if v is not None and (isinstance(v, bool) or not isinstance(v, numbers.Real) or math.isnan(v)):
                raise DataError(f"time_slice {name} must be a time in seconds or None, got {v!r}")
        # ±inf means "unbounded"; the clamping below keeps every index inside the data.
        a = 0 if start is None or start == -math.inf else _sample_at(start, self.ts, self.n_samples)
        b = self.n_samples if stop is None or stop == math.inf else _sample_at(stop, self.ts, self.n_samples)
        return self[max(a, 0) : min(b, self.n_samples)]

    def split(self, fraction: float = 0.7) -> tuple[IOData, IOData]:
        """Split at a fraction of the samples into estimation and validation data.

        Parameters
        ----------
        fraction : float
            Share of the samples in the estimation part, strictly between 0 and 1.

        Returns
        -------
        (IOData, IOData)
            Estimation data (the first samples) and validation data (the rest).
        """
        if not 0 < fraction < 1:
            raise DataError(f"split fraction must be between 0 and 1, got {fraction}")
        k = int(round(self.n_samples * fraction))
        if k < 1 or k >= self.n_samples:
            raise DataError(f"split at {fraction} leaves an empty part of {self.n_samples} samples")
        return self[:k], self[k:]

    def detrend(self, kind: str = "mean") -> IOData:
        """Remove the mean or a straight line from the output and inputs, per experiment.

        Extra signals are left as they are (they carry physics).

        Parameters
        ----------
        kind : {"mean", "linear"}
            What to remove, fitted to the finite samples (NaN stays NaN).

        Returns
        -------
        IOData
        """
        if kind not in ("mean", "linear"):
            raise DataError(f"detrend kind must be 'mean' or 'linear', got {kind!r}")
        y = self.outputs.copy()
        u = self.u.copy()
        for a, b in self.segments:
            for col in [y[a:b, j] for j in range(self.n_outputs)] + [u[a:b, i] for i in range(self.n_inputs)]:
                ok = np.isfinite(col)
                if not ok.any():
                    continue
                if kind == "mean":
                    col -= col[ok].mean()
                else:
                    t = np.arange(b - a, dtype=float)
                    if ok.sum() < 2:
                        col -= col[ok].mean()
                    else:
                        coef = np.polyfit(t[ok], col[ok], 1)
                        col -= np.polyval(coef, t)
        return self.with_samples(y=y, u=u)

    def with_signals(self, *, u=None, input_names=None, input_units=None, extra=None) -> IOData:
        """A copy with other inputs and/or extra signals (same output, ts and experiments).

        Parameters
        ----------
        u : array_like of shape (n_samples,) or (n_samples, n_inputs), optional
            New inputs (None: keep the inputs, their names and units).
        input_names, input_units : sequence of str, optional
            Names and units of the new inputs (defaults as in :class:`IOData`).
        extra : mapping of str to array_like, optional
            New extra signals, replacing all of them (None: keep them).

        Returns
        -------
        IOData
        """
        kw: dict[str, Any] = {}
        if u is not None:
            kw.update(u=u, input_names=tuple(input_names or ()), input_units=tuple(input_units or ()))
        if extra is not None:
            kw["extra"] = extra
        return self.with_samples(**kw)

    @staticmethod
    def merge(datasets: Sequence[IOData]) -> IOData:
        """Several experiments in one object; no regressor ever straddles an experiment boundary.

        Parameters
        ----------
        datasets : sequence of IOData
            Experiments with the same sampling time, output, inputs and extra signals.

        Returns
        -------
        IOData
            The samples one after the other, with ``experiment_starts`` marking each experiment.
        """
        datasets = list(datasets)
        if not datasets:
            raise DataError("merge needs at least one IOData")
        first = datasets[0]
        for d in datasets[1:]:
            if not isinstance(d, IOData):
                raise DataError(f"merge takes IOData objects, got {type(d).__name__}")
            if not math.isclose(d.ts, first.ts, rel_tol=1e-9):
                raise DataError(f"cannot merge experiments sampled at ts={first.ts} and ts={d.ts}; resample first")
            if (
                d.input_names != first.input_names
                or d.output_names != first.output_names
                or set(d.extra) != set(first.extra)
            ):
                raise DataError("merged experiments must have the same output, inputs and extra signals")
        starts, off = [], 0
        for d in datasets:
            starts += [off + s for s in d.experiment_starts]
            off += d.n_samples
        return first.with_samples(
            y=freeze_owned(np.concatenate([d.outputs for d in datasets])),
            u=freeze_owned(np.concatenate([d.u for d in datasets])),
            extra={k: freeze_owned(np.concatenate([d.extra[k] for d in datasets])) for k in first.extra},
            experiment_starts=tuple(starts),
        )

    def to_pandas(self):
        """The data as a pandas DataFrame.

        Returns
        -------
        pandas.DataFrame
            Columns ``time``, the outputs, the inputs and the extra signals.
        """
        try:
            import pandas as pd
        except ImportError:  # pragma: no cover
            raise ImportError("to_pandas needs pandas: pip install 'arxid[pandas]'") from None
        cols = {"time": self.time, **{n: self.outputs[:, i] for i, n in enumerate(self.output_names)}}
        cols.update({n: self.u[:, i] for i, n in enumerate(self.input_names)})
        cols.update(self.extra)
        return pd.DataFrame(cols)

    def __repr__(self) -> str:
        def unit(name):
            u = self.unit(name)
            return f" [{u}]" if u else ""

        dur = self.n_samples * self.ts
        parts = [
            f"IOData: {self.n_samples} samples, ts = {self.ts:g} s ({dur:g} s), "
            f"{self.n_experiments} experiment{'s' if self.n_experiments > 1 else ''}",
            f"  output{'s' if self.n_outputs > 1 else ''}: " + ", ".join(n + unit(n) for n in self.output_names),
            "  inputs: " + ", ".join(n + unit(n) for n in self.input_names),
        ]
        if self.extra:
            parts.append("  extra:  " + ", ".join(n + unit(n) for n in self.extra))
        if self.n_missing:
            parts.append(f"  missing: {self.n_missing} samples hold NaN")
        return "\n".join(parts)
