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
from dataclasses import dataclass

import numpy as np

__all__ = ["DM_CRITICAL", "Comparison", "diebold_mariano"]

#: One-sided 5% critical value of the standard normal: DM above it means "significantly worse".
DM_CRITICAL = 1.645


@dataclass(frozen=True)
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
    d = error_small[ok] ** 2 - error_best[ok] ** 2
    n = d.size
    if n < 2:
        return Comparison(math.nan, n, True)
    dc = d - d.mean()
    lag = int(n ** (1 / 3))
    # einsum, not @: a BLAS call per lag leaves its threads spinning on shared cores.
    lrv = float(np.einsum("i,i->", dc, dc)) / n
    for k in range(1, lag + 1):
        lrv += 2 * (1 - k / (lag + 1)) * float(np.einsum("i,i->", dc[k:], dc[:-k])) / n
    if not lrv > 0:
        stat = math.inf if d.mean() > 0 else 0.0
    else:
        stat = float(d.mean() / math.sqrt(lrv / n))
    return Comparison(stat, n, stat > DM_CRITICAL)
