"""The ARX regression written out in numpy: regressor names and, when needed, the matrix itself.

The Rust core never materialises this matrix for a fit; Python uses it to name collinear regressors,
for diagnostics (projecting a candidate effect on the model's regressors) and in tests as the
reference the core must match.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence

import numpy as np

from .._base import _core
from ..data.iodata import IOData
from .effects import EffectLayout, integer_power

__all__ = [
    "finite_regressor_columns",
    "regression_rows",
    "write_regressors",
    "output_term_values",
    "regressor_names",
    "regressor_matrix",
    "regressor_columns",
    "lagger",
    "first_of_run",
    "max_lag",
    "row_bound",
]


def _lag(k: int) -> str:
    return "t" if k == 0 else f"t-{k}"


def max_lag(na: int, layout: EffectLayout) -> int:
    """Largest lag any regressor of the model reaches back.

    Parameters
    ----------
    na : int
        Output order.
    layout : EffectLayout
        Input orders and delays with the effects (:func:`arxid.effects.compile_effects`).

    Returns
    -------
    int
        The first row of an experiment that has every regressor.
    """
    # The core's own rule (Structure::max_lag), so Python never mirrors it.
    return int(_core.max_lag(na, list(layout.nb), list(layout.nk), list(layout.output_terms)))


def row_bound(data: IOData, lag: int) -> int:
    """Regression rows at most available when every experiment starts ``lag`` samples in (before
    leaving out the rows that touch a missing sample).

    Parameters
    ----------
    data : IOData
    lag : int

    Returns
    -------
    int
    """
    return sum(max(0, b - a - lag) for a, b in data.segments)


def regressor_names(output_name: str, na: int, layout: EffectLayout) -> list[str]:
    """Names of the regressors in parameter order, e.g. ``roll(t-1)``, ``u1(t-8)``, ``y^3(t-1)``.

    Parameters
    ----------
    output_name : str
        Name of the output signal.
    na : int
        Output order.
    layout : EffectLayout
        Input orders and delays with the effects.

    Returns
    -------
    list of str
    """
    names = [f"{output_name}({_lag(i)})" for i in range(1, na + 1)]
    for label, b, k in zip(layout.column_labels, layout.nb, layout.nk, strict=True):
        if label in ("const", "time"):
            names += [label] * b
        else:
            names += [f"{label}({_lag(k + j)})" for j in range(b)]
    names += [f"{e}(t-1)" for e in layout.effect_of_term]
    return names


def regressor_matrix(
    data: IOData, na: int, layout: EffectLayout, first_lag: int = 0, signs: bool = True
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Regressor matrix Φ (rows × p), output y on those rows, and the row indices.

    Rows start ``max(first_lag, lag)`` into each experiment and skip any row touching a NaN, exactly
    as the Rust core does.

    Parameters
    ----------
    data : IOData
        The data.
    na : int
        Output order.
    layout : EffectLayout
        Input orders and delays with the effects (its ``u`` holds the input columns).
    first_lag : int
        Start every experiment at least this many samples in (to share rows between structures).
    signs : bool
        Enter the output lags as ``-y(t-i)`` (MATLAB convention) rather than ``y(t-i)``.

    Returns
    -------
    phi : ndarray of shape (n_rows, n_params)
    y : ndarray of shape (n_rows,)
    rows : ndarray of int, shape (n_rows,)
        Sample index of each row.
    """
    rows = regression_rows(data, max(first_lag, max_lag(na, layout)))
    phi = np.empty((len(rows), len(regressor_names(data.output_name, na, layout))))
    ok = write_regressors(phi, data, na, layout, rows, signs)
    y = data.y[rows]  # gathered after Φ is written, and once when no sample is missing
    ok &= np.isfinite(y)
    if ok.all():  # no row touches a missing sample: no copies
        return phi, y, rows
    del y  # not held beside Φ and its kept rows (the peak): gathered again on those rows
    return phi[ok], data.y[rows[ok]], rows[ok]


def regression_rows(data: IOData, lag: int) -> np.ndarray:
    """The samples from ``lag`` on in each experiment (missing samples not yet left out).

    Parameters
    ----------
    data : IOData
    lag : int
        First row of each experiment.

    Returns
    -------
    ndarray of int
    """
    parts = [np.arange(a + lag, b) for a, b in data.segments if b > a + lag]
    return np.concatenate(parts or [np.zeros(0, int)]).astype(int)


