"""The residual tests and where-it-fails keep what depends on the data alone (a signal's
prewhitening filter and autocorrelation, its operating-point bins) from one model's check to the
next: a check on data already checked with other models gives exactly what it gives on fresh data."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.checks import residuals, where_it_fails


def _record(seed: int, n: int = 6000, nan: bool = False) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    vbat = 4.2 - 0.5 * np.linspace(0, 1, n) + 0.01 * rng.standard_normal(n)
    drift = np.cumsum(rng.standard_normal(n)) * 0.01
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.4 * u[t - 1] * vbat[t - 1] / 4.2 + 0.05 * rng.standard_normal()
    if nan:
        y[rng.integers(10, n, 5)] = np.nan
    return arxid.IOData(y, u, 0.01, extra={"vbat": vbat, "drift": drift}, experiment_starts=(0, n // 2))


def _copy(d: arxid.IOData) -> arxid.IOData:
    return arxid.IOData(
        d.y.copy(),
        d.u.copy(),
        d.ts,
        extra={k: v.copy() for k, v in d.extra.items()},
        experiment_starts=d.experiment_starts,
    )


def _residual_numbers(r) -> list:
    return [r.autocorrelation, r.ljung_box_p_value] + [
        (r.cross_correlation[k], r.cross_bounds[k], r.cross_p_values[k], r.low_frequency_p_values[k])
        for k in r.cross_correlation
    ]


def _failure_numbers(f) -> list:
    return [(b.signal, b.edges, b.rms, b.mean, b.counts, b.p_value) for b in f.by_signal]


def _equal(a, b) -> None:
    for x, y in zip(a, b, strict=True):
        if isinstance(x, tuple):
            _equal(x, y)
        else:
            np.testing.assert_array_equal(x, y)


@pytest.mark.parametrize("nan", [False, True])
def test_checks_of_a_second_model_equal_those_on_fresh_data(nan):
    est, val = _record(1, nan=nan), _record(2, nan=nan)
    first = arxid.arx(est, 2, 2, 1)
    models = [arxid.arx(est, 2, 2, 1, effects=["u1*vbat"]), arxid.arx(est, 3, 1, 1)]
    residuals(first, val), where_it_fails(first, val)  # fills what the data's checks keep
    for m in models:
        fresh = _copy(val)
        _equal(_residual_numbers(residuals(m, val)), _residual_numbers(residuals(m, fresh)))
        _equal(_failure_numbers(where_it_fails(m, val)), _failure_numbers(where_it_fails(m, fresh)))


def test_a_replaced_signal_is_not_taken_for_the_one_checked_before():
    est, val = _record(3), _record(4)
    m = arxid.arx(est, 2, 2, 1)
    before = residuals(m, val).cross_p_values["drift"], where_it_fails(m, val).bins("drift").edges
    val.extra["drift"] = np.asarray(val.extra["drift"] * 3.0 + np.sin(np.arange(val.n_samples)))
    fresh = _copy(val)
    after = residuals(m, val), where_it_fails(m, val)
    assert after[0].cross_p_values["drift"] == residuals(m, fresh).cross_p_values["drift"]
    np.testing.assert_array_equal(after[1].bins("drift").edges, where_it_fails(m, fresh).bins("drift").edges)
    assert not np.array_equal(before[1], after[1].bins("drift").edges)


@pytest.mark.parametrize("digits", [1, None])
def test_shared_ranks_of_the_squared_residual_give_scipy_kruskal(digits):
    """One sort of e² serves every signal's Kruskal–Wallis test, on all finite samples or a subset,
    with ties (midranks, tie correction) or without."""
    from scipy import stats

    from arxid.checks.binning import SquaredRanks, _kruskal

    rng = np.random.default_rng(5)
    e = rng.standard_normal(4000)
    e = np.round(e, digits) if digits else e
    e[:3] = np.nan
    ranked = SquaredRanks(e)
    ok = np.isfinite(e)
    for subset in (False, True):
        use = ok.copy()
        if subset:
            use[100:400] = False
        where = rng.integers(0, 5, int(use.sum()))
        es = e[use]
        want = stats.kruskal(*[es[where == g] ** 2 for g in range(5)]).pvalue
        assert _kruskal(use, where, 5, e, ranked) == pytest.approx(want, rel=1e-12)


def test_what_the_checks_keep_per_data_is_bounded():
    from arxid.checks import binning, correlation, failures

    est, val = _record(6, n=3000), _record(7, n=3000)
    for na in range(1, 8):  # each structure's residual starts at another sample: new bins, new filters
        m = arxid.arx(est, na, 1, 1)
        where_it_fails(m, val), residuals(m, val)
    assert 0 < len(failures._BINS[val]) <= binning._MAX_BINNED
    assert 0 < len(correlation._MEMO[val]) <= correlation._MAX_SIGNALS
