"""Parsimony: the smallest structure whose validation error is not statistically worse than the best's.

Two structures are compared on the same validation samples by the Diebold–Mariano test of equal
accuracy: with the squared-error difference ``d_t = e_small(t)² − e_best(t)²``, the statistic is
``DM = mean(d) / √(S / n)``, where ``S`` is the long-run variance of ``d`` (Bartlett kernel,
bandwidth ``⌊n^(1/3)⌋``: prediction errors, free-run errors above all, are serially correlated,
and a plain paired t-test would call small differences significant). The smaller structure is
"not worse" when ``DM ≤ DM_CRITICAL`` (1.645, one-sided 5%). The errors are the sweep's own
measure: free-run (or k-step for an integrating plant) for ``val_sim``/``est_sim``, one-step
for every other criterion.

Diebold, F. X. and Mariano, R. S. (1995), "Comparing predictive accuracy", J. Business & Economic
Statistics 13(3), 253–263.
"""

from __future__ import annotations

import math

import numpy as np

from .._base import _core
from .._base.records import record

__all__ = ["DM_CRITICAL", "Comparison", "diebold_mariano", "loss_difference_test", "comparison_from_sums"]

#: One-sided 5% critical value of the standard normal: DM above it means "significantly worse".
DM_CRITICAL = 1.645
#: From this many samples the lagged sums come from the Rust core in one pass over the samples
#: (a record of 2M samples has 126 lags: 126 passes of numpy, a second and more under load).
_ONE_PASS_SAMPLES = 1 << 17


@record
class Comparison:
    """Diebold–Mariano comparison of a smaller structure against the best one.

    Attributes
    ----------
    statistic : float
        DM statistic (positive: the smaller structure has the larger squared error).
    n : int
        Samples compared.
    worse : bool
        ``statistic > DM_CRITICAL``.
    """

    statistic: float
    n: int
    worse: bool


def diebold_mariano(error_small: np.ndarray, error_best: np.ndarray) -> Comparison:
    """Is the smaller structure's error significantly larger than the best's?

    Parameters
    ----------
    error_small, error_best : ndarray of shape (n,)
        Prediction errors on the same samples (NaN where missing).

    Returns
    -------
    Comparison
    """
    ok = np.isfinite(error_small) & np.isfinite(error_best)
    return loss_difference_test(error_small[ok] ** 2 - error_best[ok] ** 2)


def loss_difference_test(d: np.ndarray) -> Comparison:
    """:func:`diebold_mariano` from the squared-error differences ``d_t = e_small(t)² − e_best(t)²``
    on the samples where both errors exist: a caller comparing many structures against one forms
    them without a temporary per comparison.

    Parameters
    ----------
    d : ndarray of shape (n,)
        The differences; overwritten (centred in place).

    Returns
    -------
    Comparison
    """
    n = d.size
    if n < 2:
        return Comparison(math.nan, n, True)
    mean = d.mean()
    d -= mean
    lag = int(n ** (1 / 3))
    return _compared(float(mean), _long_run_variance(d, lag), n)


def comparison_from_sums(n: int, mean: float, sums: np.ndarray) -> Comparison:
    """:func:`loss_difference_test` from the sums a core kernel formed in one pass
    (``_core.loss_difference``): the differences' count and mean, and the lagged products of the
    centred ones at lags 0..⌊n^(1/3)⌋.

    Parameters
    ----------
    n : int
        Samples compared.
    mean : float
        Mean of the differences.
    sums : ndarray of shape (⌊n^(1/3)⌋ + 1,)
        ``Σ_t dc(t) dc(t − k)``.

    Returns
    -------
    Comparison
    """
    if n < 2:
        return Comparison(math.nan, n, True)
    return _compared(mean, _bartlett(np.asarray(sums, dtype=float), n), n)


def _compared(mean: float, lrv: float, n: int) -> Comparison:
    if not lrv > 0:
        stat = math.inf if mean > 0 else 0.0
    else:
        stat = float(mean / math.sqrt(lrv / n))
    return Comparison(stat, n, stat > DM_CRITICAL)


def _bartlett(sums: np.ndarray, n: int) -> float:
    """``S`` from the lagged products at lags 0..lag: their Bartlett-weighted sum over ``n``."""
    lag = sums.size - 1
    lags = np.arange(1, lag + 1)
    return float(sums[0] + 2.0 * np.dot(1.0 - lags / (lag + 1), sums[1:])) / n


def _long_run_variance(dc: np.ndarray, lag: int) -> float:
    """``S``: the Bartlett-weighted sum of the centred differences' autocovariances up to ``lag``."""
    n = dc.size
    if n >= _ONE_PASS_SAMPLES:  # Σ_t dc(t) dc(t − k), k = 0..lag
        return _bartlett(np.asarray(_core.lagged_products(dc, dc, 0, lag)), n)
    # einsum, not @: a BLAS call per lag leaves its threads spinning on shared cores.
    lrv = float(np.einsum("i,i->", dc, dc)) / n
    for k in range(1, lag + 1):
        lrv += 2 * (1 - k / (lag + 1)) * float(np.einsum("i,i->", dc[k:], dc[:-k])) / n
    return lrv
