"""Distinct values and quantiles of a signal from one sort: the numbers of :func:`numpy.unique` and
:func:`numpy.quantile` (its default, linear method) to the bit.

numpy 2.4's ``unique`` and ``median`` ask ``numpy.ma`` whether an array is masked, and
``quantile`` calls ``unique`` on the indices it partitions at: each imports ``numpy.ma`` (~13 ms,
more than a diagnosis's first grid growth) into a process that never masks anything. They are a
sort or a partition and a few slices, done here with numpy's own steps;
``tests/test_order_statistics.py`` holds them to numpy's on random and tied data, signed zeros and
NaNs.
"""

from __future__ import annotations

import numpy as np

__all__ = ["distinct", "median", "quantiles", "sorted_quantiles"]


def distinct(x: np.ndarray) -> np.ndarray:
    """``np.unique(x)``: the distinct values of ``x`` (flattened), ascending, NaNs as one NaN last.

    Parameters
    ----------
    x : array_like

    Returns
    -------
    ndarray
        A new array, of ``x``'s dtype.

    Examples
    --------
    >>> distinct(np.array([3.0, np.nan, 1.0, 3.0, np.nan])).tolist()
    [1.0, 3.0, nan]
    """
    ordered = np.sort(np.ravel(x))  # numpy's own sort (quicksort) of the flattened copy, as unique's
    keep = np.empty(ordered.shape, dtype=bool)
    keep[:1] = True
    if ordered.size and ordered.dtype.kind in "fc" and np.isnan(ordered[-1]):
        first_nan = int(np.searchsorted(ordered, ordered[-1], side="left"))  # NaNs sort last
        keep[1:first_nan] = ordered[1:first_nan] != ordered[: max(first_nan - 1, 0)]
        keep[first_nan] = True
        keep[first_nan + 1 :] = False
    else:
        keep[1:] = ordered[1:] != ordered[:-1]
    return ordered[keep]


def sorted_quantiles(ordered: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``np.quantile(x, q)`` of the values ``ordered``, sorted and finite: the order statistics are
    read instead of partitioned for (the same numbers unless ``x`` holds both -0.0 and 0.0, where
    a sort and a partition may leave different zeros at an order statistic).

    Parameters
    ----------
    ordered : ndarray of shape (n,), n > 0
        Ascending, no NaN.
    q : ndarray of float in [0, 1]

    Returns
    -------
    ndarray of q's shape
    """
    n = len(ordered)
    virtual = (n - 1) * q
    below = np.floor(virtual)
    t = virtual - below
    i = below.astype(np.intp)
    a, b = ordered[i], ordered[np.minimum(i + 1, n - 1)]
    d = b - a
    return np.where(t >= 0.5, b - d * (1 - t), a + d * t)  # numpy's lerp, from the nearer end


def quantiles(x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``np.quantile(x, q)`` of a signal's samples (every quantile NaN when one is NaN), by numpy's
    own steps: the samples partitioned at the same order statistics (so a tie of -0.0 and 0.0
    leaves the same zero at each), then read and interpolated.

    Parameters
    ----------
    x : ndarray of float, at least one sample
    q : ndarray of float in [0, 1], shape (k,)

    Returns
    -------
    ndarray of shape (k,)

    Examples
    --------
    >>> quantiles(np.array([4.0, 1.0, 2.0, 3.0]), np.array([0.0, 0.5, 0.9])).tolist()
    [1.0, 2.5, 3.7]
    """
    arr = np.asarray(x, dtype=float).flatten()
    virtual = (arr.size - 1) * np.asarray(q, dtype=float)
    below, above = np.floor(virtual), np.floor(virtual) + 1
    last = virtual >= arr.size - 1  # the largest sample, read as numpy reads it
    below[last], above[last] = -1, -1
    below, above = below.astype(np.intp), above.astype(np.intp)
    arr.partition(distinct(np.concatenate(([0, -1], below, above))))
    if np.isnan(arr[-1]):
        return np.full(virtual.shape, np.nan)
    t = virtual - below
    a, b = arr[below], arr[above]
    d = b - a
    out = np.add(a, d * t)
    np.subtract(b, d * (1 - t), out=out, where=t >= 0.5)  # numpy's lerp, from the nearer end
    return out


def median(x: np.ndarray) -> np.floating:
    """``np.median(x)`` of a signal's samples (NaN when one is NaN), by numpy's own steps: the
    middle one or two of a partition, and their mean.

    Parameters
    ----------
    x : ndarray of float, at least one sample

    Returns
    -------
    numpy.float64

    Examples
    --------
    >>> float(median(np.array([4.0, 1.0, 2.0, 3.0])))
    2.5
    """
    a = np.asarray(x, dtype=float)
    n = a.size
    part = np.partition(a, [n // 2 - 1, n // 2, -1] if n % 2 == 0 else [(n - 1) // 2, -1], axis=None)
    middle = part[n // 2 - 1 : n // 2 + 1] if n % 2 == 0 else part[n // 2 : n // 2 + 1]
    return part[-1] if np.isnan(part[-1]) else np.mean(middle)
