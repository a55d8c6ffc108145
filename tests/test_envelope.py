"""Fits from one factor of an envelope (arxid.models.envelope) against each structure's own fit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid._base import _core
from arxid.exceptions import ArxidError
from arxid.models import envelope
from arxid.models.arx_model import ArxModel
from arxid.models.envelope import EnvelopeFactor

SPECS = [
    (2, (2, 2), (1, 1), ()),
    (2, (2, 2), (1, 1), ("u1*vbat",)),
    (2, (2, 2), (1, 1), ("u2^2", "u1*vbat")),
    (2, (2, 2), (1, 1), ("u1*vbat", "u2^2")),  # the same columns in the other order
    (2, (2, 2), (1, 1), ("const",)),
    (2, (2, 2), (1, 1), ("u1*vbat", "const")),
    (3, (2, 2), (1, 1), ()),
    (2, (3, 2), (1, 1), ()),
    (2, (2, 2), (0, 1), ()),
    (2, (2, 2), (1, 1), ("sat(u1,0.5)",)),
    (2, (2, 2), (1, 1), ("y^3",)),  # output terms: columns of the envelope
    (2, (2, 2), (1, 1), ("u1*vbat", "y^2")),
    (2, (2, 2), (1, 1), ("sign(dy)", "u1*y^2")),  # a term with a carrier column
    (2, (2, 2), (1, 1), ("abs(y)", "sign(y)")),
    (2, (2, 2), (1, 3), ()),
]


def _data(seed: int, n: int = 6000) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2))
    v = 4.2 - 0.5 * np.linspace(0, 1, n) + 0.01 * rng.standard_normal(n)
    x = u[:, 0] * v / 4.2 + 0.3 * u[:, 1] ** 2
    y = lfilter([0, 0.5, 0.25], [1, -1.5, 0.7], x) + 0.01 * rng.standard_normal(n)
    return arxid.IOData(y, u, 0.01, extra={"vbat": v})


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("first_lag", [0, 2, 6])
def test_envelope_fits_equal_each_structures_own_fit(seed, first_lag):
    d = _data(seed)
    env = EnvelopeFactor(d, SPECS, first_lag=first_lag)
    inside = 0
    for i, (na, nb, nk, eff) in enumerate(SPECS):
        own = ArxModel(na=na, nb=nb, nk=nk, effects=eff).fit(d, first_lag=first_lag)
        if not env.has(i):
            # left out only when its own rows start elsewhere
            assert own.n_rows_ != env.n_rows
            with pytest.raises(ArxidError):
                env.solve(i)
            continue
        inside += 1
        f = ArxModel(na=na, nb=nb, nk=nk, effects=eff).fit_in(env, i)
        assert f.regressor_names_ == own.regressor_names_
        assert f.n_rows_ == own.n_rows_
        np.testing.assert_allclose(f.parameters_, own.parameters_, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(f.covariance_, own.covariance_, rtol=1e-8, atol=1e-16)
        assert f.rss_ == pytest.approx(own.rss_, rel=1e-10)
        np.testing.assert_allclose(f.predict(d), own.predict(d), rtol=1e-9, atol=1e-12)
    assert inside >= 12


def test_envelope_refuses_data_with_gaps_and_a_foreign_structure():
    d = _data(3)
    y = d.y.copy()
    y[100] = np.nan
    with pytest.raises(ArxidError):
        EnvelopeFactor(arxid.IOData(y, d.u, 0.01, extra=d.extra), SPECS[:2])
    v = d.extra["vbat"].copy()
    v[200] = np.nan  # a gap in a column's signal only
    with pytest.raises(ArxidError, match="without missing samples"):
        EnvelopeFactor(arxid.IOData(d.y, d.u, 0.01, extra={"vbat": v}), SPECS[:2])
    env = EnvelopeFactor(d, SPECS[:2])
    with pytest.raises(ArxidError, match="not structure 0"):
        ArxModel(na=3, nb=(2, 2), nk=(1, 1)).fit_in(env, 0)


def _fit(r, n, env, s):
    return np.asarray(_core.fit_from_factor(r, n, env, s, []).theta)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("first_lag", [4, 9])
def test_rows_that_start_late_cost_no_output_lags(seed, first_lag):
    # The envelope's factor on rows from first_lag against the old path's: the grid factor of the
    # envelope padded with output lags up to first_lag (so its rows start there). The same rows
    # and least-squares problems; the padded factor's extra columns change the rounding only.
    d = _data(seed)
    y, u, starts = d.y, np.ascontiguousarray(d.u), list(d.experiment_starts)
    env = (2, [2, 3], [1, 0])
    r, n = _core.envelope_factor(y, list(u.T.copy()), starts, env, first_lag)
    padded = (first_lag, env[1], env[2])
    r0, n0 = _core.grid_factor(y, u, starts, np.array([[first_lag, 2, 3, 1, 0]], dtype=np.int64), [], n_threads=0)
    assert r.shape == (2 + 5 + 1,) * 2 and r0.shape == (first_lag + 5 + 1,) * 2
    assert n == n0 == d.n_samples - first_lag
    for s in [(2, [2, 3], [1, 0]), (1, [1, 2], [1, 1]), (2, [0, 3], [0, 0]), (0, [1, 1], [2, 0])]:
        np.testing.assert_allclose(_fit(r, n, env, s), _fit(r0, n0, padded, s), rtol=1e-11, atol=1e-13)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("starts", [[0], [0, 2500]])
def test_envelope_factor_of_separate_columns_is_the_grid_factor_to_the_bit(seed, starts):
    # Rows from the envelope's own largest lag: the same rows and columns as the grid's factor,
    # which reads the inputs side by side in one row-major matrix, so the same R bit for bit; a
    # missing sample (in the output or a column) is refused.
    d = _data(seed)
    u = np.ascontiguousarray(d.u)
    for env in [(3, [2, 2], [1, 1]), (1, [3, 0], [0, 2])]:
        r, n = _core.envelope_factor(d.y, [u[:, 0].copy(), u[:, 1].copy()], starts, env, 0)
        grid = np.array([[env[0], *env[1], *env[2]]], dtype=np.int64)
        r0, n0 = _core.grid_factor(d.y, u, starts, grid, [], n_threads=0)
        assert n == n0 == d.n_samples - len(starts) * max(env[0], *(b + k - 1 for b, k in zip(env[1], env[2]) if b))
        assert np.array_equal(r, r0)
    y = d.y.copy()
    y[100] = np.nan
    with pytest.raises(arxid.DataError, match="without missing samples"):
        _core.envelope_factor(y, [u[:, 0].copy(), u[:, 1].copy()], [0], (3, [2, 2], [1, 1]), 0)
    with pytest.raises(arxid.DataError, match="without missing samples"):
        _core.envelope_factor(
            d.y, [u[:, 0].copy(), np.where(u[:, 1] > 2, np.inf, u[:, 1])], [0], (3, [2, 2], [1, 1]), 0
        )
    with pytest.raises(arxid.DataError, match="a column has"):
        _core.envelope_factor(d.y, [u[:-1, 0].copy(), u[:, 1].copy()], [0], (3, [2, 2], [1, 1]), 0)
    with pytest.raises(arxid.DataError, match="one order per input"):
        _core.envelope_factor(d.y, [u[:, 0].copy()], [0], (3, [2, 2], [1, 1]), 0)


SHAPED = [
    (2, (2, 2), (1, 1), ("u1*vbat",)),
    (3, (2, 2), (1, 1), ("u1*vbat", "const")),
    (2, (2, 2), (1, 1), ("through(u1*vbat)",)),  # the same series as u1*vbat, in the input's place
    (2, (2, 2), (1, 1), ("through(u1*vbat)", "const")),
    (2, (2, 2), (1, 1), ("through(u1*vbat)", "u2^2", "y^2")),
    (2, (2, 2), (1, 1), ("time",)),
]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_shape_and_the_effect_of_the_same_series_are_one_column(seed, monkeypatch):
    """``through(u1*vbat)`` and ``u1*vbat`` hold the same series: the envelope holds it once, and
    every structure's fit from it equals its own fit, and the fit from the envelope that held it
    twice, to 1e-12 (the two factors differ by rounding: the QR sees other columns); a structure
    with both is left to its own fit."""
    d = _data(seed)
    env = EnvelopeFactor(d, SHAPED, first_lag=3)
    assert env.alias == {"through(u1*vbat)": "u1*vbat"}
    assert "through(u1*vbat)" not in env.labels
    for i, (na, nb, nk, eff) in enumerate(SHAPED):
        own = ArxModel(na=na, nb=nb, nk=nk, effects=eff).fit(d, first_lag=3)
        f = ArxModel(na=na, nb=nb, nk=nk, effects=eff).fit_in(env, i)
        assert f.regressor_names_ == own.regressor_names_
        np.testing.assert_allclose(f.parameters_, own.parameters_, rtol=1e-9, atol=1e-12)
        assert f.rss_ == pytest.approx(own.rss_, rel=1e-10)
    monkeypatch.setattr(envelope, "_same_columns", lambda *_: {})
    twice = EnvelopeFactor(d, SHAPED, first_lag=3)
    assert "through(u1*vbat)" in twice.labels and len(twice.labels) == len(env.labels) + 1
    for i in range(len(SHAPED)):
        a, b = env.solve(i)[2], twice.solve(i)[2]
        np.testing.assert_allclose(a.theta, b.theta, rtol=1e-12, atol=1e-14)
        assert a.rss == pytest.approx(b.rss, rel=1e-12)
    both = (2, (2, 2), (1, 1), ("u1*vbat", "through(u1*vbat)"))
    assert env.add(both) is None
    assert EnvelopeFactor(d, [*SHAPED, both], first_lag=3).alias == {}