def write_regressors(
    out: np.ndarray, data: IOData, na: int, layout: EffectLayout, rows: np.ndarray, signs: bool = True
) -> np.ndarray:
    """Write the regressors at ``rows`` into the first columns of ``out``, row by row in the Rust core
    (all cores, the GIL released): each row written once, its finiteness noted on the way, where a
    column at a time made one pass over the matrix per column and one more to find the missing rows.

    Parameters
    ----------
    out : ndarray of shape (len(rows), >= n_params), C-contiguous
    data, na, layout, signs
        As in :func:`regressor_matrix`.
    rows : ndarray of int
        Sample index of each row (each at least the model's largest lag into its experiment).

    Returns
    -------
    ndarray of bool, shape (len(rows),)
        Whether every regressor of each row is finite.
    """
    if na + sum(layout.nb) + len(layout.output_terms) == 0 or not len(rows):
        return np.ones(len(rows), dtype=bool)
    # Arrays unpickled on a Dask worker may be misaligned: the core reads aligned, contiguous ones.
    y, u = (np.require(v, dtype=float, requirements=["C", "A"]) for v in (data.y, layout.u))
    at = np.require(rows, dtype=np.int64, requirements=["C", "A"])
    terms = list(layout.output_terms)
    return _core.regressor_rows(y, u, na, list(layout.nb), list(layout.nk), terms, at, out, signs)


def regressor_columns(
    data: IOData, na: int, layout: EffectLayout, rows: np.ndarray, which: Sequence[int]
) -> np.ndarray:
    """The columns ``which`` of the regressor matrix on the sample rows ``rows``, without building
    the others (NaN kept: the caller decides which rows count).

    Parameters
    ----------
    data : IOData
    na : int
        Output order.
    layout : EffectLayout
        Input orders and delays with the effects.
    rows : ndarray of int
        Sample index of each row (each at least the model's largest lag into its experiment).
    which : sequence of int
        Column indices, in the order of :func:`regressor_names`.

    Returns
    -------
    ndarray of shape (len(rows), len(which))
    """
    index = sorted(set(which))
    out = np.empty((len(rows), len(which)))
    for lo in range(0, len(rows), _BLOCK_ROWS):  # a block of rows at a time: a column's lags share its cache lines
        cols = list(_columns(data, na, layout, rows[lo : lo + _BLOCK_ROWS], set(which), True))
        block = out[lo : lo + _BLOCK_ROWS]
        for i, w in enumerate(which):
            block[:, i] = cols[index.index(w)]
    return out


def finite_regressor_columns(
    data: IOData, na: int, layout: EffectLayout, first_lag: int, which: Sequence[int]
) -> tuple[np.ndarray, np.ndarray]:
    """The columns ``which`` of :func:`regressor_matrix` and its rows (those where no regressor and
    not the output is missing), the whole matrix held a block of rows at a time only.

    Parameters
    ----------
    data, na, layout, first_lag
        As in :func:`regressor_matrix`.
    which : sequence of int
        Column indices, in the order of :func:`regressor_names`.

    Returns
    -------
    z : ndarray of shape (n_rows, len(which))
    rows : ndarray of int, shape (n_rows,)
    """
    rows = regression_rows(data, max(first_lag, max_lag(na, layout)))
    out = np.empty((len(rows), len(which)))
    ok = np.empty(len(rows), dtype=bool)
    for lo in range(0, len(rows), _BLOCK_ROWS):
        at = rows[lo : lo + _BLOCK_ROWS]
        cols = list(_columns(data, na, layout, at, None, True))
        ok[lo : lo + len(at)] = np.isfinite(data.y[at])
        for col in cols:
            ok[lo : lo + len(at)] &= np.isfinite(col)
        block = out[lo : lo + len(at)]
        for i, w in enumerate(which):
            block[:, i] = cols[w]
    return (out, rows) if ok.all() else (out[ok], rows[ok])


#: Rows of the regressors written at a time: the input and output rows a block reads stay in cache
#: while its columns (several lags of the same samples) are written.
_BLOCK_ROWS = 32768


