"""Tail probabilities of the t, χ² and F distributions and the normal quantile, in plain Python.

They give :mod:`scipy.stats`'s answers (``t.sf``, ``chi2.sf``, ``f.sf``, ``norm.ppf``) to about
1e-12 relative, with its answers outside the support (1 below it, 0 at +inf, NaN for a NaN or a
degree of freedom that is not positive), without importing scipy: even ``scipy.special`` pulls in
scipy's array layer, a fifth of a second of a short diagnosis.

The t and F tails are regularised incomplete beta functions, the χ² tail a regularised upper
incomplete gamma function, each by its series or continued fraction (modified Lentz). The factor in
front, x^a (1-x)^b / B(a, b), is formed from Stirling's series with its large terms cancelled
algebraically (``log1p``), so large degrees of freedom lose no more digits than their arguments
carry. The normal quantile is Wichura's AS 241 (:class:`statistics.NormalDist`).
"""

from __future__ import annotations

import math

__all__ = ["t_sf", "chi2_sf", "f_sf", "standard_normal_quantile"]

_EPS = 1e-16
_TINY = 1e-300
_HALF_LOG_2PI = 0.5 * math.log(2.0 * math.pi)


def t_sf(x: float, df: float) -> float:
    """P(T > x) for Student's t with ``df`` degrees of freedom (``scipy.stats.t.sf``)."""
    if not df > 0 or math.isnan(x):
        return math.nan
    if math.isinf(x):
        return 0.0 if x > 0 else 1.0
    if x == 0:
        return 0.5
    # P(|T| > |x|) = I_{df/(df+x²)}(df/2, 1/2)
    x2 = x * x
    both = _beta_lower(0.5 * df, 0.5, df / (df + x2), x2 / (df + x2))
    return 0.5 * both if x > 0 else 1.0 - 0.5 * both


def chi2_sf(x: float, df: float) -> float:
    """P(X > x) for χ² with ``df`` degrees of freedom (``scipy.stats.chi2.sf``)."""
    if not df > 0 or math.isnan(x):
        return math.nan
    if x <= 0 or math.isinf(x):
        return 1.0 if x <= 0 else 0.0
    return _gamma_upper(0.5 * df, 0.5 * x)


def f_sf(x: float, dfn: float, dfd: float) -> float:
    """P(F > x) for F with ``dfn`` and ``dfd`` degrees of freedom (``scipy.stats.f.sf``)."""
    if not (dfn > 0 and dfd > 0) or math.isnan(x):
        return math.nan
    if x <= 0 or math.isinf(x):
        return 1.0 if x <= 0 else 0.0
    # P(F > x) = I_{dfd/(dfd + dfn x)}(dfd/2, dfn/2)
    s = dfd + dfn * x
    return _beta_lower(0.5 * dfd, 0.5 * dfn, dfd / s, dfn * x / s)


def standard_normal_quantile(p: float) -> float:
    """The standard normal's quantile at probability ``p`` (``scipy.stats.norm.ppf``)."""
    if not 0.0 <= p <= 1.0:  # NaN too
        return math.nan
    if p in (0.0, 1.0):
        return -math.inf if p == 0.0 else math.inf
    try:  # what NormalDist().inv_cdf calls, without importing statistics (random, decimal, fractions: ~4 ms)
        from _statistics import _normal_dist_inv_cdf  # type: ignore[import-not-found]
    except ImportError:  # an interpreter without CPython's accelerator
        from statistics import NormalDist

        return NormalDist().inv_cdf(p)
    return _normal_dist_inv_cdf(p, 0.0, 1.0)


def _stirling_rest(z: float) -> float:
    """log Γ(z) − ((z − ½) log z − z + ½ log 2π): small, so sums of it keep their digits."""
    if z < 10.0:
        return math.lgamma(z) - ((z - 0.5) * math.log(z) - z + _HALF_LOG_2PI)
    w = 1.0 / (z * z)
    return (1 / 12 - w * (1 / 360 - w * (1 / 1260 - w * (1 / 1680 - w * (1 / 1188 - w * 691 / 360360))))) / z


def _log_beta_front(a: float, b: float, x: float, y: float) -> float:
    """log(x^a y^b / B(a, b)) with y = 1 − x, without the cancellation of its large terms."""
    s = a + b
    d = x * b - y * a  # x·s − a, from both x and y: exact where either is small
    return (
        _log_ratio(a, x, s, d)
        + _log_ratio(b, y, s, -d)
        + 0.5 * math.log(a * b / s)
        - _HALF_LOG_2PI
        - _stirling_rest(a)
        - _stirling_rest(b)
        + _stirling_rest(s)
    )


def _log_ratio(a: float, x: float, s: float, d: float) -> float:
    """a · log(x s / a), given d = x s − a: by ``log1p`` near the mean (x s ≈ a), else directly."""
    if abs(d) < 0.5 * a:
        return a * math.log1p(d / a)
    return a * (math.log(x) + math.log(s / a))


def _beta_lower(a: float, b: float, x: float, y: float) -> float:
    """The regularised incomplete beta I_x(a, b), with y = 1 − x given separately (its digits)."""
    if x <= 0.0:
        return 0.0
    if y <= 0.0:
        return 1.0
    if x < (a + 1.0) / (a + b + 2.0):
        return math.exp(_log_beta_front(a, b, x, y)) * _beta_fraction(a, b, x) / a
    return 1.0 - math.exp(_log_beta_front(b, a, y, x)) * _beta_fraction(b, a, y) / b


def _beta_fraction(a: float, b: float, x: float) -> float:
    """The continued fraction of I_x(a, b) (modified Lentz); converges fast for x < (a+1)/(a+b+2)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * x / qap
    d = 1.0 / (d if abs(d) > _TINY else _TINY)
    h = d
    for m in range(1, 20_000 + int(10 * math.sqrt(max(a, b)))):
        m2 = 2 * m
        for num in (m * (b - m) * x / ((qam + m2) * (a + m2)), -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2))):
            d = 1.0 + num * d
            d = 1.0 / (d if abs(d) > _TINY else _TINY)
            c = 1.0 + num / c
            c = c if abs(c) > _TINY else _TINY
            h *= d * c
        if abs(d * c - 1.0) < _EPS:
            break
    return h


def _log_gamma_front(s: float, x: float) -> float:
    """log(x^s e^{−x} / Γ(s)), its large terms cancelled as in :func:`_log_beta_front`."""
    d = x - s
    return _log_ratio(s, x, 1.0, d) - d + 0.5 * math.log(s) - _HALF_LOG_2PI - _stirling_rest(s)


def _gamma_upper(s: float, x: float) -> float:
    """The regularised upper incomplete gamma Q(s, x): the series of P below s + 1, the continued
    fraction of Q above."""
    front = math.exp(_log_gamma_front(s, x))
    if x < s + 1.0:
        term = total = 1.0 / s
        ap = s
        while abs(term) > abs(total) * _EPS:
            ap += 1.0
            term *= x / ap
            total += term
        return 1.0 - total * front
    b = x + 1.0 - s
    c, d = 1.0 / _TINY, 1.0 / b
    h = d
    for i in range(1, 20_000 + int(10 * math.sqrt(s))):
        num = -i * (i - s)
        b += 2.0
        d = num * d + b
        d = 1.0 / (d if abs(d) > _TINY else _TINY)
        c = b + num / c
        c = c if abs(c) > _TINY else _TINY
        h *= d * c
        if abs(d * c - 1.0) < _EPS:
            break
    return h * front
