"""Fits from one factor of an envelope (arxid.models.envelope) against each structure's own fit."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.exceptions import ArxidError
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
    env = EnvelopeFactor(d, SPECS[:2])
    with pytest.raises(ArxidError, match="not structure 0"):
        ArxModel(na=3, nb=(2, 2), nk=(1, 1)).fit_in(env, 0)
