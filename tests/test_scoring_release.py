"""The scoring lets go of the model's regressors once it has scored the candidates (the shape scans
and the validated refits that follow hold their own tall arrays); the pairs of effects that hide
each other, formed later, rebuild them and give the same numbers as a scoring that kept them."""

from __future__ import annotations

import numpy as np

import arxid
from arxid.diagnosis.extension import candidate_list
from arxid.diagnosis.scoring import CandidateScoring, Scoring


def _record(seed: int = 3, n: int = 4000) -> arxid.IOData:
    """A first-order plant with two effects the model lacks: the battery's scaling and u1²."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, n)
    vbat = 11 + rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.7 * y[t - 1] + 0.4 * u[t - 1] * vbat[t - 1] / 11 + 0.3 * u[t - 1] ** 2 + 0.02 * rng.standard_normal()
    return arxid.IOData(y, u, ts=0.01, extra={"vbat": vbat})


def test_masked_pairs_after_the_release_equal_those_of_a_scoring_that_kept_its_regressors():
    data = _record()
    model = arxid.arx(data, 1, 1, 1)
    cands = candidate_list("auto", model, data)[0]
    released = Scoring(model, data, cands)
    scored, _ = released.run(0.01, 3)
    assert released._tall is None  # let go after the scoring
    kept = Scoring(model, data, cands)
    scored_kept, _ = CandidateScoring.run(kept, 0.01, 3)
    assert kept._tall is not None
    assert [(s["c"].label, s["p"], s["score"]) for s in scored] == [
        (s["c"].label, s["p"], s["score"]) for s in scored_kept
    ]
    pairs = released.masked_pairs(scored, 0.01)
    pairs_kept = kept.masked_pairs(scored_kept, 0.01)
    assert pairs  # the case forms pairs
    assert [(s["c"].label, s["p"], s["p_adj"], s["score"]) for s in pairs] == [
        (s["c"].label, s["p"], s["p_adj"], s["score"]) for s in pairs_kept
    ]


def test_candidate_columns_on_rows_with_gaps_equal_those_of_the_whole_regressor_matrix():
    """A candidate whose columns miss samples on the model's rows is tested on its own rows: its new
    columns there, built a block of rows at a time, are those of its whole regressor matrix."""
    from arxid.diagnosis.extension import layout_for
    from arxid.models.regressors import finite_regressor_columns, regressor_matrix

    data = _record(n=80_000)
    y, vbat = data.y.copy(), data.extra["vbat"].copy()
    rng = np.random.default_rng(5)
    for start in rng.integers(0, len(y) - 40, 30):
        y[start : start + 7] = np.nan
        vbat[start + 20 : start + 23] = np.nan
    gappy = arxid.IOData(y, data.u, ts=0.01, extra={"vbat": vbat})
    model = arxid.arx(gappy, 2, 1, 1)
    for c in candidate_list(["u1*vbat", "y^2", "na+1"], model, gappy)[0]:
        lay = layout_for(c, model, gappy)[1]
        phi, _, rows = regressor_matrix(gappy, c.na, lay, 3)
        which = list(range(1, phi.shape[1], 2))
        z, at = finite_regressor_columns(gappy, c.na, lay, 3, which)
        assert len(at) < len(y) - 3  # rows were left out
        np.testing.assert_array_equal(at, rows)
        np.testing.assert_array_equal(z, phi[:, which])


def test_output_term_columns_equal_those_of_the_candidates_regressor_matrix():
    """An output term's candidate columns, with a carrier (``u1*y``, ``y^3*vbat``) or without, read
    off the output and the carrier on the model's rows: to the bit the new columns of the regressor
    matrix of the model with the term (on consecutive rows, and gathered around gaps)."""
    from arxid.diagnosis.extension import layout_for
    from arxid.models.regressors import regressor_columns, regressor_names

    data = _record(n=6000)
    y = data.y.copy()
    y[3000:3004] = np.nan
    for d in (data, arxid.IOData(y, data.u, ts=0.01, extra=dict(data.extra))):
        model = arxid.arx(d, 2, 1, 1)
        sc = Scoring(model, d, candidate_list(["u1*y", "y^3*vbat", "sign(dy)", "y^2"], model, d)[0])
        assert len(sc.prepared) == 4
        for c in sc.prepared:
            lay = layout_for(c, model, d)[1]
            new = [i for i, nm in enumerate(regressor_names(d.output_name, c.na, lay)) if nm not in sc.base_names]
            z = sc._effect_columns(c)
            assert z is not None and z.shape[1] == len(new) == 1
            assert z.tobytes() == regressor_columns(d, c.na, lay, sc.rows0, new).tobytes()
