"""The diagnosis's textbook vocabulary and two effects at once (issue: friction on a speed output,
dead zone, saturation, asymmetric gain, and "something nonlinear is missing that no candidate explains").

Every plant is seeded and simulated here with its exact parameters; the expected effect and threshold
are the ones put in.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import arxid
from arxid.analysis.pipeline import analyse
from arxid.checks import error_rms
from arxid.diagnosis.candidates import CATALOGUE, auto_candidates, physics, threshold_grid
from arxid.diagnosis.ladder import Ladder
from arxid.diagnosis.suspects import diagnose


def _held(rng, n, lo, hi, hold):
    return np.repeat(rng.uniform(lo, hi, n // hold + 1), hold)[:n]


def dc_motor(seed=0, n=4000):
    """Bidirectional DC motor, duty in [−1, 1] → speed [rad/s]: gain ∝ battery voltage (discharging
    from 12 V and sagging under load) and Coulomb friction −1.0·sign(ω) on the speed."""
    rng = np.random.default_rng(seed)
    duty = _held(rng, n, -1, 1, 40)
    vbat = 12.0 - 2.5 * np.arange(n) / n - 0.8 * np.abs(duty) + 0.02 * rng.standard_normal(n)
    w = np.zeros(n)
    for t in range(1, n):
        w[t] = 0.9 * w[t - 1] + 0.5 * duty[t - 1] * vbat[t - 1] - 1.0 * np.sign(w[t - 1]) + 0.05 * rng.standard_normal()
    return arxid.IOData(w, duty, 0.01, output_name="speed", input_names=["duty"], extra={"vbat": vbat})


SHAPES = {
    "dz": (lambda v: np.sign(v) * np.maximum(np.abs(v) - 0.3, 0.0), 0.3),
    "sat": (lambda v: np.clip(v, -0.6, 0.6), 0.6),
    "pos": (lambda v: 0.6 * np.maximum(v, 0.0) + 0.2 * np.minimum(v, 0.0), None),
}


def actuator_plant(shape, seed=0, n=3000):
    """y(t) = 0.8 y(t−1) + 0.5 f(cmd(t−1)): f a dead zone (0.3), a saturation (0.6) or gains 0.6 / 0.2."""
    rng = np.random.default_rng(seed)
    u = _held(rng, n, -1, 1, 10)
    f = SHAPES[shape][0]
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.8 * y[t - 1] + 0.5 * f(u[t - 1]) + 0.01 * rng.standard_normal()
    return arxid.IOData(y, u, 0.01, input_names=["cmd"])


def backlash_plant(seed=0, n=3000, gap=0.25):
    """A gear with backlash (half-gap 0.25) between the command and a first-order plant."""
    rng = np.random.default_rng(seed)
    u = _held(rng, n, -1, 1, 5)
    b, y = np.zeros(n), np.zeros(n)
    for t in range(1, n):
        b[t] = b[t - 1] if abs(u[t] - b[t - 1]) <= gap else u[t] - gap * np.sign(u[t] - b[t - 1])
        y[t] = 0.8 * y[t - 1] + 0.5 * b[t - 1] + 0.01 * rng.standard_normal()
    return arxid.IOData(y, u, 0.01)


# ---------------------------------------------------------------------------------------------
# two effects at once
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 2])  # seed 2: each effect alone lowers the error < 5% (found as a pair)
def test_dc_motor_battery_and_speed_friction_within_three_steps(seed):
    est, val = dc_motor(seed).split(0.6)
    ladder = Ladder.run(arxid.arx(est, 1, 1, 1), est, val, max_steps=3)
    final = ladder.final_model.effects
    # The battery scales the duty: as a term beside it, or as the product the duty acts through.
    battery = {"duty*vbat", "through(duty*vbat)"} & set(final)
    assert battery and "sign(y)" in final and len(ladder.steps) - 1 <= 3
    assert not {"y^3", "y^2", "abs(y)"} & set(final)  # friction is named as friction
    fall = 1 - ladder.errors[-1] / ladder.errors[0]
    right = arxid.arx(est, 1, 1, 1, effects=["duty*vbat", "sign(y)"])  # least squares with the true terms
    assert fall >= 0.85 and fall >= 1 - error_rms(right, val) / ladder.errors[0] - 0.02
    np.testing.assert_allclose(right.effect_parameters["sign(y)"], [-1.0], rtol=0.05)
    friction = next(s for s in ladder.steps if "sign(y)" in s.added)
    assert "Coulomb friction on a speed output" in friction.physics
    assert not ladder.unexplained


def test_an_approximation_is_labelled_when_the_physics_is_found():
    """y^3 soaks up a little of the friction; once sign(y) is added it is not needed and says so."""
    est, val = dc_motor(0).split(0.6)
    m1 = arxid.arx(est, 1, 1, 1, effects=["duty*vbat"])
    lad = Ladder(val)
    lad.add(arxid.arx(est, 1, 1, 1))
    lad.add(m1, "duty*vbat")
    lad.add(m1.with_effects(["y^3"]), "y^3")
    step = lad.add(m1.with_effects(["y^3", "sign(y)"]), "sign(y)", settle=True)
    assert step.replaces == ("y^3",) and step.effects == ("duty*vbat", "sign(y)")
    assert lad.steps[2].approximation_of == "sign(y)" and lad.steps[1].approximation_of == ""
    assert "y^3 (approximated sign(y))" in str(lad) and "sign(y) (replaces y^3)" in str(lad)
    out = lad.to_list()
    assert out[2]["approximation_of"] == "sign(y)" and out[3]["replaces"] == ["y^3"]
    assert step.rms_sim_val == pytest.approx(error_rms(m1.with_effects(["sign(y)"]), val))


# ---------------------------------------------------------------------------------------------
# actuator effects with a threshold
# ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("shape", ["dz", "sat", "pos"])
def test_actuator_shape_is_the_top_suspect_with_its_threshold(shape):
    est, val = actuator_plant(shape).split(0.6)
    d = diagnose(arxid.arx(est, 1, 1, 1), est, val)
    top = d.top
    # A dead zone and a saturation are shapes the command acts through (Hammerstein).
    written = {"dz": "through(dz(cmd", "sat": "through(clip(cmd", "pos": "pos(cmd"}[shape]
    assert top is d.suspects[0] and top.effect.startswith(written), top.effect
    assert top.improvement >= 0.5 and top.p_value < 1e-10
    truth = SHAPES[shape][1]
    if truth is not None:
        levels = [abs(float(v)) for v in re.findall(r"-?[0-9.]+", top.effect.split(",", 1)[1])]
        assert all(abs(c - truth) <= 0.1 * truth for c in levels), top.effect
        assert {"dz": "dead zone", "sat": "saturation"}[shape] in top.physics
    # the other shape of the same family is not listed beside it
    twin = {"dz": "sat(cmd", "sat": "dz(cmd", "pos": "abs(cmd"}[shape]
    assert not any(s.effect.startswith(twin) for s in d.suspects)


@pytest.mark.parametrize("collinear", [False, True])
def test_threshold_shares_in_one_pass_equal_the_shares_one_by_one(collinear):
    """The scan scores forty thresholds from one pass over the regressors per block of rows; each
    share is the one :meth:`AddedVariableTest.share` gives for that threshold's columns alone."""
    from arxid.diagnosis.added_variable import AddedVariableTest
    from arxid.models.effects import thresholded, thresholded_products

    rng = np.random.default_rng(5)
    n = 40_000  # more than two blocks of rows
    phi = rng.standard_normal((n, 4))
    if collinear:  # rank-deficient regressors: the blocked QR path of the test
        phi[:, 3] = phi[:, 0] - 2.0 * phi[:, 1]
    x = rng.uniform(-2, 2, n + 2)
    lagged = np.column_stack([x[2:], x[1:-1]])  # two lags of one signal
    y = phi @ [1.0, -0.5, 0.3, 0.0] + 0.4 * thresholded("dz", np.abs(lagged[:, 0]), np.sign(lagged[:, 0]), 0.7)
    test = AddedVariableTest(phi, y + 0.05 * rng.standard_normal(n))
    cs = np.linspace(0.1, 1.9, 40)
    for op in ("dz", "sat"):
        batch = test.shares(lambda phi, e, op=op: thresholded_products(op, phi, e, lagged, cs), len(cs), 2)
        one_by_one = [test.share(thresholded(op, np.abs(lagged), np.sign(lagged), c)) for c in cs]
        assert batch is not None
        np.testing.assert_allclose(batch, one_by_one, rtol=1e-9, atol=1e-15)
        if op == "dz":
            assert abs(cs[int(np.argmax(batch))] - 0.7) < 0.05  # the dead zone put in


