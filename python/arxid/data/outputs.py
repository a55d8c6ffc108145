"""Several measured outputs in one :class:`~arxid.IOData`.

The single-output fields ``y``, ``output_name`` and ``output_unit`` keep their meaning (one array,
one name, one unit) and refuse, with a :class:`~arxid.exceptions.DataError` that says what to do,
to be read from data of several outputs: every single-output path (ARX, sweeps, the diagnosis)
reads them, so none can take the first output silently. The views of all outputs are
``outputs``, ``output_names``, ``output_units`` and ``output(name)``, which :class:`~arxid.IOData`
inherits from :class:`SeveralOutputs`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any, Generic, TypeVar, cast

import numpy as np

from ..exceptions import DataError
from .samples import as_float_samples

__all__ = ["GridBuilt", "OutputField", "SeveralOutputs", "checked_outputs", "output_list", "several_outputs_error"]

_T = TypeVar("_T")
_NO_DEFAULT = object()
_S = TypeVar("_S", bound="SeveralOutputs")
_G = TypeVar("_G", bound="GridBuilt")


def output_list(output: Any) -> list[str]:
    """Output names as a list: a string is one name, ``"p,q,r"`` is not split (column names may hold
    commas); a sequence is taken as it is.

    Parameters
    ----------
    output : str or sequence of str

    Returns
    -------
    list of str
    """
    if isinstance(output, str):
        return [output]
    if isinstance(output, Sequence) and output and all(isinstance(o, str) for o in output):
        return list(output)
    raise DataError(f"output must be a column name or a list of column names, got {output!r:.80}")


def several_outputs_error(names: Sequence[str], what: str) -> DataError:
    """The error of a single-output path that received data of several outputs.

    Parameters
    ----------
    names : sequence of str
        The data's outputs.
    what : str
        What was asked for (``"y"``, ``"the output name"``).

    Returns
    -------
    DataError
    """
    return DataError(
        f"these data have {len(names)} outputs ({', '.join(names)}), and {what} means one: pick one with "
        f"data.output({names[0]!r}), or identify all of them at once with arxid.ssest(data)"
    )


def _is_several(obj: Any) -> bool:
    return type(obj.__dict__.get("output_name")) is tuple


class OutputField(Generic[_T]):
    """A dataclass field of one output (``y``, ``output_name``, ``output_unit``), read as stored when
    the data have one output and refused with :func:`several_outputs_error` when they have several.

    Parameters
    ----------
    default : optional
        The field's default; none when omitted.
    """

    def __init__(self, default: Any = _NO_DEFAULT) -> None:
        self.default = default
        self.name = ""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, obj: Any, owner: Any = None) -> _T:
        if obj is None:  # the dataclass asks for the default
            if self.default is _NO_DEFAULT:
                raise AttributeError(self.name)
            return cast(_T, self.default)
        if _is_several(obj):
            raise several_outputs_error(obj.__dict__["output_name"], f"data.{self.name}")
        return cast(_T, obj.__dict__[self.name])

    def __set__(self, obj: Any, value: Any) -> None:
        obj.__dict__[self.name] = value


class SeveralOutputs:
    """The views of all outputs of :class:`~arxid.IOData` (it inherits them)."""

    @property
    def outputs(self) -> np.ndarray:
        """All outputs, shape (n_samples, n_outputs) (read-only); one column for single-output data."""
        y = self.__dict__["y"]
        return y if y.ndim == 2 else y[:, None]

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the outputs, one for single-output data."""
        name = self.__dict__["output_name"]
        return name if _is_several(self) else (name,)

    @property
    def output_units(self) -> tuple[str, ...]:
        """Units of the outputs, in the order of ``output_names``."""
        unit = self.__dict__["output_unit"]
        return unit if _is_several(self) else (unit,)

    @property
    def n_outputs(self) -> int:
        """Number of outputs (columns of ``outputs``)."""
        return len(self.output_names)

    def output(self: _S, name: str) -> _S:
        """The data of one output: the same inputs, extra signals, experiments and sampling time.

        Parameters
        ----------
        name : str
            One of ``output_names``.

        Returns
        -------
        IOData
            Single-output data (``y`` is that output).
        """
        if name not in self.output_names:
            raise DataError(f"no output named {name!r}; the outputs are {list(self.output_names)}")
        i = self.output_names.index(name)
        return self.with_outputs(self.outputs[:, i], name, self.output_units[i])

    def with_outputs(self: _S, y: Any, names: Any, units: Any = None, **changes: Any) -> _S:
        """A copy with other outputs (and other fields in ``changes``), by :func:`dataclasses.replace`.

        Parameters
        ----------
        y : array_like of shape (n_samples,) or (n_samples, n_outputs)
        names : str or sequence of str
        units : str or sequence of str, optional
            Default: no unit.
        **changes
            Other fields of :class:`~arxid.IOData`.

        Returns
        -------
        IOData
        """
        if units is None:
            units = "" if isinstance(names, str) else ("",) * len(names)
        return replace(cast(Any, self), y=y, output_name=names, output_unit=units, **changes)

    def with_samples(self: _S, **changes: Any) -> _S:
        """A copy with the fields in ``changes`` replaced, the others kept (the output fields too,
        which cannot be read one by one from data of several outputs).

        Parameters
        ----------
        **changes
            Fields of :class:`~arxid.IOData`.

        Returns
        -------
        IOData
        """
        raw = self.__dict__
        y, name, unit = (changes.pop(k, raw[k]) for k in ("y", "output_name", "output_unit"))
        return self.with_outputs(y, name, unit, **changes)


