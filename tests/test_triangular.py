"""Triangular and Cholesky solves by numpy agree with scipy.linalg's to rounding, on matrices with a
condition number of about 1e6, for one right-hand side and several; and the fast FFT length is
scipy's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.fft import next_fast_len
from scipy.linalg import cho_solve, solve_triangular

from arxid._base.triangular import cholesky_solve, solve_upper, solve_upper_transposed
from arxid.diagnosis.disturbance import fast_length


@pytest.mark.parametrize("shape", [(7,), (7, 3)])
def test_solves_agree_with_scipy(shape):
    rng = np.random.default_rng(4)
    a = rng.standard_normal((50, 7)) * np.logspace(0, 3, 7)
    r = np.linalg.qr(a, mode="r")
    r[np.tril_indices(7, -1)] = rng.standard_normal(21)  # below the diagonal: never read
    b = rng.standard_normal(shape)
    upper = np.triu(r)
    np.testing.assert_allclose(solve_upper(r, b), solve_triangular(upper, b), rtol=1e-10)
    np.testing.assert_allclose(solve_upper_transposed(r, b), solve_triangular(upper, b, trans="T"), rtol=1e-10)
    np.testing.assert_allclose(cholesky_solve(r, b), cho_solve((upper, False), b), rtol=1e-9)
    lower = upper.T
    np.testing.assert_allclose(cholesky_solve(lower, b, lower=True), cho_solve((lower, True), b), rtol=1e-9)
    # and the solve is a solve: R x = b
    np.testing.assert_allclose(upper @ solve_upper(r, b), b, atol=1e-12)


def test_fast_length_is_scipys():
    sizes = list(range(1, 5000)) + [2**20 + 1, 3 * 5**7 + 2, 10**9 + 7]
    assert [fast_length(n) for n in sizes] == [next_fast_len(n, real=True) for n in sizes]
