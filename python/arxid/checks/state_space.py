"""A state-space model in the checks: its predictions of each output on measured data, the data of
one output that the single-output tests read, and the results gathered per output
(:class:`PerOutput`).

:func:`~arxid.compare`, :func:`~arxid.residuals` and :func:`~arxid.where_it_fails` take a
:class:`~arxid.StateSpaceModel` through here: every output is predicted at once (the predictor of
a model of several outputs reads all of them), then each output is judged as a single-output
model's would be.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from typing import Any, Generic, Protocol, TypeVar

import numpy as np

from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError
from ..models.state_space import StateSpaceModel

__all__ = ["PerOutput", "state_space_label", "state_space_prediction", "in_model_order"]


class _Result(Protocol):
    def to_dict(self) -> dict: ...


_R = TypeVar("_R", bound=_Result)


def state_space_label(model: StateSpaceModel) -> str:
    """The model's name in tables: method and order, e.g. ``N4SID, 4 states``."""
    return f"{model.method.upper()}, {model.order} state{'s' if model.order != 1 else ''}"


def in_model_order(model: StateSpaceModel, data: IOData, what: str = "the data") -> IOData:
    """``data`` with their outputs in the model's order, after checking that they measure what the
    model describes: the sampling time, the inputs and every output of the model.

    Parameters
    ----------
    model : StateSpaceModel
    data : IOData
        Data of one output or several.
    what : str
        How to call ``data`` in a message.

    Returns
    -------
    IOData
    """
    if not isinstance(data, IOData):
        raise DataError(f"{what} must be an arxid.IOData, got {type(data).__name__}")
    if not math.isclose(data.ts, model.ts, rel_tol=1e-9):
        raise DataError(f"{what} are sampled at ts = {data.ts:g} s, the model at ts = {model.ts:g} s; resample them")
    if tuple(data.input_names) != tuple(model.input_names):
        raise DataError(f"{what} have inputs {list(data.input_names)}, but the model {list(model.input_names)}")
    missing = [name for name in model.output_names if name not in data.output_names]
    if missing:
        raise DataError(
            f"{what} lack the model's output(s) {missing}: the predictor of a state-space model reads all "
            f"of its outputs {list(model.output_names)}; pass data of all of them"
        )
    if data.output_names == model.output_names:
        return data
    columns = [data.output_names.index(name) for name in model.output_names]
    units = [data.output_units[i] for i in columns]
    names: Any = model.output_names[0] if len(columns) == 1 else list(model.output_names)
    return data.with_outputs(data.outputs[:, columns], names, units[0] if len(columns) == 1 else units)


def state_space_prediction(model: StateSpaceModel, data: IOData, horizon: int | None, initial: str) -> np.ndarray:
    """Every output of the model predicted on ``data`` (already :func:`in_model_order`).

    Parameters
    ----------
    model : StateSpaceModel
    data : IOData
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction.
    initial : {"zero", "estimate"}
        Initial state of each stretch: zero, or fitted to ``data`` by least squares.

    Returns
    -------
    ndarray of shape (n_samples, n_outputs)
        In the model's output order; NaN where a sample is missing.
    """
    with np.errstate(all="ignore"):
        return model.predict(data, k=np.inf if horizon is None else horizon, initial=initial)


@record(eq=False)
class PerOutput(Mapping[str, _R], Generic[_R]):
    """One result per output of a model of several outputs, by output name (a mapping).

    Attributes
    ----------
    results : dict of str to result
        A :class:`~arxid.Comparison`, :class:`~arxid.ResidualAnalysis` or
        :class:`~arxid.FailureAnalysis` per output, in the data's output order.
    """

    results: dict[str, _R]

    def __getitem__(self, name: str) -> _R:
        if name not in self.results:
            raise KeyError(f"no output {name!r}; the outputs are {list(self.results)}")
        return self.results[name]

    def __iter__(self) -> Iterator[str]:
        return iter(self.results)

    def __len__(self) -> int:
        return len(self.results)

    def __str__(self) -> str:
        return "\n\n".join(f"output {name}:\n{result}" for name, result in self.results.items())

    def to_dict(self) -> dict:
        """The result of each output as its own ``to_dict()``.

        Returns
        -------
        dict
            ``{output name: dict}``.
        """
        return {name: result.to_dict() for name, result in self.results.items()}

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None
            Indentation of the JSON; None writes one line.

        Returns
        -------
        str
        """
        import json

        return json.dumps(self.to_dict(), indent=indent)
