"""The shortcut of a shape scan gives the refit's one-step loss: the shaped lags projected against
the model's other columns, on seeded Hammerstein plants (a dead zone, a saturation, a power law)
with two inputs, an offset and an output term; and +inf wherever the refit refuses the value."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.diagnosis.shape_cost import ShapeCost


def plant(seed: int, n: int = 1500) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u1 = np.repeat(rng.uniform(-1.5, 1.5, n // 10 + 1), 10)[:n]
    u2 = rng.standard_normal(n)
    dz = np.sign(u1) * np.maximum(np.abs(u1) - 0.4, 0.0)
    y = lfilter([0, 0.3, 0.15], [1, -1.2, 0.45], dz) + lfilter([0, 0.2], [1, -0.5], u2) + 0.3
    y += 0.01 * rng.standard_normal(n)
    return arxid.IOData(y, np.column_stack([u1, u2]), 0.01, input_names=["u", "w"])


@pytest.mark.parametrize(
    ("kind", "values", "effects", "const"),
    [
        ("dead zone", [(0.1,), (0.4,), (0.77,), (1.2,)], [], True),
        ("saturation", [(-0.6, 0.8), (-1.0, 0.3), (-2.0, 1.0)], [], False),
        ("signed power", [(0.5,), (1.0,), (2.3,)], ["y^2"], True),
    ],
)
def test_shortcut_equals_the_refit(kind, values, effects, const):
    data = plant(1)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1], effects=effects).fit(data)
    cost = ShapeCost(model, data, kind, "u", const)
    first = cost(values[0])  # refitted, and the shortcut checked against it
    assert cost._fast is not None
    assert first == cost.refit(arxid.models.input_shapes.InputShape(kind, "u", values[0]))
    for v in values:
        shape = arxid.models.input_shapes.InputShape(kind, "u", v)
        assert cost(v) == pytest.approx(cost.refit(shape), rel=1e-10)


@pytest.mark.parametrize("effects", [[], ["y^2"]])
def test_the_families_of_one_model_share_one_projection_to_the_bit(effects):
    """The scans of a diagnosis share the projection of the model's other columns: each family's
    losses equal those of its own projection, to the bit (the missing samples' rows too)."""
    data = plant(4)
    y = data.y.copy()
    y[[300, 301]] = np.nan
    data = arxid.IOData(y, data.u, 0.01, input_names=["u", "w"])
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1], effects=effects).fit(data)
    families = [
        ("signed power", [(1.0,), (0.7,), (1.6,)]),
        ("saturation", [(-1.6, 1.6), (-0.9, 1.2), (-2.0, 0.4)]),
        ("dead zone", [(0.0,), (0.35,), (0.8,)]),
    ]
    shared: dict = {}
    for kind, values in families:
        alone = ShapeCost(model, data, kind, "u", True)
        together = ShapeCost(model, data, kind, "u", True, shared)
        assert together.many(values) == alone.many(values)
        assert together._fast is not None
    assert len(shared) == 1


def test_refused_values_cost_infinity_as_the_refit_does():
    """A dead zone wider than the input leaves zero columns; the refit calls them rank deficient."""
    data = plant(2)
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(data)
    cost = ShapeCost(model, data, "dead zone", "u", True)
    cost((0.2,))
    assert cost._fast is not None
    shape = arxid.models.input_shapes.InputShape("dead zone", "u", (5.0,))
    assert math.isinf(cost.refit(shape))
    assert math.isinf(cost((5.0,)))


def test_missing_samples_keep_the_refits_rows():
    data = plant(3)
    y = data.y.copy()
    y[[100, 101, 700]] = np.nan
    data = arxid.IOData(y, data.u, 0.01, input_names=["u", "w"])
    model = arxid.ArxModel(na=2, nb=[2, 1], nk=[1, 1]).fit(data)
    cost = ShapeCost(model, data, "dead zone", "u", False)
    cost((0.3,))
    assert cost._fast is not None
    for c in (0.35, 0.5):
        shape = arxid.models.input_shapes.InputShape("dead zone", "u", (c,))
        assert cost((c,)) == pytest.approx(cost.refit(shape), rel=1e-10)


@pytest.mark.parametrize("rows", [50, 4096 * 3, 4096 * 5 + 17, 300_017])
def test_the_projected_factor_is_numpys_qr_of_the_projected_columns(rows):
    """The core's R of [Z − Q(QᵀZ) | y⊥] (two passes, blocks of rows, every core from 2^18 samples)
    against numpy's QR of the projection written out, on nearly dependent columns too."""
    from arxid._base.orthonormal import projected_r

    rng = np.random.default_rng(rows)
    q = np.linalg.qr(rng.standard_normal((rows, 3)))[0]
    y = rng.standard_normal(rows)
    y -= q @ (q.T @ y)
    mix = np.array([[1.0, 0.9, 0.0], [0.0, 0.1, 0.0], [0.0, 0.0, 1e-3]])
    z = rng.standard_normal((rows, 3)) @ mix + q @ rng.standard_normal((3, 3))
    got, dependent = projected_r(q, y, z)
    want = np.linalg.qr(np.column_stack([z - q @ (q.T @ z), y]), mode="r")
    signs = np.sign(np.diag(got)) * np.sign(np.diag(want))
    np.testing.assert_allclose(signs[:, None] * got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    assert not dependent.any()
    z[:, 1] = q @ [1.0, -2.0, 0.5]  # in the basis's span
    z[:, 2] = 3.0 * z[:, 0]  # a multiple of a column before it
    assert projected_r(q, y, np.asfortranarray(z))[1].tolist() == [False, True, True]


def test_a_tall_basis_is_numpys_projection_written_over_the_columns():
    """From 2^17 rows Q is the columns times R⁻¹, twice, in place: the same projections as numpy's Q
    (on nearly dependent columns too), and a column the others span is refused alike."""
    from arxid._base.orthonormal import _LEAN_ROWS, orthonormal_basis

    rng = np.random.default_rng(7)
    a = rng.standard_normal((_LEAN_ROWS + 999, 5))
    a[:, 3] = a[:, 2] + 1e-5 * a[:, 3]
    y = rng.standard_normal(a.shape[0])
    want, _ = np.linalg.qr(a)
    columns = a.copy()
    got = orthonormal_basis(columns, overwrite=True)
    assert got is columns
    np.testing.assert_allclose(got.T @ got, np.eye(5), atol=1e-13)
    np.testing.assert_allclose(got @ (got.T @ y), want @ (want.T @ y), atol=1e-11)
    a[:, 4] = a[:, 0] - 2 * a[:, 1]
    assert orthonormal_basis(a) is None