def checked_outputs(y: Any, name: Any, unit: Any) -> tuple[np.ndarray, Any, Any]:
    """The output samples, name(s) and unit(s) of an :class:`~arxid.IOData` as it stores them: one
    output as a 1-D array, a name and a unit; several as a 2-D array and tuples (a list of one name
    is one output).

    Parameters
    ----------
    y : array_like of shape (n_samples,) or (n_samples, n_outputs)
    name : str or sequence of str
    unit : str or sequence of str
        One unit for all outputs, or one per output.

    Returns
    -------
    (ndarray, str or tuple of str, str or tuple of str)
    """
    names = [name] if isinstance(name, str) else name
    if not isinstance(names, Sequence) or not names or not all(isinstance(n, str) for n in names):
        raise DataError(f"output_name must be a string, or a list of strings for several outputs, got {name!r:.80}")
    units = [unit] * len(names) if isinstance(unit, str) else unit  # one unit for all of them
    if isinstance(units, str) or not isinstance(units, Sequence) or not all(isinstance(x, str) for x in units):
        raise DataError(f"output_unit must be a string, or a list of strings for several outputs, got {unit!r:.80}")
    if len(units) != len(names):
        raise DataError(f"{len(units)} output units given for {len(names)} outputs")
    if len(names) == 1:
        if isinstance(y, np.ndarray) and y.ndim == 2 and y.shape[1] > 1:
            raise DataError(
                f"y has shape {y.shape}, {y.shape[1]} columns but one output name; for several outputs "
                "name each, e.g. output_name=['p', 'q', 'r']"
            )
        return as_float_samples("y (output)", y, 1), names[0], units[0]
    samples = as_float_samples("y (outputs)", y, 2)
    if samples.shape[1] != len(names):
        raise DataError(f"{len(names)} output names given for {samples.shape[1]} output columns of y")
    return samples, tuple(names), tuple(units)


class GridBuilt:
    """What the readers (tables, flight logs) build on: signals on one grid made into an IOData."""

    @classmethod
    def _from_grid(
        cls: type[_G],
        values: Mapping[str, np.ndarray],
        units: Mapping[str, str],
        ts: float,
        n_inputs: int,
        n_outputs: int = 1,
    ) -> _G:
        """Signals on one grid as an IOData: the outputs first, then the inputs, then extras."""
        raise NotImplementedError  # IOData builds itself
