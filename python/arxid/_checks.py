"""Argument checks shared by the public functions: one message per mistake a user can make."""

from __future__ import annotations

from typing import Any, cast

import numpy as np

from .data import IOData
from .exceptions import ArxidError, DataError, OrderError
from .model import ArxModel
from .polynomial import PolynomialModel

__all__ = ["check_model", "check_data", "check_horizon"]


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
