"""tfest with several inputs (common or independent denominators), several experiments and NaN
gaps: known answers simulated with an exact zero-order hold."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.exceptions import OrderError
from test_tfest import rel_error, simulate

TS = 0.05
DEN = [1.0, 0.8, 4.0]


def two_inputs(seed, n=4000, noise=0.1, independent=False):
    rng = np.random.default_rng(seed)
    u1 = np.sign(rng.standard_normal(n // 10)).repeat(10)
    u2 = np.sign(rng.standard_normal(n // 7 + 1)).repeat(7)[:n]
    second = simulate([2.0], [1.0, 2.0], TS, 0.13, u2) if independent else simulate([1.0, 2.0], DEN, TS, 0.13, u2)
    y0 = simulate([4.0], DEN, TS, 0.0, u1) + second
    y = y0 + noise * np.std(y0) * rng.standard_normal(n)
    return arxid.IOData(y, np.column_stack([u1, u2]), ts=TS)


@pytest.mark.parametrize("seed", [0, 1])
def test_two_inputs_with_a_common_denominator(seed):
    """4/(s² + 0.8 s + 4) from u1 and (s + 2) e^{-0.13 s}/(s² + 0.8 s + 4) from u2: poles within 1 %,
    numerators within 3 %."""
    m = arxid.tfest(two_inputs(seed), 2, [0, 1], delay=[0.0, 0.13])
    assert rel_error(m.poles(0), np.roots(DEN)) < 0.01
    np.testing.assert_allclose(m.nums_[0], [4.0], rtol=0.03)
    np.testing.assert_allclose(m.nums_[1], [1.0, 2.0], rtol=0.03)
    assert m.delays_ == (0.0, 0.13)
    assert len(m.to_control()) == 2
    assert list(m.parameter_dict()) == ["a1", "a2", "b0(u1)", "b0(u2)", "b1(u2)"]


@pytest.mark.parametrize("seed", [0, 1])
def test_two_inputs_with_independent_denominators(seed):
    """4/(s² + 0.8 s + 4) and 2 e^{-0.13 s}/(s + 2): each input's poles within 2 %."""
    data = two_inputs(seed, independent=True)
    m = arxid.tfest(data, [2, 1], [0, 0], delay=[0.0, 0.13], denominator="independent")
    assert rel_error(m.poles(0), np.roots(DEN)) < 0.02
    assert rel_error(m.poles(1), [-2.0]) < 0.02
    assert m.dc_gain() == pytest.approx([1.0, 1.0], rel=0.02)
    with pytest.raises(OrderError, match="common denominator"):
        arxid.tfest(data, [2, 1], [0, 0])


def test_experiments_restart_the_filters_from_rest():
    """Two experiments, each simulated from rest, noise free: recovered to 1e-6 only if the
    filters restart in each (the second would otherwise inherit the first's state)."""
    rng = np.random.default_rng(3)
    parts = []
    for n in (700, 900):
        u = np.sign(rng.standard_normal(n // 10 + 1)).repeat(10)[:n]
        parts.append(arxid.IOData(simulate([4.0], DEN, TS, 0.07, u), u, ts=TS))
    data = arxid.IOData.merge(parts)
    assert data.n_experiments == 2
    m = arxid.tfest(data, 2, 0, delay=0.07)
    np.testing.assert_allclose(m.den_, DEN, rtol=1e-6)
    np.testing.assert_allclose(m.num_, [4.0], rtol=1e-6)
    assert arxid.compare(m, data).fit_percent[0] == pytest.approx(100.0, abs=1e-4)


@pytest.mark.parametrize("seed", [0, 1])
def test_nan_gaps(seed):
    """10 % noise and three gaps of 25 missing output samples: poles within 2 % (the filters restart
    after each gap); the free run needs only the inputs, so it covers the gaps and equals the
    model's simulation of the whole input (after the first run's initial lags)."""
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(400)).repeat(10)
    y0 = simulate([4.0], DEN, TS, 0.0, u)
    y = y0 + 0.1 * np.std(y0) * rng.standard_normal(len(u))
    for start in (800, 1900, 3100):
        y[start : start + 25] = np.nan
    gappy = arxid.IOData(y, u, ts=TS)
    m = arxid.tfest(gappy, 2, 0)
    assert rel_error(m.poles(), np.roots(DEN)) < 0.02
    pred = m.predict(gappy, horizon=None)
    lag = m.first_lag_  # samples that only feed the filters' lags, as for any OE model
    np.testing.assert_allclose(pred[lag:], m.simulate(u)[lag:], atol=1e-9)
    assert np.isfinite(arxid.compare(m, gappy).fit_percent[0])


def two_dead_times(seed, n=3000, noise=0.1):
    """u1 → 2 e^{-0.12 s}/(s + 1) (2.4 samples), u2 → 3 e^{-0.335 s}/(s + 2) (6.7 samples)."""
    rng = np.random.default_rng(seed)
    u1 = np.sign(rng.standard_normal(n // 10)).repeat(10)
    u2 = np.sign(rng.standard_normal(n // 7 + 1)).repeat(7)[:n]
    y0 = simulate([2.0], [1.0, 1.0], TS, 0.12, u1) + simulate([3.0], [1.0, 2.0], TS, 0.335, u2)
    return arxid.IOData(y0 + noise * np.std(y0) * rng.standard_normal(n), np.column_stack([u1, u2]), ts=TS)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_one_dead_time_searched_per_input(seed):
    """Two inputs with different fractional dead times (2.4 and 6.7 samples), 10 % noise: each
    found within 0.1 sample (0.005 s), the poles within 2 %; a list mixing a given dead time and
    "estimate" searches only the second."""
    data = two_dead_times(seed)
    m = arxid.tfest(data, [1, 1], [0, 0], delay="estimate", denominator="independent")
    assert m.delays_[0] == pytest.approx(0.12, abs=0.005)
    assert m.delays_[1] == pytest.approx(0.335, abs=0.005)
    assert rel_error(m.poles(0), [-1.0]) < 0.02
    assert rel_error(m.poles(1), [-2.0]) < 0.02
    mixed = arxid.tfest(data, [1, 1], [0, 0], delay=[0.12, "estimate"], denominator="independent")
    assert mixed.delays_[0] == 0.12
    assert mixed.delays_[1] == pytest.approx(0.335, abs=0.005)
