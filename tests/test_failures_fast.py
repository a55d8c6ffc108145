"""Where it fails: the per-bin statistics from sums per bin against direct references (scipy's
one-way ANOVA and Kruskal–Wallis on the bins' samples, numpy per bin, the F test of a window)."""

import math

import numpy as np
import pytest
from scipy import stats

import arxid
from arxid.checks.binning import _anova_p, _varies
from arxid.checks.failures import _segment_p_value


def _groups(seed, nb=6, n=5000):
    rng = np.random.default_rng(seed)
    where = rng.integers(0, nb, n).astype(np.uint8)
    es = rng.standard_normal(n) * (1.0 + 0.1 * where) + 0.03 * where + 5.0
    return es, where, np.bincount(where, minlength=nb)


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_anova_from_sums_is_scipys_f_oneway(seed):
    es, where, counts = _groups(seed)
    want = stats.f_oneway(*[es[where == g] for g in range(len(counts))]).pvalue
    assert _anova_p(es, where, counts) == pytest.approx(want, rel=1e-9)


def test_anova_from_sums_with_an_empty_group():
    es, where, _ = _groups(4)
    where[where == 2] = 3
    counts = np.bincount(where, minlength=6)
    want = stats.f_oneway(*[es[where == g] for g in range(6) if counts[g]]).pvalue
    assert _anova_p(es, where, counts) == pytest.approx(want, rel=1e-9)


def test_varies_is_every_group_not_constant():
    es, where, counts = _groups(5)
    assert _varies(es, where, counts)
    es[where == 1] = 0.25  # one constant group
    assert not _varies(es, where, counts)
    # with more groups than the per-group search handles, the same answer
    rng = np.random.default_rng(6)
    many = rng.integers(0, 40, 4000)
    vals = rng.standard_normal(4000)
    c = np.bincount(many, minlength=45)
    assert _varies(vals, many, c) == all(np.ptp(vals[many == g]) > 0 for g in np.flatnonzero(c))
    vals[many == 39] = 1.0
    assert not _varies(vals, many, c)


@pytest.mark.parametrize("seed", [0, 1])
def test_segment_f_test_matches_the_split_samples(seed):
    rng = np.random.default_rng(seed)
    res = rng.standard_normal(6000)
    res[2000:2300] *= 1.3
    res[[5, 2100, 4000]] = np.nan
    finite = res[np.isfinite(res)]
    total = (finite.size, float(np.dot(finite, finite)))
    for lo, hi in [(2000, 2300), (0, 400), (5700, 6000)]:
        inside = res[lo:hi][np.isfinite(res[lo:hi])]
        outside = np.concatenate([res[:lo], res[hi:]])
        outside = outside[np.isfinite(outside)]
        f = np.mean(inside**2) / np.mean(outside**2)
        want = min(1.0, stats.f.sf(f, inside.size, outside.size) * 20)
        assert _segment_p_value(res, lo, hi, 20, total) == pytest.approx(want, rel=1e-10)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_binned_statistics_match_the_bins_samples(seed):
    rng = np.random.default_rng(seed)
    n = 6000
    u = rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):  # the gain grows with |u|: the error depends on the input
        y[t] = 0.6 * y[t - 1] + u[t - 1] + 0.2 * u[t - 1] * abs(u[t - 1]) + 0.05 * rng.standard_normal()
    data = arxid.IOData(y, u, 0.01)
    m = arxid.arx(data, 1, 1, 1)
    fa = arxid.where_it_fails(m, data)
    res = fa.residual
    sb = next(b for b in fa.by_signal if b.signal == data.input_names[0])
    x = np.r_[np.nan, u[:-1]]
    ok = np.isfinite(x) & np.isfinite(res)
    xs, es = x[ok], res[ok]
    bins = np.clip(np.searchsorted(sb.edges, xs, side="right") - 1, 0, len(sb.edges) - 2)
    groups = [es[bins == g] for g in range(len(sb.edges) - 1)]
    assert sb.counts.tolist() == [len(g) for g in groups]
    assert np.allclose(sb.mean, [g.mean() for g in groups], rtol=1e-10, atol=0)
    assert np.allclose(sb.rms, [math.sqrt(np.mean(g**2)) for g in groups], rtol=1e-12, atol=0)
    p_kw = stats.kruskal(*[g**2 for g in groups]).pvalue
    p_an = stats.f_oneway(*groups).pvalue
    assert sb.p_value == pytest.approx(min(1.0, 2 * min(p_kw, p_an)), rel=1e-9)
    assert sb.p_value < 1e-6  # the input's bins differ


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bin_index_is_quantile_bins_by_searchsorted(seed):
    from arxid.checks.binning import _bin_index

    rng = np.random.default_rng(seed)
    for xs in [rng.standard_normal(5001), np.round(rng.standard_normal(3000), 1), rng.integers(0, 5, 999) * 0.5]:
        for n_bins in [4, 8, 300]:
            edges, where = _bin_index(xs, n_bins)
            want = np.quantile(xs, np.linspace(0, 1, n_bins + 1))
            if len(np.unique(want)) > n_bins:
                assert np.array_equal(edges, np.unique(want))
                assert np.array_equal(where, np.clip(np.searchsorted(edges, xs, side="right") - 1, 0, len(edges) - 2))
            else:
                values = np.unique(xs)
                assert np.array_equal(where, np.searchsorted(values, xs))


