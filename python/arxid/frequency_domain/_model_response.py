"""A fitted model's frequency response at the frequencies of a measured one (for the Bode figure)."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..exceptions import DataError
from ..models.polynomial import PolynomialModel

__all__ = ["model_response"]


def model_response(model: Any, frequency: np.ndarray, input: int = 0) -> np.ndarray:
    """B(e^{−jω}) / (A(e^{−jω}) F(e^{−jω})) of ``input`` at ``frequency`` [Hz], ω = 2π f ts.

    A :class:`~arxid.models.continuous_tf.ContinuousTransferFunction` is evaluated through its exact
    zero-order-hold discrete equivalent, which is what a frequency response measured on sampled
    data with held inputs shows.

    Parameters
    ----------
    model : ArxModel or PolynomialModel
        A fitted model (its linear part).
    frequency : ndarray of shape (n_f,)
        Hz.
    input : int
        Which input.

    Returns
    -------
    ndarray of complex, shape (n_f,)
    """
    if not (hasattr(model, "a") and hasattr(model, "b") and hasattr(model, "ts_")):
        raise DataError(f"expected a fitted arxid model (arx, oe, tfest, ...), got {type(model).__name__}")
    zinv = np.exp(-2j * np.pi * np.asarray(frequency, dtype=float) * model.ts_)
    b = np.asarray(model.b[input], dtype=float)
    den = np.asarray(model.a, dtype=float)
    if isinstance(model, PolynomialModel) and model.nf_[input]:
        den = np.convolve(den, model.f[input])
    return np.polyval(b[::-1], zinv) / np.polyval(den[::-1], zinv)
