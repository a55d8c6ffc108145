"""The rechoice scores a neighbourhood of structures by the core's lanes, as a sweep does, and
forms the errors only of a structure that can be better: the same RMS as each model's own
prediction to rounding, and the same models kept."""

import math

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.diagnosis.restructure import _neighbours, _Search
from arxid.models.lanes import lane_rms


def _record(seed, n=6000, gap=False):
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(n))
    v = 12.0 - np.linspace(0, 2, n) + 0.05 * rng.standard_normal(n)
    y = lfilter([0, 0.4, 0.2], [1, -1.3, 0.5], u * v / 12) + 0.02 * rng.standard_normal(n)
    if gap:
        y[n // 2] = np.nan
    return arxid.IOData(y, u, 0.01, extra={"v": v})


def _neighbourhood(effects, gap=False, initial="zero"):
    est, val = _record(1), _record(2, gap=gap)
    model = arxid.arx(est, 2, 2, 1, effects=effects)
    search = _Search(est, val, None, initial, None)
    orders = (model.na_, tuple(model.nb_), tuple(model.nk_))
    return search, [m for m in search.fit_all(model, _neighbours(orders), 5) if m is not None]


@pytest.mark.parametrize("effects", [[], ["u1*v"], ["u1*v", "const"]])
def test_lanes_give_each_models_rms_and_keep_the_same_models(effects):
    search, models = _neighbourhood(effects)
    lanes = lane_rms(models, search.validation, None)
    assert lanes is not None
    exact = np.array([search.measured(m)[0] for m in models])
    np.testing.assert_allclose(lanes, exact, rtol=1e-12)
    below = float(np.median(exact))
    got = search.screened(models, below)
    want = [search.measured(m, keep_below=below) for m in models]
    for (g_rms, g_model, g_err), (w_rms, w_model, w_err) in zip(got, want, strict=True):
        assert g_model is w_model and (g_err is None) == (w_err is None)
        if w_err is not None:  # a kept model: its own prediction's RMS and errors
            assert g_rms == w_rms
            np.testing.assert_array_equal(g_err, w_err)


@pytest.mark.parametrize(
    ("effects", "gap", "initial"), [(["y^2"], False, "zero"), ([], True, "zero"), ([], False, "estimate")]
)
def test_output_terms_missing_samples_and_estimated_starts_use_each_prediction(effects, gap, initial):
    search, models = _neighbourhood(effects, gap=gap, initial=initial)
    assert (lane_rms(models, search.validation, None) if initial == "zero" else None) is None
    got = search.screened(models, math.inf)
    assert all(err is not None for _, _, err in got)
    assert [rms for rms, _, _ in got] == [search.measured(m)[0] for m in models]


def test_the_judges_refits_are_validated_together_as_one_by_one():
    """Candidates with different effects share lanes through the union of their columns; each gets
    the validation error of its own prediction (to rounding), an output term its own free run."""
    from arxid.checks import error_rms
    from arxid.diagnosis.extension import Candidate, Refits

    est, val = _record(3), _record(4)
    model = arxid.arx(est, 2, 2, 1)
    cands = [Candidate(e, (e,), 2, model.nb_, model.nk_, "effect") for e in ("u1*v", "v", "const", "time", "y^2")]
    shared = Refits(model, est, cands)
    shared.validate_all(cands, val, None)
    assert len(shared._validated) == 4  # all but the output term
    for c in cands:
        fitted, rms = shared.validated(c, val, None)
        assert rms == pytest.approx(error_rms(fitted, val), rel=1e-12)
        assert fitted.effects == (c.label,)


@pytest.mark.parametrize("seed", [3, 5, 8])
def test_refits_whose_columns_come_in_other_orders_share_lanes(seed):
    """A shape that replaces the input (``through(u1*v)``, its column where the input's was) beside
    effects after the input: the union keeps every model's own column order, so all share lanes,
    each with its own prediction's error to rounding; models that order two columns both ways
    cannot."""
    from arxid.checks import error_rms
    from arxid.diagnosis.extension import Candidate, Refits
    from arxid.models.lanes import _union

    est, val = _record(seed), _record(seed + 1)
    model = arxid.arx(est, 2, 2, 1)
    labels = ("u1*v", "u1*v+const", "through(u1*v)", "through(u1*v)+const", "const", "time")
    cands = [Candidate(lab, tuple(lab.split("+")), 2, model.nb_, model.nk_, "effect") for lab in labels]
    shared = Refits(model, est, cands)
    shared.validate_all(cands, val, None)
    assert len(shared._validated) == len(cands)
    for c in cands:
        fitted, rms = shared.validated(c, val, None)
        assert rms == pytest.approx(error_rms(fitted, val), rel=1e-12)
    assert _union([["u1", "const"], ["through(u1*v)", "const"]]) == ["u1", "through(u1*v)", "const"]
    assert _union([["u1", "v"], ["v", "u1"]]) is None
