"""Brent's bounded search and the Nelder–Mead simplex take scipy.optimize's steps: the same point
and cost, to the bit, on smooth, flat and stepped functions and within an evaluation budget."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from arxid._base.local_search import bounded_minimum, simplex_minimum

SCALAR = [
    (lambda x: (x - 0.3) ** 2 + 1.0, (-2.0, 2.0), 1e-5),
    (lambda x: np.cos(3 * x) + 0.1 * x, (0.0, 4.0), 1e-4),
    (lambda x: float(np.floor(4 * abs(x - 1.1))), (0.0, 3.0), 1e-3),  # steps: many ties
    (lambda x: abs(x - 2.0) ** 0.5, (2.0, 5.0), 1e-6),  # at the bound
]


@pytest.mark.parametrize(("f", "bounds", "xatol"), SCALAR)
def test_bounded_minimum_is_scipys(f, bounds, xatol):
    res = optimize.minimize_scalar(f, bounds=bounds, method="bounded", options={"xatol": xatol})
    x, fun = bounded_minimum(f, bounds, xatol=xatol)
    assert x == res.x and fun == res.fun


def rosenbrock(p):
    return (1 - p[0]) ** 2 + 100 * (p[1] - p[0] ** 2) ** 2


@pytest.mark.parametrize("maxfev", [5, 17, 60, 400])
@pytest.mark.parametrize(
    ("f", "start"),
    [
        (rosenbrock, [-1.2, 1.0]),
        (lambda p: float(np.sum(np.abs(p - [0.5, -0.25, 2.0]))), [0.0, 0.0, 0.0]),
        (lambda p: float(np.round(10 * (p[0] ** 2 + p[1] ** 2))), [1.0, 1.0]),  # plateaus: shrinks
        (lambda p: float(np.floor(5 * abs(p[0] - 0.7))), [0.0]),  # one parameter, tied costs
        (lambda p: float(np.floor(2 * abs(p[0])) + np.floor(2 * abs(p[1]))), [0.9, -0.8]),  # ties at -0.0 and 0.0
    ],
)
def test_simplex_minimum_is_scipys(f, start, maxfev):
    start = np.array(start, dtype=float)
    simplex = np.vstack([start] + [start + 0.1 * e for e in np.eye(start.size)])
    res = optimize.minimize(f, start, method="Nelder-Mead", options={"initial_simplex": simplex, "maxfev": maxfev})
    x, fun = simplex_minimum(f, simplex, maxfev=maxfev)
    assert np.array_equal(x, res.x) and fun == res.fun
