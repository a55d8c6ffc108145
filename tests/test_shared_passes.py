"""Work a diagnosis shares instead of repeating it: an envelope's columns computed one by one
(effects.layout_column), more structures fitted from a factor already made (EnvelopeFactor.add,
Refits(reuse=)), an output term's overflow check made once per data set."""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.diagnosis.extension import Candidate, Refits
from arxid.exceptions import DataError
from arxid.models.arx_model import ArxModel
from arxid.models.effects import compile_effects, layout_column
from arxid.models.envelope import EnvelopeFactor
from test_envelope import _data  # the battery-scaled two-input plant

EFFECTS = ("u1*vbat", "u2^2", "vbat", "const", "time", "sat(u1,0.5)", "sign(dy)", "u1*y^2", "abs(u2)")


@pytest.mark.parametrize("seed", [0, 1])
def test_layout_column_is_the_compiled_column_bit_for_bit(seed):
    d = _data(seed)
    lay = compile_effects(EFFECTS, d, (2, 2), (1, 1))
    assert "carrier:u1*y^2" in lay.column_labels  # a carrier column is among them
    for j, label in enumerate(lay.column_labels):
        assert np.array_equal(layout_column(label, d), lay.u[:, j]), label


def test_layout_column_refuses_an_overflow_like_compile_effects():
    d = arxid.IOData(np.zeros(50), np.full(50, 1e200), 0.1)
    with pytest.raises(DataError, match="overflows"):
        compile_effects(("u1^2",), d, (1,), (1,))
    with pytest.raises(DataError, match="overflows"):
        layout_column("u1^2", d)


def test_an_output_term_that_overflows_is_refused_every_time():
    y = np.full(50, 1e120)
    d = arxid.IOData(y, np.ones(50), 0.1)
    for _ in range(2):  # the check is remembered only when it passes
        with pytest.raises(DataError, match="overflows"):
            compile_effects(("y^3",), d, (1,), (1,))


def test_an_added_structure_fits_as_its_own_envelope_and_an_uncovered_one_is_refused():
    d = _data(2)
    specs = [(2, (2, 2), (1, 1), ("u1*vbat",)), (2, (2, 2), (1, 1), ("u2^2",)), (3, (2, 2), (1, 1), ())]
    env = EnvelopeFactor(d, specs, first_lag=3)
    pair = (2, (2, 2), (1, 1), ("u1*vbat", "u2^2"))
    i = env.add(pair)
    assert i == len(specs)
    fit = ArxModel(na=2, nb=(2, 2), nk=(1, 1), effects=pair[3]).fit_in(env, i)
    own = ArxModel(na=2, nb=(2, 2), nk=(1, 1), effects=pair[3]).fit(d, first_lag=3)
    assert fit.n_rows_ == own.n_rows_
    np.testing.assert_allclose(fit.parameters_, own.parameters_, rtol=1e-9, atol=1e-12)
    assert env.add((2, (2, 2), (1, 1), ("const",))) is None  # a column the envelope lacks
    assert env.add((4, (2, 2), (1, 1), ())) is None  # more output lags than it has
    assert env.add((2, (3, 2), (1, 1), ())) is None  # a deeper input lag
    assert env.add((2, (2, 2), (0, 1), ())) is None  # an earlier delay
    assert env.add((2, (2, 2), (1, 1), ("u1*vbat",))) is not None  # a structure it holds already


def test_refits_from_a_reused_factor_validate_as_from_their_own():
    d, val = _data(3), _data(4)
    m = arxid.ArxModel(na=2, nb=(2, 2), nk=(1, 1)).fit(d)
    one = [Candidate(e, (e,), 2, (2, 2), (1, 1), "effect") for e in ("u1*vbat", "u2^2", "const")]
    pairs = [
        Candidate("u1*vbat+u2^2", ("u1*vbat", "u2^2"), 2, (2, 2), (1, 1), "pair"),
        Candidate("u1*vbat+const", ("u1*vbat", "const"), 2, (2, 2), (1, 1), "pair"),
    ]
    first = Refits(m, d, one)
    shared = Refits(m, d, pairs, first)
    alone = Refits(m, d, pairs)
    assert shared.envelope is first.envelope and alone.envelope is not first.envelope
    for c in pairs:
        assert shared.has(c)
        a, b = shared.validated(c, val, None), alone.validated(c, val, None)
        np.testing.assert_allclose(a[0].parameters_, b[0].parameters_, rtol=1e-9, atol=1e-12)
        assert a[1] == pytest.approx(b[1], rel=1e-9)
    # a candidate the factor does not hold: a new factor, the same answers
    other = [Candidate("na+1", (), 3, (2, 2), (1, 1), "dynamics"), pairs[0]]
    again = Refits(m, d, other, first)
    assert again.envelope is not first.envelope and again.has(other[0])
    # another model: never its factor
    m2 = arxid.ArxModel(na=2, nb=(2, 2), nk=(1, 1), effects=("u1*vbat",)).fit(d)
    assert Refits(m2, d, pairs, first).envelope is not first.envelope
