"""The digital filter that stands in for scipy.signal.lfilter on the analysis's path agrees with it
(the reference) to 1e-12: IIR and FIR, a0 != 1, numerators longer and shorter than denominators,
unstable filters, strided signals; and it refuses a0 = 0 with a typed error."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter as scipy_lfilter

from arxid._base.digital_filter import lfilter
from arxid.exceptions import ArxidError


def agree(ours: np.ndarray, reference: np.ndarray) -> None:
    assert ours.shape == reference.shape
    np.testing.assert_allclose(ours, reference, rtol=1e-12, atol=1e-300)


@pytest.mark.parametrize("seed", range(6))
def test_random_filters_agree_with_scipy(seed):
    rng = np.random.default_rng(seed)
    x = rng.standard_normal(3000)
    for nb, na in [(1, 2), (3, 2), (2, 5), (6, 3), (4, 1), (1, 1)]:
        roots = rng.uniform(0.2, 0.95, na - 1) * rng.choice([-1, 1], na - 1)
        a = np.poly(roots) * rng.uniform(0.5, 2.0)  # a0 != 1
        b = rng.standard_normal(nb)
        agree(lfilter(b, a, x), scipy_lfilter(b, a, x))


def test_bitwise_equal_on_an_arx_step_response():
    """The sanity checks' step response of a second-order model: scipy's numbers to the last bit."""
    a, b = [1.0, -1.5, 0.7], [0.0, 0.0, 0.5, 0.25]
    x = np.full(5000, 0.3)
    assert np.array_equal(lfilter(b, a, x), scipy_lfilter(b, a, x))


def test_unstable_and_integrating_filters_agree_until_they_overflow():
    x = np.random.default_rng(1).standard_normal(2000)
    for a in ([1.0, -1.0], [1.0, -2.0, 1.0], [1.0, -1.02]):
        with np.errstate(all="ignore"):
            ours, ref = lfilter([0.0, 0.4], a, x), scipy_lfilter([0.0, 0.4], a, x)
        finite = np.isfinite(ref)
        assert np.array_equal(np.isfinite(ours), finite)
        agree(ours[finite], ref[finite])
    big = np.full(40000, 1.0)
    with np.errstate(all="ignore"):
        ours, ref = lfilter([1.0], [1.0, -1.1], big), scipy_lfilter([1.0], [1.0, -1.1], big)
    assert np.array_equal(ours, ref)  # inf where scipy overflows, too


def test_strided_signal_and_nan_propagate_as_in_scipy():
    u = np.random.default_rng(2).standard_normal((500, 3))
    u[100, 1] = np.nan
    for j in range(3):
        agree(lfilter([0.5, 0.25], [1.0, -0.8], u[:, j]), scipy_lfilter([0.5, 0.25], [1.0, -0.8], u[:, j]))
    agree(lfilter([1.0, -0.3, 0.1], [1.0], u[:, 1]), scipy_lfilter([1.0, -0.3, 0.1], [1.0], u[:, 1]))


def test_a_zero_leading_coefficient_is_refused():
    with pytest.raises(ArxidError):
        lfilter([1.0], [0.0, 1.0], np.ones(3))
