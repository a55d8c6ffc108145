"""The tail probabilities, computed without scipy, agree with scipy.stats (the reference they replace)
to 1e-12, inside and outside the support, for NaN and for degrees of freedom that are not positive.
Where scipy loses digits itself (the Cauchy distribution, t with one degree of freedom, near zero),
the closed forms are the reference."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from arxid._base.probabilities import chi2_sf, f_sf, standard_normal_quantile, t_sf

POINTS = [-math.inf, -50.0, -3.0, -1e-9, 0.0, 1e-12, 0.3, 1.0, 2.58, 7.5, 40.0, 400.0, 1e6, math.inf, math.nan]
DEGREES = [-1.0, 0.0, 0.5, 1.0, 2.0, 3.7, 10.0, 57.0, 1e4, math.nan]


def agree(ours: float, reference: float) -> None:
    if math.isnan(reference):
        assert math.isnan(ours)
    else:
        assert ours == pytest.approx(reference, rel=1e-12, abs=1e-300)


def cauchy_sf(x: float) -> float:
    """t with one degree of freedom: 1/2 − atan(x)/π, written as atan(1/x)/π above zero (no cancellation)."""
    return math.atan2(1.0, x) / math.pi if x > 0 else 0.5 - math.atan(x) / math.pi


def f11_sf(x: float) -> float:
    """F with one and one degrees of freedom: 1 − (2/π) atan(√x) = (2/π) atan(1/√x)."""
    return 2.0 * math.atan2(1.0, math.sqrt(x)) / math.pi


@pytest.mark.parametrize("df", DEGREES)
def test_t_and_chi2_tails_agree_with_scipy_stats(df):
    for x in POINTS:
        exact = df == 1.0 and math.isfinite(x)
        agree(t_sf(x, df), cauchy_sf(x) if exact else float(stats.t.sf(x, df)))
        agree(chi2_sf(x, df), float(stats.chi2.sf(x, df)))


@pytest.mark.parametrize("dfn", DEGREES)
def test_f_tail_agrees_with_scipy_stats(dfn):
    for dfd in DEGREES:
        for x in POINTS:
            exact = dfn == dfd == 1.0 and 0 < x < math.inf
            agree(f_sf(x, dfn, dfd), f11_sf(x) if exact else float(stats.f.sf(x, dfn, dfd)))


def test_random_arguments_agree_with_scipy_stats():
    rng = np.random.default_rng(0)
    x, d1, d2 = rng.exponential(3.0, 300), rng.integers(1, 500, 300), rng.integers(1, 5000, 300)
    for xi, a, b in zip(x, d1, d2):
        agree(t_sf(xi, a), float(stats.t.sf(xi, a)))
        agree(chi2_sf(xi * a, a), float(stats.chi2.sf(xi * a, a)))
        agree(f_sf(xi, a, b), float(stats.f.sf(xi, a, b)))
    assert t_sf(2.0, 10) == pytest.approx(0.036694017385370196, rel=1e-12)  # tables: P(T10 > 2)


def test_standard_normal_quantile_agrees_with_scipy_stats():
    for p in [-0.1, 0.0, 1e-300, 1e-9, 0.025, 0.5, 0.8, 0.975, 0.995, 1 - 1e-12, 1.0, 1.5, math.nan]:
        agree(standard_normal_quantile(p), float(stats.norm.ppf(p)))
    assert standard_normal_quantile(0.995) == pytest.approx(2.5758293035489004, rel=1e-12)


def test_large_degrees_of_freedom_agree_with_scipy_stats():
    """A long record's F and χ² tests: millions of degrees of freedom, near the mean and far in the
    tail (the factor in front of the series keeps its digits)."""
    for x, dfn, dfd in [(1.2, 3, 4e6), (1.0005, 3, 4e6), (50.0, 3, 4e6), (0.999, 2e6, 2e6), (3.0, 40, 2e5)]:
        assert f_sf(x, dfn, dfd) == pytest.approx(float(stats.f.sf(x, dfn, dfd)), rel=1e-10)
    for x, df in [(4.003e6, 4e6), (3.997e6, 4e6), (1e6, 1e6), (2e5, 1.9e5)]:
        assert chi2_sf(x, df) == pytest.approx(float(stats.chi2.sf(x, df)), rel=1e-12)


def test_no_scipy_import():
    """The point of the module: a diagnosis's p-values do not import scipy (a fifth of a second)."""
    import subprocess
    import sys

    code = "import sys; from arxid._base import probabilities as p; p.f_sf(2.0, 3, 50); p.chi2_sf(3.0, 2); "
    code += "p.t_sf(1.0, 5); p.standard_normal_quantile(0.9); print(any(m.startswith('scipy') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False"