def test_threshold_products_equal_the_products_of_the_columns():
    """The Rust core forms a scan's products without its columns; they are those of the columns
    numpy forms, for both shapes, a zero sample and rows that are not a multiple of its chunks."""
    from arxid.models.effects import thresholded, thresholded_products

    rng = np.random.default_rng(3)
    n = 20_011
    a, e, lagged = rng.standard_normal((n, 3)), rng.standard_normal(n), rng.uniform(-2, 2, (n, 2))
    lagged[5, 1] = 0.0
    cs = np.array([0.0, 0.2, 1.0, 1.7, 3.0])
    for op in ("dz", "sat"):
        cross, zz = thresholded_products(op, a, e, lagged, cs)
        for i, c in enumerate(cs):
            z = thresholded(op, np.abs(lagged), np.sign(lagged), c)
            want = np.column_stack([a, e]).T @ z
            np.testing.assert_allclose(cross[:, 2 * i : 2 * i + 2], want, rtol=1e-11, atol=1e-9)
            np.testing.assert_allclose(zz[i], z.T @ z, rtol=1e-11, atol=1e-9)


@pytest.mark.parametrize("collinear", [False, True])
def test_candidate_tests_in_one_pass_equal_the_tests_one_by_one(collinear):
    """Candidates are tested in groups that read the regressors once per block of rows; each
    result is the one :meth:`AddedVariableTest.test` gives for that block alone, including a block
    collinear with the regressors (the stripped QR decides), a zero block and a block with a
    column that repeats a regressor."""
    from arxid.diagnosis.added_variable import AddedVariableTest

    rng = np.random.default_rng(11)
    n = 40_000  # more than two blocks of rows
    phi = rng.standard_normal((n, 4))
    if collinear:  # rank-deficient regressors: the blocked QR path of the test
        phi[:, 3] = phi[:, 0] - 2.0 * phi[:, 1]
    x = rng.standard_normal(n)
    y = phi @ [1.0, -0.5, 0.3, 0.0] + 0.3 * x**2 + 0.05 * rng.standard_normal(n)
    test = AddedVariableTest(phi, y)
    blocks = [
        np.column_stack([x**2, x**3]),  # the effect put in
        rng.standard_normal((n, 1)),  # nothing
        np.zeros((n, 2)),  # zero on these data
        np.column_stack([phi[:, 1], np.abs(x)]),  # one column already in the model
        np.column_stack([phi[:, 0] + 1e-9 * x, x]),  # nearly collinear: the stripped QR
    ]
    batch, one_by_one = test.tests(blocks), [test.test(z) for z in blocks]
    assert [why for _, why in batch] == [why for _, why in one_by_one]
    for (got, _), (want, _) in zip(batch, one_by_one):
        assert (got is None) == (want is None)
        if got is not None:
            assert got.n_columns == want.n_columns
            np.testing.assert_allclose(
                [got.score, got.f_statistic, got.p_value], [want.score, want.f_statistic, want.p_value], rtol=1e-9
            )
    assert batch[0][0].p_value < 1e-12 and batch[1][0].p_value > 1e-4  # the effect, and not the noise


