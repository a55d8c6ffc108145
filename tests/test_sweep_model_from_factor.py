"""A sweep's ranked model is solved from the sweep's estimation factor (no pass over a long record):
the same parameters, covariance, loss and rows as the refit on the sweep's rows, on complete data
and on data with missing samples, with one input and with two."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.models.arx_model import ArxModel


def _record(seed: int, two_inputs: bool, gaps: bool) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    n = 4000
    u = rng.standard_normal((n, 2 if two_inputs else 1))
    y = lfilter([0, 0.4, 0.2], [1, -1.3, 0.45], u[:, 0]) + 0.05 * rng.standard_normal(n)
    if two_inputs:
        y += lfilter([0, 0, 0.3], [1, -0.6], u[:, 1])
    if gaps:
        y[[500, 1700]] = np.nan
        u[2500, 0] = np.nan
    return arxid.IOData(y + 1.5, u, ts=0.01)


@pytest.mark.parametrize("two_inputs", [False, True])
@pytest.mark.parametrize("gaps", [False, True])
def test_ranked_models_from_the_factor_equal_the_refit(two_inputs, gaps):
    data = _record(3, two_inputs, gaps)
    est, val = data.split(0.6)
    res = arxid.sweep(est, validation=val)
    assert res.estimation_factor is not None
    for i in range(3):
        m = res.model(i)
        ref = ArxModel(na=m.na_, nb=m.nb_, nk=m.nk_).fit(est, first_lag=res.first_lag, rows_like=res.row_orders)
        np.testing.assert_allclose(m.parameters_, ref.parameters_, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(m.covariance_, ref.covariance_, rtol=1e-8, atol=1e-15)
        assert (m.n_rows_, m.n_skipped_, m.first_lag_) == (ref.n_rows_, ref.n_skipped_, ref.first_lag_)
        assert m.rss_ == pytest.approx(ref.rss_, rel=1e-10)
        assert m.regressor_names_ == ref.regressor_names_


def test_a_model_outside_the_envelope_or_with_effects_is_refused():
    data = _record(4, False, False)
    res = arxid.sweep(data)
    too_big = ArxModel(na=res.row_orders[0] + 2, nb=1, nk=0)
    with pytest.raises(arxid.ArxidError):
        too_big.fit_from_factor(data, res.estimation_factor, res.n_est, res.row_orders, res.first_lag)
    with pytest.raises(arxid.ArxidError, match="effect"):
        ArxModel(na=1, nb=1, nk=1, effects=("const",)).fit_from_factor(
            data, res.estimation_factor, res.n_est, res.row_orders, res.first_lag
        )
