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
    return float(np.sign(v))


def simplex_minimum(
    cost: Callable[[np.ndarray], float],
    simplex: np.ndarray,
    maxfev: int,
    xatol: float = 1e-4,
    fatol: float = 1e-4,
) -> tuple[np.ndarray, float]:
    """The minimum of ``cost`` by the Nelder–Mead simplex from ``simplex``, at most ``maxfev``
    evaluations.

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
    sim = np.asarray(simplex, dtype=float).copy()
    n = sim.shape[1]
    calls = [0]

    def f(x: np.ndarray) -> float:
        if calls[0] >= maxfev:
            raise _Exhausted
        calls[0] += 1
        return float(cost(np.copy(x)))

    fsim = np.full(n + 1, np.inf)
    try:
        for k in range(n + 1):
            fsim[k] = f(sim[k])
    except _Exhausted:
        pass
    ind = np.argsort(fsim)
    sim, fsim = np.take(sim, ind, 0), np.take(fsim, ind, 0)
    while calls[0] < maxfev:
        try:
            if np.max(np.abs(sim[1:] - sim[0])) <= xatol and np.max(np.abs(fsim[0] - fsim[1:])) <= fatol:
                break
            _step(f, sim, fsim, n)
        except _Exhausted:
            pass
        ind = np.argsort(fsim)
        sim, fsim = np.take(sim, ind, 0), np.take(fsim, ind, 0)
    return sim[0], float(np.min(fsim))


class _Exhausted(Exception):
    """The evaluations are used up."""


def _step(f: Callable[[np.ndarray], float], sim: np.ndarray, fsim: np.ndarray, n: int) -> None:
    """One Nelder–Mead step in place: reflect, expand, contract or shrink (coefficients 1, 2, ½, ½)."""
    xbar = np.add.reduce(sim[:-1], 0) / n
    xr = 2.0 * xbar - sim[-1]
    fxr = f(xr)
    if fxr < fsim[0]:
        xe = 3.0 * xbar - 2.0 * sim[-1]
        fxe = f(xe)
        sim[-1], fsim[-1] = (xe, fxe) if fxe < fxr else (xr, fxr)
        return
    if fxr < fsim[-2]:
        sim[-1], fsim[-1] = xr, fxr
        return
    if fxr < fsim[-1]:  # outside contraction
        xc = 1.5 * xbar - 0.5 * sim[-1]
        fxc = f(xc)
        if fxc <= fxr:
            sim[-1], fsim[-1] = xc, fxc
            return
    else:  # inside contraction
        xcc = 0.5 * xbar + 0.5 * sim[-1]
        fxcc = f(xcc)
        if fxcc < fsim[-1]:
            sim[-1], fsim[-1] = xcc, fxcc
            return
    for j in range(1, n + 1):  # shrink towards the best
        sim[j] = sim[0] + 0.5 * (sim[j] - sim[0])
        fsim[j] = f(sim[j])
