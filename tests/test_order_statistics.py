"""The order statistics of :mod:`arxid._base.order_statistics` are numpy's to the bit (they stand in
for ``np.unique``, ``np.quantile``, ``np.percentile`` and ``np.median`` on the diagnosis's path,
which import ``numpy.ma``): random samples, heavy ties, both signed zeros, NaNs, one sample."""

from __future__ import annotations

import numpy as np
import pytest

from arxid._base.order_statistics import distinct, median, quantiles, sorted_quantiles


def _samples(seed: int) -> list[np.ndarray]:
    """Samples of every kind the statistics meet, sizes 1 to 400."""
    rng = np.random.default_rng(seed)
    out = []
    for n in (1, 2, 3, 4, 7, 20, 101, 400):
        out.append(rng.standard_normal(n))
        out.append(np.round(rng.standard_normal(n), 1))  # ties
        signed_zeros = rng.choice([-0.0, 0.0, 1.0, -2.5], n)
        out.append(signed_zeros)
        with_nan = rng.standard_normal(n)
        with_nan[rng.integers(0, n)] = np.nan
        out.append(with_nan)
    return out


def _same(a, b) -> bool:
    """Equal to the bit (the sign of a zero and NaNs included)."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_distinct_values_are_numpys_unique(seed):
    for x in _samples(seed):
        assert _same(distinct(x), np.unique(x))
    ints = np.random.default_rng(seed).integers(0, 6, 50)
    assert _same(distinct(ints), np.unique(ints))
    assert _same(distinct(np.zeros(0)), np.unique(np.zeros(0)))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_quantiles_and_percentiles_are_numpys(seed):
    q = np.concatenate([[0.0, 1.0, 0.5], np.random.default_rng(seed).uniform(0, 1, 9), np.linspace(0.05, 0.95, 19)])
    for x in _samples(seed):
        assert _same(quantiles(x, q), np.quantile(x, q))
        assert _same(quantiles(x, np.array([1, 99]) / 100), np.percentile(x, [1, 99]))
        finite = np.sort(np.abs(x[np.isfinite(x)]))  # no -0.0: a sort reads what a partition reads
        if finite.size:
            assert _same(sorted_quantiles(finite, q), np.quantile(finite, q))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_median_is_numpys(seed):
    for x in _samples(seed):
        assert _same(median(x), np.median(x))