def test_sorted_quantiles_are_numpys_to_the_bit():
    from arxid._base.order_statistics import sorted_quantiles

    rng = np.random.default_rng(7)
    for n in [1, 2, 3, 7, 8, 9, 100, 1001, 40000]:
        for xs in [rng.standard_normal(n) * 1e3, np.round(rng.standard_normal(n), 2), rng.integers(0, 4, n) * 0.1]:
            for n_bins in [2, 7, 8, 13]:
                q = np.linspace(0, 1, n_bins + 1)
                assert np.array_equal(sorted_quantiles(np.sort(xs), q), np.quantile(xs, q))


def test_argsort_of_nonnegative_values_sorts_them():
    from arxid.checks.binning import _argsort_nonnegative

    rng = np.random.default_rng(8)
    base = rng.standard_normal(300000) ** 2
    near = np.nextafter(base[:5000], np.inf)  # values that tie in all but the lowest bits
    for v in [base, np.r_[base, near, base[:100], 0.0, 0.0], np.round(base, 3), np.zeros(5), base[:1], base[:0]]:
        order = _argsort_nonnegative(v)
        assert np.array_equal(np.sort(order), np.arange(len(v)))
        assert np.array_equal(v[order], np.sort(v))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_sums_per_group_in_one_pass_are_numpys_bincounts_to_the_bit(seed):
    """The core's one pass over the bins gives bincount's counts and sums bit for bit, and says
    whether each group holds two different values as _varies does."""
    from arxid._base import _core

    es, where, counts = _groups(seed, nb=9, n=30_011)
    where[where == 4] = 5  # an empty group
    es[where == 7] = 1.5  # a constant one
    series = [es, es * es, np.arange(1.0, len(es) + 1.0), es - es.mean()]
    got_counts, sums, varies = _core.group_sums(where, 10, series)
    np.testing.assert_array_equal(got_counts, np.bincount(where, minlength=10))
    for s, got in zip(series, sums, strict=True):
        assert np.array_equal(got, np.bincount(where, weights=s, minlength=10))
    filled = got_counts > 0
    assert not varies[7] and varies[[0, 1, 2, 3, 5, 6, 8]].all() and not varies[~filled].any()
    assert bool(varies[filled].all()) == _varies(es, where, np.bincount(where, minlength=10))
    with pytest.raises(arxid.ArxidError, match="not below the number of groups"):
        _core.group_sums(where, 8, series)
    with pytest.raises(arxid.DataError, match="grouped series"):
        _core.group_sums(where, 10, [es[:-1]])