def _columns(
    data: IOData, na: int, layout: EffectLayout, rows: np.ndarray, which: set[int] | None, signs: bool
) -> Iterator[np.ndarray]:
    """The regressor columns at ``rows`` in parameter order (only those in ``which`` when given),
    one at a time."""
    y = data.y
    u = layout.u
    s = -1.0 if signs else 1.0
    at = -1
    lagged = lagger(rows)

    def wanted() -> bool:
        nonlocal at
        at += 1
        return which is None or at in which

    for i in range(1, na + 1):
        if wanted():
            yield s * lagged(y, i)
    for j, (b, k) in enumerate(zip(layout.nb, layout.nk, strict=True)):
        for lag_j in range(b):
            if wanted():
                yield lagged(u[:, j], k + lag_j)
    for kind, power, mult in layout.output_terms:
        if not wanted():
            continue
        g = output_term_values(kind, power, lagged(y, 1), lambda: lagged(y, 2))
        if mult >= 0:
            g = g * lagged(u[:, mult], 1)
        yield g


def output_term_values(kind: str, power: int, y1: np.ndarray, y2: Callable[[], np.ndarray]) -> np.ndarray:
    """g(y(t-1), y(t-2)) of an output term without its carrier, as the core evaluates it.

    Parameters
    ----------
    kind : {"pow", "abs", "sign", "signdiff"}
    power : int
        The power of ``"pow"``.
    y1 : ndarray
        y(t-1).
    y2 : callable
        Gives y(t-2) (read only by ``"signdiff"``).

    Returns
    -------
    ndarray

    Examples
    --------
    >>> y1, y2 = np.array([2.0, -1.0]), np.array([1.0, 1.0])
    >>> output_term_values("pow", 3, y1, lambda: y2).tolist()
    [8.0, -1.0]
    >>> output_term_values("signdiff", 1, y1, lambda: y2).tolist()
    [1.0, -1.0]
    """
    if kind == "pow":
        return integer_power(y1, power)
    if kind == "abs":
        return np.abs(y1)
    if kind == "sign":
        return np.sign(y1)
    return np.sign(y1 - y2())


def lagger(rows: np.ndarray) -> Callable[[np.ndarray, int], np.ndarray]:
    """``lagged(x, lag)``: the samples ``x[rows - lag]``; a view of ``x`` when the rows are one run of
    consecutive samples (the usual case: one experiment without gaps), else a gather.

    Parameters
    ----------
    rows : ndarray of int
        Sample index of each row.

    Returns
    -------
    callable
        ``lagged(x, lag)`` for a signal ``x`` and a lag.

    Examples
    --------
    >>> lagged = lagger(np.array([2, 3, 4]))
    >>> lagged(np.arange(10.0), 2).tolist()
    [0.0, 1.0, 2.0]
    """
    n, first = len(rows), first_of_run(rows)
    if first is not None:
        return lambda x, lag: x[first - lag : first - lag + n]
    return lambda x, lag: x[rows - lag]


def first_of_run(rows: np.ndarray) -> int | None:
    """The first row when ``rows`` are one run of consecutive samples (a lagged column of them is a
    slice), else None.

    Parameters
    ----------
    rows : ndarray of int

    Returns
    -------
    int or None

    Examples
    --------
    >>> first_of_run(np.array([3, 4, 5])), first_of_run(np.array([3, 5]))
    (3, None)
    """
    n = len(rows)
    if n and rows[-1] - rows[0] == n - 1 and bool(np.all(np.diff(rows) == 1)):
        return int(rows[0])
    return None


def dependent_partners(phi: np.ndarray, column: int, names: Sequence[str], top: int = 3) -> list[str]:
    """Regressors before ``column`` that together reproduce it (largest normalised weights first).

    Parameters
    ----------
    phi : ndarray of shape (n_rows, n_params)
        Regressor matrix.
    column : int
        The dependent column.
    names : sequence of str
        Regressor names, one per column.
    top : int
        At most this many partners.

    Returns
    -------
    list of str
    """
    if column == 0:
        return []
    a = phi[:, :column]
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    coef, *_ = np.linalg.lstsq(a / scale, phi[:, column], rcond=None)
    order = np.argsort(-np.abs(coef))
    return [names[i] for i in order[:top] if abs(coef[i]) > 1e-8 * np.abs(coef).max()]
