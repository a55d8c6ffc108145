"""The encompassing test of a shape from one reduction of the model's columns gives the refit's F
statistic: seeded two-input plants whose first input acts through a dead zone, with and without an
offset, an additive effect of the input, missing samples, and a modulating signal with gaps (where
the refit decides). The shape models fitted from one envelope factor equal their own fits."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid._base.orthonormal import orthonormal_basis
from arxid.diagnosis.shape_beside import BesideFit
from arxid.diagnosis.shapes import ShapeFits, _f_test
from arxid.exceptions import ArxidError
from arxid.models.input_shapes import InputShape


def plant(seed: int, n: int = 2000, gaps: bool = False) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u1 = np.repeat(rng.uniform(-1.5, 1.5, n // 10 + 1), 10)[:n]
    u2 = rng.standard_normal(n)
    v = 4.0 - np.linspace(0.0, 0.6, n) + 0.01 * rng.standard_normal(n)
    dz = np.sign(u1) * np.maximum(np.abs(u1) - 0.4, 0.0)
    y = lfilter([0, 0.3, 0.15], [1, -1.2, 0.45], dz * v / 4) + lfilter([0, 0.2], [1, -0.5], u2) + 0.3
    y += 0.01 * rng.standard_normal(n)
    if gaps:
        y[[100, 101, 700, 1500]] = np.nan
        v[[300, 1200]] = np.nan
    return arxid.IOData(y, np.column_stack([u1, u2]), 0.01, input_names=["u", "w"], extra={"v": v})


SHAPES = [
    InputShape("dead zone", "u", (0.4,)),
    InputShape("dead zone", "u", (0.9,)),
    InputShape("signed power", "u", (2.0,)),
    InputShape("saturation", "u", (-0.7, 0.8)),
    InputShape("product", "u", (), "v"),
    InputShape("signed power", "w", (0.5,)),
]


def f_statistic(model: arxid.ArxModel, beside, q: int) -> float:
    return _f_test(model.rss_, beside.rss, q, beside.n_rows - beside.n_params)[0]


@pytest.mark.parametrize(("effects", "gaps"), [((), False), ((), True), (("u^2",), False), (("const",), True)])
def test_the_f_statistic_equals_the_refits(effects, gaps):
    data = plant(4, gaps=gaps)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1], effects=effects).fit(data)
    fit = BesideFit(model, data)
    offsets = (False,) if "const" in effects else (False, True)
    for shape in SHAPES:
        for const in offsets:
            q = model.nb_[["u", "w"].index(shape.signal)] + int(const)
            fast, exact = fit(shape, const), fit.refit(shape, const)
            assert fast.n_rows == exact.n_rows and fast.n_params == exact.n_params
            assert fast.rss == pytest.approx(exact.rss, rel=1e-10)
            assert f_statistic(model, fast, q) == pytest.approx(f_statistic(model, exact, q), rel=1e-9)
    # the shortcut stood for the refits (a modulating signal with gaps is refitted: other rows)
    assert fit._basis is not None and fit._lags[0] is not None and fit._lags[1] is not None


def test_the_dead_zone_is_the_significant_shape():
    data = plant(5)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(data)
    fit = BesideFit(model, data)
    f_dz = f_statistic(model, fit(InputShape("dead zone", "u", (0.4,)), False), 2)
    f_w = f_statistic(model, fit(InputShape("signed power", "w", (0.5,)), False), 1)  # w acts linearly
    assert f_dz > 100 * f_w


def test_a_shape_the_model_spans_is_refused_as_the_refit_refuses_it():
    """A dead zone wider than the input gives zero columns: rank deficient to the refit and here."""
    data = plant(6)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(data)
    fit = BesideFit(model, data)
    wide = InputShape("dead zone", "u", (5.0,))
    with pytest.raises(ArxidError):
        fit.refit(wide, False)
    with pytest.raises(ArxidError):
        fit(wide, False)


@pytest.mark.parametrize("gaps", [False, True])
def test_the_shape_models_from_one_envelope_equal_their_own_fits(gaps):
    data = plant(7, gaps=gaps)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(data)
    pairs = [(shape, const) for shape in SHAPES for const in (False, True)]
    fits = ShapeFits(model, data, pairs)
    assert (fits.envelope is None) == gaps  # data with gaps: each refitted on its own rows
    for shape, const in pairs:
        got = fits.fit(shape, const)
        effects = [shape.effect] + (["const"] if const else [])
        own = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1], effects=effects).fit(data)
        assert got.regressor_names_ == own.regressor_names_ and got.n_rows_ == own.n_rows_
        np.testing.assert_allclose(got.parameters_, own.parameters_, rtol=1e-9, atol=1e-12)
        assert got.rss_ == pytest.approx(own.rss_, rel=1e-10)


def _reference_rss(model: arxid.ArxModel, data: arxid.IOData, shape: InputShape, const: bool) -> float:
    """numpy's least squares of y on the model's regressors, the shape's lags (read through the old
    numbered regressor, :func:`input_lags`) and the offset."""
    from arxid.diagnosis.shape_cost import input_lags
    from arxid.models.effects import compile_effects
    from arxid.models.regressors import regressor_matrix

    layout = compile_effects(model.effects, data, model.nb_, model.nk_)
    phi, y, rows = regressor_matrix(data, model.na_, layout, model.first_lag_)
    i = ["u", "w"].index(shape.signal)
    which, index, plain = input_lags(data, model.na_, layout, i, phi, rows)
    assert plain.sum() == model.nb_[i]
    other = data.signal(shape.other) if shape.other else None
    z = shape.evaluate(data.u[:, i], other)[index[:, plain]]
    x = np.column_stack([phi, z] + ([np.ones(rows.size)] if const else []))
    return float(np.sum((y - x @ np.linalg.lstsq(x, y, rcond=None)[0]) ** 2))


@pytest.mark.parametrize("seed", [11, 12, 13])
@pytest.mark.parametrize(("effects", "gaps"), [((), False), ((), True), (("u*v",), True)])
def test_the_shape_lags_read_from_the_layout_give_numpys_loss(seed, effects, gaps):
    """The shape's columns taken at the layout's lags (row t of lag k reads sample t − k) are those
    the numbered regressor found, on rows with gaps and beside an effect of the same input: the loss
    is numpy's least squares of the stacked columns to rounding."""
    data = plant(seed, gaps=gaps)
    if gaps:  # the shaped inputs themselves missing (the modulating signal's gaps are refitted)
        u = data.u.copy()
        u[[400, 401, 1800], 0] = np.nan
        u[[900], 1] = np.nan
        data = data.with_signals(u=u, input_names=["u", "w"])
    model = arxid.ArxModel(na=2, nb=[3, 2], nk=[1, 2], effects=effects).fit(data)
    fit = BesideFit(model, data)
    for shape in [s for s in SHAPES if s.kind != "product"]:
        for const in ("const" not in effects, False):
            got = fit(shape, const)
            assert got.rss == pytest.approx(_reference_rss(model, data, shape, const), rel=1e-12)
    assert fit._basis is not None and fit._lags == {0: (1, 2, 3), 1: (2, 3)}


