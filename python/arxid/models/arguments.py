"""Argument checks shared by the public functions: one message per mistake a user can make."""

from __future__ import annotations

import math
from typing import Any, cast

import numpy as np

from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from .arx_model import ArxModel
from .polynomial import PolynomialModel
from .wiener import WienerModel

__all__ = ["check_model", "check_predictor", "check_data", "check_horizon", "check_same_signals"]


def check_model(model: Any) -> ArxModel:
    """``model`` if it is a fitted :class:`~arxid.ArxModel` (or :class:`~arxid.PolynomialModel`, which
    has the same surface), else a typed error saying what to pass."""
    if not isinstance(model, (ArxModel, PolynomialModel)):
        raise ArxidError(
            f"expected a fitted arxid.ArxModel, got {type(model).__name__}; fit one with arxid.arx(data, na, nb, nk)"
        )
    model.check_fitted()
    # A PolynomialModel has the ArxModel surface the checked functions use (duck typing).
    return cast(ArxModel, model)


def check_predictor(model: Any) -> Any:
    """``model`` as :func:`check_model` checks it, or a fitted Wiener model (the error ladder's last
    step when the output is read through a sensor shape): the models a comparison or a search for
    where the error lies predicts with."""
    if isinstance(model, WienerModel):
        model.check_fitted()
        return model
    return check_model(model)


def check_data(data: Any, what: str = "data") -> IOData:
    """``data`` if it is an :class:`~arxid.IOData`, else a :class:`DataError` naming ``what``."""
    if not isinstance(data, IOData):
        raise DataError(
            f"{what} must be an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)"
        )
    return data


def check_horizon(horizon: Any) -> int | None:
    """None (free run) or a prediction horizon k ≥ 1 as an int."""
    if horizon is None:
        return None
    if isinstance(horizon, bool) or not isinstance(horizon, (int, np.integer)) or horizon < 1:
        raise OrderError(f"horizon must be None (free run) or an integer >= 1, got {horizon!r}")
    return int(horizon)


def check_same_signals(ts: float, output_name: str, input_names: tuple[str, ...], data: IOData, what: str) -> None:
    """A :class:`DataError` unless ``data`` are sampled at ``ts`` and name the same output and inputs
    (validation data must measure what the model or the estimation data describe).

    Parameters
    ----------
    ts : float
        The reference sampling time in seconds.
    output_name : str
        The reference output name.
    input_names : tuple of str
        The reference input names.
    data : IOData
        The data to check.
    what : str
        How to call ``data`` in the message, e.g. ``"the validation data"``.

    Returns
    -------
    None
    """
    if not math.isclose(data.ts, ts, rel_tol=1e-9):
        raise DataError(f"{what} are sampled at ts = {data.ts:g} s, but ts = {ts:g} s is expected; resample them")
    if data.output_name != output_name or tuple(data.input_names) != tuple(input_names):
        raise DataError(
            f"{what} have output {data.output_name!r} and inputs {list(data.input_names)}, but "
            f"{output_name!r} and {list(input_names)} are expected; pass data of the same signals "
            "(rename them with output_name=/input_names=)"
        )