def test_threshold_grid_is_the_quantiles_and_needs_enough_levels():
    x = np.linspace(-1, 1, 2001)
    np.testing.assert_allclose(threshold_grid(x), np.quantile(np.abs(x), np.linspace(0.05, 0.95, 19)))
    assert threshold_grid(np.repeat([-1.0, 0.5, 2.0], 100)).size == 0  # three levels: nothing to scan


# ---------------------------------------------------------------------------------------------
# outside the vocabulary
# ---------------------------------------------------------------------------------------------
def test_backlash_is_not_explained_and_the_diagnosis_says_so():
    est, val = backlash_plant().split(0.6)
    a = analyse(est, val, orders=(1, 1, 1), max_steps=3)
    for d in a.ladder.diagnoses:  # a suspect is only "the explanation" with the usual 5% fall
        assert all(s.improvement >= d.min_improvement for s in d.significant)
    sentence = a.ladder.unexplained
    assert sentence.startswith("the residuals still depend nonlinearly on u1 (lag")
    assert sentence.endswith("but none of the candidates removes it")
    assert sentence in str(a)
    out = json.loads(a.to_json())
    assert out["nonlinear_dependence"]["unexplained"] == sentence
    assert "u1" in [s["signal"] for s in out["nonlinear_dependence"]["signals"]]


