"""The judge's refits of shape candidates (an input replaced by a shape) from the shared factor of
the model's refits, against each one refitted and validated on its own."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.diagnosis.extension import Candidate, Refits, refit_and_validate
from test_envelope import _data  # the battery-scaled two-input plant

SHAPES = (("through(u1*vbat)",), ("through(u1*vbat)", "const"), ("through(spow(u2,1.5))",), ("through(clip(u1,-1,1))",))


def _candidates(m) -> list[Candidate]:
    effect = Candidate("u2^2", ("u2^2",), m.na_, m.nb_, m.nk_, "effect")
    shapes = [Candidate("+".join(e), e, m.na_, m.nb_, m.nk_, "shape") for e in SHAPES]
    return [effect, *shapes]


def _with_gaps(d: arxid.IOData) -> arxid.IOData:
    y = d.y.copy()
    y[[500, 2000, 2001, 4100]] = np.nan
    return arxid.IOData(y, d.u, d.ts, extra=d.extra)


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("horizon", [None, 10])
def test_shape_refits_from_the_shared_factor_equal_their_own(seed, horizon):
    d, val = _data(seed), _data(seed + 10)
    m = arxid.ArxModel(na=2, nb=(2, 2), nk=(1, 1)).fit(d)
    cands = _candidates(m)
    refits = Refits(m, d, cands)
    refits.validate_all(cands, val, horizon)
    for c in cands:
        assert refits.has(c), c.label
        got, own = refits.validated(c, val, horizon), refit_and_validate(m, d, val, c, horizon)
        assert got[0].regressor_names_ == own[0].regressor_names_
        # a small QR of the shared factor's columns against the QR of the candidate's own rows:
        # the same least-squares problem, equal to rounding
        np.testing.assert_allclose(got[0].parameters_, own[0].parameters_, rtol=1e-9, atol=1e-12)
        assert got[1] == pytest.approx(own[1], rel=1e-9)


@pytest.mark.parametrize("seed", [0, 1])
def test_shape_refits_on_data_with_gaps_are_their_own(seed):
    d, val = _with_gaps(_data(seed)), _data(seed + 10)
    m = arxid.ArxModel(na=2, nb=(2, 2), nk=(1, 1)).fit(d)
    cands = _candidates(m)
    refits = Refits(m, d, cands)
    assert refits.envelope is None
    for c in cands:
        got, own = refits.validated(c, val, None), refit_and_validate(m, d, val, c, None)
        assert np.array_equal(got[0].parameters_, own[0].parameters_)
        assert got[1] == own[1]
