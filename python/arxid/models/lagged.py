"""Lagged signals as regression rows: rows never cross an experiment start and rows that touch a
missing sample (NaN) are left out. Used by the feedback test, the AR models of the residual tests'
prewhitening and of the dependence test's noise (:func:`ar_factor`), and the Python reference of
the instrumental-variable estimator."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._base import _core
from .._base.digital_filter import lfilter
from .._base.nested import BLOCK_ROWS, cholesky_factor, core_readable

__all__ = ["ar_factor", "lagged_columns", "lagged_factor", "lagged_gram", "filter_segments"]


def lagged_columns(
    columns: Sequence[tuple[np.ndarray, int]], segments: Sequence[tuple[int, int]], back: int, ahead: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The matrix whose column ``j`` holds ``signal_j(t - lag_j)`` for every usable row ``t``.

    Parameters
    ----------
    columns : sequence of (ndarray of shape (n_samples,), int)
        A signal and its lag (negative: a lead, a later sample).
    segments : sequence of (int, int)
        Half-open sample ranges of the experiments.
    back, ahead : int
        Largest lag and largest lead: row ``t`` of an experiment ``[a, b)`` is used when
        ``a + back <= t < b - ahead``.

    Returns
    -------
    matrix : ndarray of shape (n_rows, n_columns)
    rows : ndarray of int
        The sample ``t`` of each row.
    """
    parts = [np.arange(a + back, b - ahead) for a, b in segments if b - ahead > a + back]
    rows = np.concatenate(parts) if parts else np.zeros(0, dtype=int)
    mat = np.empty((rows.shape[0], len(columns)))
    for j, (signal, lag) in enumerate(columns):
        mat[:, j] = signal[rows - lag]
    keep = np.all(np.isfinite(mat), axis=1)
    return mat[keep], rows[keep]


def _blocks(
    columns: Sequence[tuple[np.ndarray, int]], segments: Sequence[tuple[int, int]], back: int, ahead: int, count: list
):
    """The matrix of :func:`lagged_columns` one block of rows at a time (rows touching a missing
    sample left out); ``count[0]`` grows by the rows of each block."""
    parts = [np.arange(a + back, b - ahead) for a, b in segments if b - ahead > a + back]
    rows = np.concatenate(parts) if parts else np.zeros(0, dtype=int)
    signals = list({id(signal): signal for signal, _ in columns}.values())
    low, high = min((lag for _, lag in columns), default=0), max((lag for _, lag in columns), default=0)
    for lo in range(0, len(rows), BLOCK_ROWS):
        at = rows[lo : lo + BLOCK_ROWS]
        mat = np.empty((len(at), len(columns)))
        first, last = int(at[0]), int(at[-1])
        consecutive = last - first == len(at) - 1
        for j, (signal, lag) in enumerate(columns):
            # Consecutive samples (the usual block): a slice, not a gather.
            mat[:, j] = signal[first - lag : last + 1 - lag] if consecutive else signal[at - lag]
        # A block whose signals are finite over the samples it reads needs no row-by-row check.
        if not (consecutive and all(np.isfinite(x[first - high : last + 1 - low]).all() for x in signals)):
            finite = np.isfinite(mat).all(axis=1)
            if not finite.all():
                mat = mat[finite]
        count[0] += len(mat)
        yield mat