def test_no_sentence_when_the_model_is_right():
    est, val = actuator_plant("dz").split(0.6)
    d = diagnose(arxid.arx(est, 1, 1, 1, effects=["dz(cmd,0.3)"]), est, val)
    assert not d.significant and d.nonlinear_dependence == () and d.unexplained == ""


# ---------------------------------------------------------------------------------------------
# grammar, candidates and the catalogue
# ---------------------------------------------------------------------------------------------
def test_sign_of_the_output_is_simulated_on_the_simulated_output():
    est, val = dc_motor(1).split(0.6)
    m = arxid.arx(est, 1, 1, 1, effects=["duty*vbat", "sign(y)"])
    a1, b1, cv, cs = m.parameters_
    y, u, v = val.y, val.u[:, 0], val.extra["vbat"]
    sim = np.zeros_like(y)
    sim[0] = y[0]
    for t in range(1, len(y)):
        sim[t] = -a1 * sim[t - 1] + b1 * u[t - 1] + cv * u[t - 1] * v[t - 1] + cs * np.sign(sim[t - 1])
    np.testing.assert_allclose(m.predict(val)[1:], sim[1:], rtol=1e-9, atol=1e-9)


def test_effect_grammar_for_thresholds_and_parts():
    rng = np.random.default_rng(5)
    u = rng.uniform(-1, 1, 400)
    data = arxid.IOData(rng.standard_normal(400), u, 0.1)
    m = arxid.arx(data, 1, 1, 0, effects=["dz(u1,0.4)", "pos(u1)"])
    phi = np.column_stack(
        [-data.y[:-1], u[1:], np.sign(u[1:]) * np.maximum(np.abs(u[1:]) - 0.4, 0), np.maximum(u[1:], 0)]
    )
    np.testing.assert_allclose(m.parameters_, np.linalg.lstsq(phi, data.y[1:], rcond=None)[0], rtol=1e-8)
    sat = arxid.arx(data, 1, 1, 0, effects=["sat(u1,0.4)", "neg(u1)"])
    phi[:, 2], phi[:, 3] = np.clip(u[1:], -0.4, 0.4), np.minimum(u[1:], 0)
    np.testing.assert_allclose(sat.parameters_, np.linalg.lstsq(phi, data.y[1:], rcond=None)[0], rtol=1e-8)
    with pytest.raises(arxid.OrderError, match="positive number"):
        arxid.arx(data, 1, 1, 0, effects=["dz(u1,0)"])
    with pytest.raises(arxid.OrderError, match="apply to inputs"):
        arxid.arx(data, 1, 1, 0, effects=["sat(y,1)"])


def test_candidates_follow_the_signal_kinds():
    data = dc_motor(0)
    c = auto_candidates(arxid.arx(data, 1, 1, 1), data)
    assert {"sign(y)", "abs(y)", "sign(dy)", "dz(duty)", "sat(duty)", "pos(duty)"} <= set(c)
    # A one-way speed (never changes sign) gets no sign(y) (it would be an offset) and no pos().
    one_way = arxid.IOData(np.abs(data.y) + 1, np.abs(data.u[:, 0]), 0.01)
    c1 = auto_candidates(arxid.arx(one_way, 1, 1, 1), one_way)
    assert "sign(y)" not in c1 and "pos(u1)" not in c1 and "dz(u1)" in c1
    # An integrated output is a position: friction is sign(dy), never sign(y).
    pos = arxid.IOData(np.cumsum(data.y) * 0.01, data.u, 0.01)
    m = arxid.arx(pos, 2, 1, 1)
    assert np.any(np.abs(m.poles() - 1) < 1e-3)
    assert "sign(y)" not in auto_candidates(m, pos) and "sign(dy)" in auto_candidates(m, pos)
    # Every candidate has its physics in the catalogue.
    for label in c:
        assert physics(label, data), label


def test_an_effect_already_in_the_model_is_not_named_again():
    est, val = dc_motor(0).split(0.6)
    m = arxid.arx(est, 1, 1, 1, effects=["sign(y)"])
    d = diagnose(m, est, val, candidates=["sign(y)+const", "const", "duty*vbat"])
    assert [s.effect for s in d.suspects].count("const") == 1
    assert not any(s.effect.startswith("sign(y)") for s in d.suspects)