@pytest.mark.parametrize(("seed", "gaps"), [(21, False), (22, True)])
def test_a_long_records_basis_from_the_models_own_factor_gives_numpys_loss(seed, gaps, monkeypatch):
    """From 131,072 rows the basis starts from the fit's (ΦᵀΦ)⁻¹ (no fresh QR of Φ, which would
    fail here): a slow plant (poles at 0.95, lags of y close to collinear), with and without gaps."""
    from arxid.diagnosis import shape_beside

    def from_the_fit(columns, overwrite=False, r=None):
        assert r is not None, "the basis was not taken from the model's factor"
        return orthonormal_basis(columns, overwrite, r)

    monkeypatch.setattr(shape_beside, "orthonormal_basis", from_the_fit)
    data = plant(seed, n=140_000, gaps=gaps)
    y = lfilter([0, 0.05, 0.02], [1, -1.9, 0.9025], data.u[:, 0]) + 0.01 * data.y
    data = arxid.IOData(y, data.u, data.ts, input_names=["u", "w"], extra=data.extra)
    model = arxid.ArxModel(na=3, nb=[2, 2], nk=[1, 1], effects=("u*v",)).fit(data)
    fit = BesideFit(model, data)
    for shape in (InputShape("dead zone", "u", (0.4,)), InputShape("signed power", "w", (0.5,))):
        for const in (False, True):
            assert fit(shape, const).rss == pytest.approx(_reference_rss(model, data, shape, const), rel=1e-12)
    assert fit._basis is not None


