"""The dependence test on consecutive rows filters each signal's nonlinear functions once, as series,
and reads every lag's block as a slice of them; it must give the numbers of filtering each lag's
block on the rows, operation for operation (a coloured remainder, so the noise filter is not the
identity; raw and de-meaned data)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
import arxid.diagnosis.nonlinearity as nl


def _plant(seed: int, offset: float) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    n = 6000
    u = rng.uniform(-1, 1, n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.8 * y[t - 1] + np.tanh(2 * u[t - 1]) + 0.3 * u[t - 1]
    noise = lfilter([1], [1, -1.5, 0.7], 0.1 * rng.standard_normal(n))  # coloured: an AR noise model
    return arxid.IOData(y + noise + offset, u + offset / 4, ts=0.01)


@pytest.mark.parametrize(("seed", "offset"), [(0, 0.0), (1, 3.0), (2, 0.0)])
def test_by_signal_equals_by_lag(seed, offset, monkeypatch):
    data = _plant(seed, offset)
    model = arxid.arx(data, 2, 2, 1)
    orders, p_values = [], []
    noise_model, holm = nl._noise_model, nl.holm
    monkeypatch.setattr(nl, "_noise_model", lambda *a: orders.append((a := noise_model(*a)).size) or a)
    monkeypatch.setattr(nl, "holm", lambda p: p_values.append(np.array(p)) or holm(p))
    by_signal = nl.nonlinear_dependence(model, data)
    monkeypatch.setattr(nl, "_tests_by_signal", nl._tests_by_lag)
    by_lag = nl.nonlinear_dependence(model, data)
    assert orders[0] > 0  # the filter is not the identity
    assert by_signal == by_lag and by_signal[0].signal == "u1"  # the tanh of the input, strongest
    np.testing.assert_array_equal(p_values[0], p_values[1])