def test_docs_table_lists_every_candidate():
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "diagnostics.md").read_text(encoding="utf-8")
    for entry in CATALOGUE:
        assert f"`{entry.written}`" in text, entry.written


def test_candidate_columns_read_off_one_effect_equal_the_regressor_columns():
    """The scoring builds a one-effect candidate's columns from that effect's own column (or, for
    an output term, from the output) instead of the input matrix of the model with it; they are the
    regressor columns of that model, bit for bit, on a record of two experiments with a logged
    signal, for a model that already has an effect."""
    from arxid.diagnosis.extension import candidate_list, layout_for
    from arxid.diagnosis.scoring import Scoring
    from arxid.models.regressors import regressor_columns, regressor_names

    rng = np.random.default_rng(4)
    parts = []
    for _ in range(2):
        n = 1500
        u, vbat = rng.uniform(-1, 1, (n, 2)), 11 + rng.standard_normal(n)
        y = np.zeros(n)
        for t in range(1, n):
            y[t] = (
                0.7 * y[t - 1] + 0.4 * u[t - 1, 0] * vbat[t - 1] / 11 + 0.2 * u[t - 1, 1] + 0.01 * rng.standard_normal()
            )
        parts.append(arxid.IOData(y + 1.0, u, ts=0.01, extra={"vbat": vbat}))
    for data in (arxid.IOData.merge(parts), parts[0]):  # rows gathered, and rows as strided views
        model = arxid.ArxModel(na=2, nb=(2, 1), nk=(1, 2), effects=("u1*vbat",)).fit(data)
        sc = Scoring(model, data, candidate_list("auto", model, data)[0])
        read_off = 0
        for c in sc.prepared:
            z = sc._effect_columns(c)
            if z is None:
                continue
            read_off += 1
            lay = layout_for(c, model, data)[1]
            names = regressor_names(data.output_name, c.na, lay)
            new = [i for i, nm in enumerate(names) if nm not in sc.base_names]
            np.testing.assert_array_equal(z, regressor_columns(data, c.na, lay, sc.rows0, new), err_msg=c.label)
        assert read_off >= 10  # input effects, a logged signal, const/time and output terms


@pytest.mark.parametrize("collinear", [False, True])
def test_coefficients_from_cross_products_equal_the_least_squares_fit(collinear):
    """The coefficients of y on [Φ | z] from the partitioned normal equations are numpy's lstsq
    fit; ill-conditioned blocks give None (the caller fits the columns themselves)."""
    from arxid.diagnosis.added_variable import AddedVariableTest

    rng = np.random.default_rng(8)
    n = 5000
    phi = rng.standard_normal((n, 4)) * [1.0, 100.0, 0.01, 1.0]
    if collinear:
        phi[:, 3] = phi[:, 0] - 2.0 * phi[:, 1]
    z = np.column_stack([np.maximum(phi[:, 0], 0.0), rng.standard_normal(n)])
    y = phi @ [1.0, -0.5, 30.0, 0.2] + z @ [0.7, -0.1] + 0.05 * rng.standard_normal(n)
    test = AddedVariableTest(phi, y)
    got = test.coefficients(z)
    if collinear:
        assert got is None  # the rank-deficient regressors: the caller fits
        return
    want = np.linalg.lstsq(np.column_stack([phi, z]), y, rcond=None)[0]
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    assert test.coefficients(np.column_stack([phi[:, 1], z[:, 0]])) is None  # a column the model has


def test_a_power_is_squared_and_multiplied_as_the_core_does():
    """Regressors y^p and u^p are written by squaring and multiplying, the order of the core's
    powi (its Rust test holds it to that): the same bits in the regression and in the simulation."""
    from arxid.models.effects import integer_power

    x = np.random.default_rng(8).standard_normal(5000) * 4.0
    for p in range(1, 8):
        want = np.empty_like(x)
        for i, v in enumerate(x):
            r, a, b = 1.0, float(v), p
            while True:
                if b & 1:
                    r *= a
                b >>= 1
                if b == 0:
                    break
                a *= a
            want[i] = r
        got = integer_power(x, p)
        assert np.array_equal(got, want) and got is not x
        np.testing.assert_allclose(got, x**p, rtol=1e-15 * p)
