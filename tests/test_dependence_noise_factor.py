"""The dependence test's noise model reads its AR fits from one factor of the lagged remainder
(``ar_factor``: the Cholesky factor of its lagged products for a near-white remainder, the QR of its
rows in the Rust core for an ill-conditioned, drifting one): R'R = M'M of the lagged matrix M, on
rows with gaps."""

from __future__ import annotations

import numpy as np
import pytest

from arxid.diagnosis.nonlinearity import MAX_NOISE_ORDER, _lagged_factor, _previous_rows


@pytest.mark.parametrize("drifting", [False, True])
def test_noise_factor_of_the_lagged_remainder(drifting):
    rng = np.random.default_rng(8)
    r = rng.standard_normal(40000)
    r = np.cumsum(r) if drifting else r
    rows = np.delete(np.arange(40000), [5000, 5001, 20000])  # gaps: rows whose lags are missing go
    keep = _previous_rows(rows, MAX_NOISE_ORDER)
    assert len(keep) == len(rows) - 3 * MAX_NOISE_ORDER  # the first rows and those after each gap
    m = np.column_stack([r[keep - j] for j in range(1, MAX_NOISE_ORDER + 1)] + [r[keep]])
    f = _lagged_factor(r, rows, MAX_NOISE_ORDER)
    np.testing.assert_allclose(f.T @ f, m.T @ m, rtol=1e-10, atol=1e-10 * np.abs(m.T @ m).max())
