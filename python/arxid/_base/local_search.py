"""Local searches of a few parameters without derivatives: Brent's bounded minimisation of one
parameter and the Nelder–Mead simplex, step for step as :func:`scipy.optimize.minimize_scalar`
(``method="bounded"``) and :func:`scipy.optimize.minimize` (``method="Nelder-Mead"``) take them.

A diagnosis refines the parameter of a shape (a dead zone's width, a saturation's levels) with
them; importing :mod:`scipy.optimize` would take half a second of a short diagnosis (it imports
scipy's linear algebra, sparse matrices and special functions). The same steps give the same
points, so the answers are scipy's.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

__all__ = ["bounded_minimum", "simplex_minimum"]

_SQRT_EPS = math.sqrt(2.2e-16)
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))


def bounded_minimum(
    cost: Callable[[float], float], bounds: tuple[float, float], xatol: float = 1e-5, maxiter: int = 500
) -> tuple[float, float]:
    """The minimum of ``cost`` on ``bounds`` by Brent's method (golden sections and parabolas).

    Parameters
    ----------
    cost : callable
        ``cost(x) -> float``.
    bounds : (float, float)
        Finite, lower first.
    xatol : float
        Absolute tolerance on x.
    maxiter : int
        Evaluations at most.

    Returns
    -------
    (float, float)
        The point and its cost.
    """
    a, b = float(bounds[0]), float(bounds[1])
    fulc = a + _GOLDEN * (b - a)
    nfc, xf = fulc, fulc
    rat = e = 0.0
    fx = cost(xf)
    num = 1
    ffulc = fnfc = fx
    xm = 0.5 * (a + b)
    tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
    tol2 = 2.0 * tol1
    while abs(xf - xm) > tol2 - 0.5 * (b - a):
        golden = True
        if abs(e) > tol1:  # a parabola through the three best points
            golden = False
            r = (xf - nfc) * (fx - ffulc)
            q = (xf - fulc) * (fx - fnfc)
            p = (xf - fulc) * q - (xf - nfc) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r, e = e, rat
            if abs(p) < abs(0.5 * q * r) and q * (a - xf) < p < q * (b - xf):
                rat = (p + 0.0) / q
                x = xf + rat
                if (x - a) < tol2 or (b - x) < tol2:
                    rat = tol1 * (_sign(xm - xf) + (xm - xf == 0))
            else:
                golden = True
        if golden:
            e = a - xf if xf >= xm else b - xf
            rat = _GOLDEN * e
        x = xf + (_sign(rat) + (rat == 0)) * max(abs(rat), tol1)
        fu = cost(x)
        num += 1
        if fu <= fx:
            if x >= xf:
                a = xf
            else:
                b = xf
            fulc, ffulc = nfc, fnfc
            nfc, fnfc = xf, fx
            xf, fx = x, fu
        else:
            if x < xf:
                a = x
            else:
                b = x
            if fu <= fnfc or nfc == xf:
                fulc, ffulc = nfc, fnfc
                nfc, fnfc = x, fu
            elif fu <= ffulc or fulc == xf or fulc == nfc:
                fulc, ffulc = x, fu
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(xf) + xatol / 3.0
        tol2 = 2.0 * tol1
        if num >= maxiter:
            break
    return xf, fx


def _sign(v: float) -> float:
    """``float(np.sign(v))``: -1, 0 or 1, NaN for NaN."""
    return 1.0 if v > 0 else -1.0 if v < 0 else 0.0 if v == 0 else math.nan


def simplex_minimum(
    cost: Callable[[np.ndarray], float],
    simplex: np.ndarray,
    maxfev: int,
    xatol: float = 1e-4,
    fatol: float = 1e-4,
) -> tuple[np.ndarray, float]:
    """The minimum of ``cost`` by the Nelder–Mead simplex from ``simplex``, at most ``maxfev``
    evaluations.

    The vertices are lists of Python floats (a few parameters: numpy's calls on them cost more
    than their arithmetic), each step the same operations in the same order as scipy's arrays.

    Parameters
    ----------
    cost : callable
        ``cost(x) -> float`` for x of shape (n,).
    simplex : array_like of shape (n + 1, n)
        The starting simplex.
    maxfev : int
    xatol, fatol : float
        It stops when every vertex lies within ``xatol`` of the best and every cost within ``fatol``.

    Returns
    -------
    (ndarray of shape (n,), float)
    """
    sim = np.asarray(simplex, dtype=float).tolist()
    n = len(sim[0])
    calls = [0]

    def f(x: list[float]) -> float:
        if calls[0] >= maxfev:
            raise _Exhausted
        calls[0] += 1
        return float(cost(np.array(x)))

    fsim = [math.inf] * (n + 1)
    try:
        for k in range(n + 1):
            fsim[k] = f(sim[k])
    except _Exhausted:
        pass
    sim, fsim = _sorted(sim, fsim)
    while calls[0] < maxfev:
        try:
            if _within(sim, fsim, xatol, fatol):
                break
            _step(f, sim, fsim, n)
        except _Exhausted:
            pass
        sim, fsim = _sorted(sim, fsim)
    return np.array(sim[0]), float(np.min(fsim))


class _Exhausted(Exception):
    """The evaluations are used up."""


def _sorted(sim: list[list[float]], fsim: list[float]) -> tuple[list[list[float]], list[float]]:
    """The vertices by cost, by numpy's argsort (its order of ties, which is not always theirs)."""
    order = np.argsort(fsim).tolist()
    return [sim[i] for i in order], [fsim[i] for i in order]


def _within(sim: list[list[float]], fsim: list[float], xatol: float, fatol: float) -> bool:
    """Every vertex within ``xatol`` of the best and every cost within ``fatol`` (a NaN never is)."""
    best = sim[0]
    near = all(abs(v[i] - best[i]) <= xatol for v in sim[1:] for i in range(len(best)))
    return near and all(abs(fsim[0] - c) <= fatol for c in fsim[1:])


def _step(f: Callable[[list[float]], float], sim: list[list[float]], fsim: list[float], n: int) -> None:
    """One Nelder–Mead step in place: reflect, expand, contract or shrink (coefficients 1, 2, ½, ½)."""
    xbar = list(sim[0])
    for v in sim[1:-1]:  # the centroid of all but the worst, summed vertex after vertex
        xbar = [a + b for a, b in zip(xbar, v)]
    xbar = [a / n for a in xbar]
    worst = sim[-1]
    xr = [2.0 * a - w for a, w in zip(xbar, worst)]
    fxr = f(xr)
    if fxr < fsim[0]:
        xe = [3.0 * a - 2.0 * w for a, w in zip(xbar, worst)]
        fxe = f(xe)
        sim[-1], fsim[-1] = (xe, fxe) if fxe < fxr else (xr, fxr)
        return
    if fxr < fsim[-2]:
        sim[-1], fsim[-1] = xr, fxr
        return
    if fxr < fsim[-1]:  # outside contraction
        xc = [1.5 * a - 0.5 * w for a, w in zip(xbar, worst)]
        fxc = f(xc)
        if fxc <= fxr:
            sim[-1], fsim[-1] = xc, fxc
            return
    else:  # inside contraction
        xcc = [0.5 * a + 0.5 * w for a, w in zip(xbar, worst)]
        fxcc = f(xcc)
        if fxcc < fsim[-1]:
            sim[-1], fsim[-1] = xcc, fxcc
            return
    for j in range(1, n + 1):  # shrink towards the best
        sim[j] = [b + 0.5 * (v - b) for b, v in zip(sim[0], sim[j])]
        fsim[j] = f(sim[j])
