"""The base fit of the added-variable tests: Gram matrix, Cholesky, and a residual refined once,
each pass over the rows in the Rust core; the same fit as numpy's least squares."""

import numpy as np
import pytest

from arxid._base import _core
from arxid.diagnosis.added_variable import AddedVariableTest
from arxid.exceptions import DataError


@pytest.mark.parametrize(("seed", "n", "p"), [(0, 50, 1), (1, 20_011, 4), (2, 40_000, 21)])
def test_the_base_fit_is_numpys_least_squares(seed, n, p):
    rng = np.random.default_rng(seed)
    phi = rng.standard_normal((n, p)) * np.logspace(0, 3, p)  # columns of different sizes
    y = phi @ rng.standard_normal(p) + rng.standard_normal(n)
    theta, *_ = np.linalg.lstsq(phi, y, rcond=None)
    e = y - phi @ theta
    test = AddedVariableTest(phi, y)
    assert test.gram is not None  # the well-conditioned path
    np.testing.assert_allclose(test.gram[:p, :p], phi.T @ phi, rtol=1e-13)
    np.testing.assert_allclose(test.e, e, rtol=1e-9, atol=1e-12 * np.abs(y).max())
    assert test.rss0 == pytest.approx(float(e @ e), rel=1e-12)
    assert test._theta is not None
    np.testing.assert_allclose(test._theta, theta, rtol=1e-9)


def test_collinear_regressors_take_the_qr_path():
    rng = np.random.default_rng(4)
    phi = rng.standard_normal((5000, 3))
    phi = np.column_stack([phi, phi[:, 0] - phi[:, 1]])
    y = phi[:, :3] @ [1.0, 2.0, -1.0] + 0.1 * rng.standard_normal(5000)
    test = AddedVariableTest(phi, y)
    assert test.gram is None
    theta, *_ = np.linalg.lstsq(phi, y, rcond=None)
    assert test.rss0 == pytest.approx(float(np.sum((y - phi @ theta) ** 2)), rel=1e-10)


def test_the_residual_passes_are_numpys_products():
    rng = np.random.default_rng(5)
    a, y = rng.standard_normal((30_001, 5)), rng.standard_normal(30_001)
    theta, delta = rng.standard_normal(5), 1e-3 * rng.standard_normal(5)
    e, products = _core.fit_residual(a, y, theta)
    np.testing.assert_allclose(e, y - a @ theta, rtol=0, atol=1e-13)
    np.testing.assert_allclose(products, a.T @ e, rtol=1e-11)
    before = e.copy()
    rss = _core.refine_fit_residual(a, e, delta)
    np.testing.assert_allclose(e, before - a @ delta, rtol=0, atol=1e-13)
    assert rss == pytest.approx(float(e @ e), rel=1e-12)
    with pytest.raises(DataError, match="coefficients of the fit"):
        _core.fit_residual(a, y, theta[:4])
    with pytest.raises(DataError, match="regressor values"):
        _core.refine_fit_residual(a[:-1], e, delta)
