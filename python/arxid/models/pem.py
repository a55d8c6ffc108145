"""Prediction-error estimation: :func:`oe`, :func:`armax`, :func:`bj`, :func:`polyest` and :func:`delayest`.

The iterations run in the Rust core (Gauss–Newton with Levenberg–Marquardt damping, each step
solved by QR of the filtered gradient; an ARX / refined-instrumental-variable start; F, C and D kept
stable by reflecting roots into the unit circle). See :class:`arxid.PolynomialModel`. The output-error
refinement of a sweep (:func:`arxid.refine`) is in :mod:`arxid.selection.refine`.
"""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from ..data.iodata import IOData
from ..exceptions import DataError, OrderError
from .arx_model import ArxModel
from .polynomial import PolynomialModel

__all__ = ["oe", "armax", "bj", "polyest", "delayest"]


def _fit(model: PolynomialModel, data: IOData, options: dict[str, Any]) -> PolynomialModel:
    if not isinstance(data, IOData):
        raise DataError(f"expected an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)")
    return model.fit(data, **options)


def oe(data: IOData, nb: Any, nf: Any, nk: Any, **options: Any) -> PolynomialModel:
    """Fit an output-error model y = B/F u + e (MATLAB ``oe(data, [nb nf nk])``).

    Parameters
    ----------
    data : IOData
    nb, nf, nk : int or sequence of int
        Per input: numerator coefficients, poles (order of F) and delay in samples.
    **options
        ``start``, ``max_iterations``, ``tolerance``, ``n_threads``, ``warn`` and ``initial`` (``"zero"`` or
        ``"estimate"``: the initial state of each run estimated too) of :meth:`PolynomialModel.fit`.

    Returns
    -------
    PolynomialModel

    Raises
    ------
    DataError, OrderError, IdentifiabilityError, ConvergenceError

    Notes
    -----
    Unbiased when the noise enters at the output (sensor noise), where ARX is not.
    """
    return _fit(PolynomialModel(nb=nb, nf=nf, nk=nk), data, options)


def armax(data: IOData, na: int, nb: Any, nc: int, nk: Any, **options: Any) -> PolynomialModel:
    """Fit an ARMAX model A y = B u + C e (MATLAB ``armax(data, [na nb nc nk])``).

    Parameters
    ----------
    data : IOData
    na, nc : int
        Orders of A and C.
    nb, nk : int or sequence of int
        Per input: numerator coefficients and delay.
    **options
        As :func:`oe`.

    Returns
    -------
    PolynomialModel
    """
    return _fit(PolynomialModel(na=na, nb=nb, nc=nc, nk=nk), data, options)


def bj(data: IOData, nb: Any, nc: int, nd: int, nf: Any, nk: Any, **options: Any) -> PolynomialModel:
    """Fit a Box–Jenkins model y = B/F u + C/D e (MATLAB ``bj(data, [nb nc nd nf nk])``).

    Parameters
    ----------
    data : IOData
    nb, nf, nk : int or sequence of int
        Per input: numerator coefficients, poles and delay.
    nc, nd : int
        Orders of the noise numerator C and denominator D.
    **options
        As :func:`oe`.

    Returns
    -------
    PolynomialModel
    """
    return _fit(PolynomialModel(nb=nb, nc=nc, nd=nd, nf=nf, nk=nk), data, options)


def polyest(data: IOData, na: int, nb: Any, nc: int, nd: int, nf: Any, nk: Any, **options: Any) -> PolynomialModel:
    """Fit the general polynomial model A y = B/F u + C/D e (MATLAB ``polyest(data, [na nb nc nd nf nk])``).

    Parameters
    ----------
    data : IOData
    na, nc, nd : int
        Orders of A (poles shared by the input and the noise paths), C and D.
    nb, nf, nk : int or sequence of int
        Per input: numerator coefficients, poles of F and delay.
    **options
        As :func:`oe`.

    Returns
    -------
    PolynomialModel

    Notes
    -----
    The start is ARX for A and B (F = 1), Hannan–Rissanen for C and D; the Gauss–Newton iterations
    then fit every polynomial. Prefer the named structures when one fits: OE, ARMAX and BJ are
    special cases with fewer parameters to determine.
    """
    return _fit(PolynomialModel(na=na, nb=nb, nc=nc, nd=nd, nf=nf, nk=nk), data, options)


def _int(name: str, value: Any, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or int(value) < low:
        raise OrderError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)


def delayest(
    data: IOData, na: int = 2, nb: int = 2, nkmin: int = 0, nkmax: int | None = None, *, confirm: int = 3
) -> int:
    """Input delay in samples, as MATLAB's ``delayest``: ARX(na, nb, nk) over a range of delays, the
    best few confirmed by output-error fits.

    Parameters
    ----------
    data : IOData
        Single-input data.
    na, nb : int
        Orders of the ARX models compared (and the OE models that confirm).
    nkmin, nkmax : int
        Delays tried (default ``nkmax = nkmin + 20``).
    confirm : int
        Number of best ARX delays refitted as OE(nb, na, nk); the lowest OE loss wins (0: ARX only).

    Returns
    -------
    int
        The delay in samples.

    Notes
    -----
    All ARX models are scored on the same samples (from the largest lag on), so their losses
    compare. Under output noise ARX is biased; the OE confirmation is not.
    """
    if not isinstance(data, IOData):
        raise DataError(f"delayest needs an arxid.IOData, got {type(data).__name__}")
    if data.n_inputs != 1:
        raise OrderError(f"delayest estimates the delay of one input; the data have {data.n_inputs}: select one")
    na, nb, nkmin = _int("na", na), _int("nb", nb, 1), _int("nkmin", nkmin)
    nkmax = nkmin + 20 if nkmax is None else _int("nkmax", nkmax)
    if nkmax < nkmin:
        raise OrderError(f"nkmax ({nkmax}) must be >= nkmin ({nkmin})")
    lag = max(na, nb + nkmax - 1)
    delays = list(range(nkmin, nkmax + 1))
    losses = [ArxModel(na=na, nb=nb, nk=k).fit(data, first_lag=lag).loss_ for k in delays]
    ranked = [delays[i] for i in np.argsort(losses, kind="stable")]
    candidates = ranked[: _int("confirm", confirm)]
    if len(candidates) <= 1:
        return int(ranked[0])
    oe_losses = []
    for k in candidates:
        oe_losses.append(oe(data, nb, na, k, warn=False).loss_ if na else losses[delays.index(k)])
    return int(candidates[int(np.argmin(oe_losses))])
