"""The validation evidence of a shape, formed in one call of the core: each shape's Diebold–Mariano
test against the model's errors (kept once, squared) is the plain comparison of the two error series
(numpy's passes) to 1e-12, on two-input records with missing samples, short and long, free run and
k steps; the statistic is the textbook formula to rounding. A shape's series evaluated in place is
the formula's to the last bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.diagnosis.shapes import ValidationEvidence, validation_p
from arxid.models.input_shapes import InputShape
from arxid.selection import parsimony


def record(seed: int, n: int) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u1, u2 = rng.uniform(-1.5, 1.5, n), rng.standard_normal(n)
    dz = np.sign(u1) * np.maximum(np.abs(u1) - 0.3, 0.0)
    y = lfilter([0, 0.3, 0.15], [1, -1.2, 0.45], dz) + lfilter([0, 0.2], [1, -0.5], u2)
    y += 0.02 * rng.standard_normal(n)
    y[rng.integers(10, n, 5)] = np.nan
    u2[rng.integers(10, n, 3)] = np.nan
    return arxid.IOData(y, np.column_stack([u1, u2]), 0.01)


def textbook_dm(e_small: np.ndarray, e_best: np.ndarray) -> float:
    """DM = mean(d) / √(S / n), S the Bartlett-weighted autocovariances of d up to ⌊n^(1/3)⌋."""
    ok = np.isfinite(e_small) & np.isfinite(e_best)
    d = e_small[ok] ** 2 - e_best[ok] ** 2
    n, lag = d.size, int(d.size ** (1 / 3))
    dc = d - d.mean()
    s = sum((1.0 if k == 0 else 2 * (1 - k / (lag + 1))) * float(dc[k:] @ dc[: n - k]) for k in range(lag + 1)) / n
    return float(d.mean() / math.sqrt(s / n))


@pytest.mark.parametrize(("seed", "n"), [(1, 3000), (2, 3000), (3, parsimony._ONE_PASS_SAMPLES + 500)])
@pytest.mark.parametrize("horizon", [None, 5])
def test_each_shapes_p_value_is_the_plain_comparisons(seed, n, horizon):
    est, val = record(seed, n), record(seed + 50, n)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(est)
    evidence = ValidationEvidence(model, val, horizon, "zero")
    base = val.y - model.predict(val, horizon)
    for shape in (InputShape("dead zone", "u1", (0.3,)), InputShape("signed power", "u1", (1.5,))):
        fitted = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1], effects=[shape.effect]).fit(est)
        err = val.y - fitted.predict(val, horizon)
        assert evidence.p_value(fitted) == pytest.approx(validation_p(base, err), rel=1e-12, abs=1e-300)
        stat = parsimony.diebold_mariano(base, err).statistic
        assert stat == pytest.approx(textbook_dm(base, err), rel=1e-12)
        assert 0.5 * math.erfc(stat / math.sqrt(2)) == validation_p(base, err)
    assert evidence._squares is not None and np.isnan(evidence._squares).any()  # the gaps were left out


@pytest.mark.parametrize("seed", [6, 7, 8])
def test_the_cores_loss_differences_are_numpys(seed):
    """``_core.loss_difference``: the count, mean and centred lagged sums of numpy's passes, with
    missing and infinite errors left out, on short and long series (to 1e-12)."""
    rng = np.random.default_rng(seed)
    for n in (50, 3000, parsimony._ONE_PASS_SAMPLES + 77):
        y = rng.standard_normal(n)
        pred = y + 0.3 * rng.standard_normal(n) + 0.05 * np.sin(np.arange(n) / 40)
        base_err = 0.31 * rng.standard_normal(n)
        pred[rng.integers(0, n, 4)] = np.nan
        pred[rng.integers(0, n, 2)] = np.inf
        base_err[rng.integers(0, n, 3)] = np.nan
        err = y - pred
        ok = np.isfinite(err) & np.isfinite(base_err)
        d = base_err[ok] ** 2 - err[ok] ** 2
        lag = int(d.size ** (1 / 3))
        dc = d - d.mean()
        want = [float(dc[k:] @ dc[: d.size - k]) for k in range(lag + 1)]
        squares = np.where(np.isfinite(base_err), base_err**2, np.nan)
        count, mean, sums = arxid._base._core.loss_difference(y, squares, pred.copy())
        assert count == d.size and mean == pytest.approx(d.mean(), rel=1e-12)
        np.testing.assert_allclose(sums, want, rtol=0, atol=1e-12 * want[0])
        got = parsimony.comparison_from_sums(count, mean, sums)
        assert got.statistic == pytest.approx(parsimony.diebold_mariano(base_err, err).statistic, rel=1e-12)


def test_the_difference_test_centres_in_place_and_agrees_with_the_two_series():
    rng = np.random.default_rng(4)
    e1, e2 = rng.standard_normal(5000), 1.02 * rng.standard_normal(5000)
    d = e1**2 - e2**2
    got = parsimony.loss_difference_test(d)
    assert got == parsimony.diebold_mariano(e1, e2)
    assert abs(d.mean()) < 1e-15  # centred where it lies: no copy
    assert parsimony.loss_difference_test(np.ones(1)).n == 1


@pytest.mark.parametrize(
    ("kind", "params", "formula"),
    [
        ("signed power", (1.7,), lambda x: np.sign(x) * np.power(np.abs(x), 1.7)),
        ("signed power", (0.5,), lambda x: np.sign(x) * np.power(np.abs(x), 0.5)),
        ("dead zone", (0.4,), lambda x: np.sign(x) * np.maximum(np.abs(x) - 0.4, 0.0)),
        ("dead zone", (0.0,), lambda x: np.sign(x) * np.maximum(np.abs(x) - 0.0, 0.0)),
    ],
)
def test_a_shape_evaluated_in_place_is_the_formula_to_the_last_bit(kind, params, formula):
    x = np.random.default_rng(5).standard_normal(10001) * 2
    x[::7], x[3::11], x[5::13], x[1] = 0.0, -0.0, np.nan, 1e200
    with np.errstate(over="ignore", invalid="ignore"):
        got, want = InputShape(kind, "u1", params).evaluate(x), formula(x)
    assert np.array_equal(got.view(np.int64), want.view(np.int64))  # signed zeros and NaN too