def lagged_factor(
    columns: Sequence[tuple[np.ndarray, int]], segments: Sequence[tuple[int, int]], back: int, ahead: int = 0
) -> tuple[np.ndarray, int]:
    """The triangular factor R (R'R = M'M) of the matrix M of :func:`lagged_columns`, by Householder
    QR of one block of rows at a time in the Rust core (on every core; the same R for any number):
    M is never held whole (a high-order model on a long record has dozens of columns).

    Parameters
    ----------
    columns, segments, back, ahead
        As in :func:`lagged_columns`.

    Returns
    -------
    r : ndarray of shape (min(n_rows, n_columns), n_columns)
    n_rows : int
        Rows of M (those touching a missing sample left out).

    Examples
    --------
    >>> x = np.arange(6.0)
    >>> r, n = lagged_factor([(x, 1), (x, 0)], [(0, 6)], 1)
    >>> n, np.round(r.T @ r, 9).tolist()
    (5, [[30.0, 40.0], [40.0, 55.0]])
    """
    index: dict[int, int] = {}  # each signal passed once, however many of its lags are columns
    sources: list[np.ndarray] = []
    for signal, _ in columns:
        if id(signal) not in index:
            index[id(signal)] = len(sources)
            sources.append(core_readable(signal)[:, None])
    spec = [(index[id(signal)], 0, int(lag)) for signal, lag in columns]
    r, n_rows = _core.lagged_r(sources, spec, [(int(a), int(b)) for a, b in segments], int(back), int(ahead))
    return np.asarray(r)[: min(n_rows, len(columns))], int(n_rows)


def lagged_gram(
    columns: Sequence[tuple[np.ndarray, int]], segments: Sequence[tuple[int, int]], back: int, ahead: int = 0
) -> tuple[np.ndarray, int]:
    """The cross-product matrix M'M of the matrix M of :func:`lagged_columns`, summed one block of
    rows at a time (M is never held whole; several times faster than :func:`lagged_factor`, and as
    accurate where M'M is well conditioned).

    Parameters
    ----------
    columns, segments, back, ahead
        As in :func:`lagged_columns`.

    Returns
    -------
    gram : ndarray of shape (n_columns, n_columns)
    n_rows : int
        Rows of M (those touching a missing sample left out).

    Examples
    --------
    >>> x = np.arange(6.0)
    >>> g, n = lagged_gram([(x, 1), (x, 0)], [(0, 6)], 1)
    >>> n, g.tolist()
    (5, [[30.0, 40.0], [40.0, 55.0]])
    """
    one = _lags_of_one_series(columns, segments, back, ahead)
    if one is not None:
        return one
    count = [0]
    gram = np.zeros((len(columns), len(columns)))
    for mat in _blocks(columns, segments, back, ahead, count):
        gram += mat.T @ mat
    return gram, count[0]


def _lags_of_one_series(
    columns: Sequence[tuple[np.ndarray, int]], segments: Sequence[tuple[int, int]], back: int, ahead: int
) -> tuple[np.ndarray, int] | None:
    """:func:`lagged_gram` when every column is a lag of one series (an AR model's regressors):
    entry (i, j) is the series' product with itself at lag |l_i − l_j| over each stretch of rows
    (the core's lagged products: one pass for every lag, not one per pair of columns), less the few
    products at the stretch's ends that the rows do not reach. The rows that touch a missing sample
    split an experiment into stretches; None (the general path) when the columns read other series
    or the missing samples make more than :data:`_MAX_STRETCHES` stretches."""
    x = columns[0][0] if columns else None
    if x is None or any(signal is not x for signal, _ in columns):
        return None
    lags = [int(lag) for _, lag in columns]
    top, bottom = max(lags), min(lags)
    # With every lag from bottom to top a column, a row drops out exactly when a sample it spans is
    # missing (see _finite_stretches); with lags left out, only when every sample is there.
    contiguous = set(lags) == set(range(bottom, top + 1))
    stretches: list[tuple[int, int]] = []
    for a, b in segments:
        lo, hi = a + back, b - ahead  # the rows t, reading x(t − lag)
        if hi <= lo:
            continue
        if lo - top < a or hi - bottom > b:
            return None  # a lag beyond back or ahead reads outside the experiment
        found = _finite_stretches(x, lo, hi, top, bottom)
        if len(stretches) + len(found) > _MAX_STRETCHES or (found != [(lo, hi)] and not contiguous):
            return None
        stretches += found
    gram = np.zeros((len(lags), len(lags)))
    for lo, hi in stretches:
        gram += _stretch_gram(x, lags, lo, hi)
    return np.triu(gram) + np.triu(gram, 1).T, sum(hi - lo for lo, hi in stretches)