def test_a_known_r_gives_the_fresh_qrs_basis_and_refuses_dependent_columns():
    """orthonormal_basis from a given R (a fit's) is the basis of a fresh QR to rounding; a column
    the rank rule calls dependent is refused from the given R too."""
    rng = np.random.default_rng(8)
    x = rng.standard_normal((140_000, 4)) @ np.array([[1, 0.99, 0, 0], [0, 0.1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1e3]])
    r = np.linalg.cholesky(x.T @ x).T
    fresh, given = orthonormal_basis(x.copy()), orthonormal_basis(x.copy(), r=r)
    assert fresh is not None and given is not None
    np.testing.assert_allclose(given @ (given.T @ x[:, 1]), x[:, 1], rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.abs(given.T @ fresh), np.eye(4), rtol=0, atol=1e-12)
    x[:, 1] = 2 * x[:, 0]
    assert orthonormal_basis(x.copy(), r=np.linalg.qr(x, mode="r")) is None


@pytest.mark.parametrize("seed", [31, 32, 33])
@pytest.mark.parametrize("effects", [(), ("u^2",), ("u*v",), ("const",), ("y^3",)])
def test_the_beside_fits_from_the_shape_models_envelope_equal_the_refits(seed, effects):
    """With the model among the shape models' envelope, each shape beside the model is a
    sub-structure of its factor: the refit's loss, rows and parameters (no basis is built), beside
    an additive effect of the same input, an offset and an output term."""
    data = plant(seed)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1], effects=effects).fit(data)
    offsets = (False,) if "const" in effects else (False, True)
    pairs = [(shape, const) for shape in SHAPES for const in offsets]
    fits, fit = ShapeFits(model, data, pairs), BesideFit(model, data)
    for shape, const in pairs:
        try:
            exact = fit.refit(shape, const)
        except ArxidError:  # through(u*v) beside u*v: the same columns
            with pytest.raises(ArxidError):
                fits.beside(shape, const)
            continue
        got = fits.beside(shape, const)
        assert got is not None
        assert (got.n_rows, got.n_params) == (exact.n_rows, exact.n_params)
        assert got.rss == pytest.approx(exact.rss, rel=1e-10)
    assert fit._basis is None  # never needed
    wide = InputShape("dead zone", "u", (5.0,))  # zero columns: refused as the refit refuses them
    wide_fits = ShapeFits(model, data, [(wide, False), (SHAPES[0], False)])
    with pytest.raises(ArxidError):
        fit.refit(wide, False)
    with pytest.raises(ArxidError):
        wide_fits.beside(wide, False)


def test_without_an_envelope_the_beside_fit_is_the_basis():
    """Data with gaps have no envelope: the beside fit comes from the model's basis."""
    data = plant(34, gaps=True)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(data)
    fits = ShapeFits(model, data, [(SHAPES[0], False), (SHAPES[2], True)])
    assert fits.envelope is None and fits.beside(SHAPES[0], False) is None


def test_the_beside_fit_from_the_envelope_tests_the_shape_as_written():
    """A scanned parameter has more digits than the effect's text: the beside fit from the envelope
    is that of the shape as its effect writes it (four significant digits), the shape the
    validation test and the judge's refit fit, to numpy's least squares (1e-10)."""
    data = plant(35)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(data)
    scanned = InputShape("dead zone", "u", (0.4123456789,))
    written = InputShape("dead zone", "u", (0.4123,))
    assert scanned.effect == written.effect
    fits = ShapeFits(model, data, [(scanned, False), (scanned, True)])
    for const in (False, True):
        got = fits.beside(scanned, const)
        assert got is not None
        assert got.rss == pytest.approx(_reference_rss(model, data, written, const), rel=1e-10)
