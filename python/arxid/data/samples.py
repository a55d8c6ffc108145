"""Sample arrays and sampling times as :class:`~arxid.IOData` accepts them: numbers, finite or NaN
(a missing sample), float64, frozen so that data can be shared without copies; sampling times in a
plausible range of seconds."""

from __future__ import annotations

import sys
from typing import Any

import numpy as np

from ..exceptions import DataError

__all__ = ["MAX_TS", "MIN_TS", "as_float_samples", "check_sampling_time", "freeze_owned"]


def _is_masked(values) -> bool:
    """Whether ``values`` is a numpy masked array, without importing numpy.ma (a fifth of the command
    line's start on a small file): none exists before numpy.ma is imported."""
    ma = sys.modules.get("numpy.ma")
    return ma is not None and isinstance(values, ma.MaskedArray)


def as_float_samples(name: str, values, ndim: int) -> np.ndarray:
    """``values`` as a float64 array of ``ndim`` dimensions (shared when it is frozen already), or a
    :class:`DataError` naming ``name`` and what to pass.

    Parameters
    ----------
    name : str
        What the values are, for the message (``"y (output)"``).
    values : array_like
        Numbers; NaN marks a missing sample, a masked entry becomes NaN.
    ndim : int
        1 for a signal, 2 for inputs (a vector becomes one column).

    Returns
    -------
    ndarray
        C-ordered float64.
    """
    if values is None:
        raise DataError(f"{name} is None; pass a list or numpy array of numbers")
    if _is_masked(values):
        # A masked sample is a missing one: NaN, as everywhere in arxid (the mask would be lost).
        if values.dtype.kind not in "biuf":
            raise DataError(f"{name} is a masked array of {values.dtype}; it must hold numbers")
        values = np.ma.filled(values.astype(np.float64), np.nan)
    try:
        arr = np.asarray(values)
    except Exception as exc:  # ragged lists and the like
        raise DataError(
            f"{name} could not be read as a numeric array ({exc}); pass a list or numpy array of numbers"
        ) from None
    if arr.dtype == object or arr.dtype.kind in "USV":
        raise DataError(
            f"{name} has dtype {arr.dtype}; it must hold numbers (convert it with numpy.asarray(..., dtype=float))"
        )
    if arr.dtype.kind == "c":
        raise DataError(f"{name} is complex; arxid identifies real-valued signals")
    if arr.dtype.kind == "b":
        arr = arr.astype(np.float64)
    if not _is_frozen_float(arr):
        arr = np.array(arr, dtype=np.float64, copy=True, order="C")
    if ndim == 1 and arr.ndim == 2 and 1 in arr.shape:
        arr = arr.reshape(-1)
    if ndim == 2 and arr.ndim == 1:
        arr = arr.reshape(-1, 1)
    if arr.ndim != ndim:
        shape = "(n_samples,)" if ndim == 1 else "(n_samples, n_inputs)"
        raise DataError(f"{name} has shape {arr.shape}; expected {shape}")
    if np.isinf(arr).any():
        idx = int(np.argwhere(np.isinf(arr))[0][0])
        raise DataError(f"{name} holds an infinite value at sample {idx}; mark missing samples with NaN instead")
    return arr


def _is_frozen_float(arr: np.ndarray) -> bool:
    """Whether ``arr`` can be shared rather than copied: C-ordered float64 that neither it nor any
    array it views can write (an IOData's own samples, a slice of them, a read-only memory map)."""
    if arr.dtype != np.float64 or not arr.flags.c_contiguous:
        return False
    a: Any = arr
    while isinstance(a, np.ndarray):
        if a.flags.writeable:
            return False
        a = a.base
    return True


def freeze_owned(arr: np.ndarray) -> np.ndarray:
    """An array nobody else holds (made or read just now) made read-only, with the buffers it views,
    so that IOData takes it without a copy.

    Parameters
    ----------
    arr : ndarray

    Returns
    -------
    ndarray
        ``arr`` itself.
    """
    a: Any = arr
    while isinstance(a, np.ndarray):
        a.setflags(write=False)
        a = a.base
    return arr


#: Sampling times arxid accepts, in seconds: 1 ns to one day. Outside, the value is almost surely a
#: wrong unit (milliseconds or microseconds read as seconds), and ``time`` effects would overflow.
MIN_TS, MAX_TS = 1e-9, 86400.0


def check_sampling_time(ts: float) -> None:
    """A :class:`DataError` of its own for an absurd sampling time (it would otherwise surface as an
    overflow warning and "too few usable samples").

    Parameters
    ----------
    ts : float
        The sampling time in seconds.
    """
    if ts < MIN_TS:
        raise DataError(
            f"ts = {ts:g} s is below 1 ns ({MIN_TS:g} s): no sampled data are that fast; "
            "give the sampling time in seconds (for example ts=0.001 for 1 kHz)"
        )
    if ts > MAX_TS:
        raise DataError(
            f"ts = {ts:g} s is longer than a day ({MAX_TS:g} s); give the sampling time in seconds "
            "(a time column in milliseconds or microseconds must be converted to seconds first)"
        )