#: Stretches of rows between missing samples beyond which the lagged products' shortcut is left to
#: the general path (each stretch is one call into the core).
_MAX_STRETCHES = 64


def _finite_stretches(x: np.ndarray, lo: int, hi: int, top: int, bottom: int) -> list[tuple[int, int]]:
    """The rows t in [lo, hi) whose samples x(t − top) … x(t − bottom) are all finite, as stretches
    of consecutive rows (every sample a stretch's rows span is finite)."""
    ok = np.isfinite(x[lo - top : hi - bottom])
    if ok.all():
        return [(lo, hi)]
    edges = np.flatnonzero(np.diff(np.r_[False, ok, False].astype(np.int8)))
    out = []
    for c, d in zip(edges[::2], edges[1::2], strict=True):  # a finite run of samples lo − top + [c, d)
        first, last = lo + c, min(hi, lo - top + d + bottom)  # the rows reading only that run
        if last > first:
            out.append((first, last))
    return out


def _stretch_gram(x: np.ndarray, lags: list[int], lo: int, hi: int) -> np.ndarray:
    """The upper triangle of M'M for the rows [lo, hi) of one stretch (every sample read finite)."""
    top, bottom = max(lags), min(lags)
    first = lo - top
    seg = np.ascontiguousarray(x[first : hi - bottom], dtype=float)
    # c[d] = Σ_s seg[s] seg[s − d] over every s >= d; the rows cover s in [top − l, hi − l − first)
    c = np.asarray(_core.lagged_products(seg, seg, 0, top - bottom))
    q = len(lags)
    gram = np.zeros((q, q))
    for i in range(q):
        for j in range(i, q):
            near, d = min(lags[i], lags[j]), abs(lags[i] - lags[j])
            s0, s1 = top - near, hi - near - first
            head = float(np.dot(seg[d:s0], seg[: s0 - d]))
            tail = float(np.dot(seg[s1:], seg[s1 - d : len(seg) - d]))
            gram[i, j] = c[d] - head - tail
    return gram


def ar_factor(x: np.ndarray, segments: Sequence[tuple[int, int]], order: int) -> tuple[np.ndarray, int]:
    """R of ``[x(t−1) … x(t−order) | x(t)]`` (the regression of an AR model of ``x``) over the rows
    of each segment from its ``order``-th sample, rows touching a missing sample left out; reduced
    block by block of rows, never held whole: the Cholesky factor of its cross products when they
    are well conditioned (a near-white series: R then keeps about twelve digits), else Householder
    QR (a drifting or integrating series).

    Parameters
    ----------
    x : ndarray of shape (n_samples,)
    segments : sequence of (int, int)
    order : int

    Returns
    -------
    r : ndarray of shape (order + 1, order + 1)
    n_rows : int
    """
    columns = [*((x, k) for k in range(1, order + 1)), (x, 0)]
    gram, n_rows = lagged_gram(columns, segments, order)
    r = cholesky_factor(gram, _WELL_CONDITIONED)
    if r is None:
        r, n_rows = lagged_factor(columns, segments, order)
    return r, n_rows


#: Smallest eigenvalue, relative to the largest, of the scaled cross products whose Cholesky factor
#: stands for the QR's R in :func:`ar_factor` (rounding in R grows with the condition number).
_WELL_CONDITIONED = 1e-4


def filter_segments(num: np.ndarray, den: np.ndarray, x: np.ndarray, segments: Sequence[tuple[int, int]]) -> np.ndarray:
    """``num(q^-1) / den(q^-1)`` applied to ``x`` from rest in each experiment (NaN samples as 0).

    Parameters
    ----------
    num, den : ndarray
        Polynomials in ``q^-1``, ``den[0] != 0``.
    x : ndarray of shape (n_samples,)
    segments : sequence of (int, int)

    Returns
    -------
    ndarray of shape (n_samples,)
    """
    out = np.empty_like(x, dtype=float)
    clean = np.where(np.isfinite(x), x, 0.0)
    for a, b in segments:
        out[a:b] = lfilter(num, den, clean[a:b])
    return out
