"""Tail probabilities of the t, χ² and F distributions and the normal quantile, from
:mod:`scipy.special`.

These are the functions :mod:`scipy.stats` evaluates (``t.sf`` is ``stdtr(df, -x)``, ``chi2.sf`` is
``chdtrc``, ``f.sf`` is ``fdtrc``, ``norm.ppf`` is ``ndtri``), with its answers outside the support
(1 below it, 0 at +inf, NaN for a NaN or a degree of freedom that is not positive). Importing
scipy.stats takes a large share of a short analysis (about half a second); scipy.special a tenth of it.
"""

from __future__ import annotations

import math

__all__ = ["t_sf", "chi2_sf", "f_sf", "standard_normal_quantile"]


def t_sf(x: float, df: float) -> float:
    """P(T > x) for Student's t with ``df`` degrees of freedom (``scipy.stats.t.sf``)."""
    from scipy.special import stdtr

    if not df > 0 or math.isnan(x):
        return math.nan
    if math.isinf(x):
        return 0.0 if x > 0 else 1.0
    return float(stdtr(df, -x))


def chi2_sf(x: float, df: float) -> float:
    """P(X > x) for χ² with ``df`` degrees of freedom (``scipy.stats.chi2.sf``)."""
    from scipy.special import chdtrc

    if not df > 0 or math.isnan(x):
        return math.nan
    if x <= 0 or math.isinf(x):
        return 1.0 if x <= 0 else 0.0
    return float(chdtrc(df, x))


def f_sf(x: float, dfn: float, dfd: float) -> float:
    """P(F > x) for F with ``dfn`` and ``dfd`` degrees of freedom (``scipy.stats.f.sf``)."""
    from scipy.special import fdtrc

    if not (dfn > 0 and dfd > 0) or math.isnan(x):
        return math.nan
    if x <= 0 or math.isinf(x):
        return 1.0 if x <= 0 else 0.0
    return float(fdtrc(dfn, dfd, x))


def standard_normal_quantile(p: float) -> float:
    """The standard normal's quantile at probability ``p`` (``scipy.stats.norm.ppf``)."""
    from scipy.special import ndtri

    if not 0.0 <= p <= 1.0:  # NaN too
        return math.nan
    return float(ndtri(p))
