"""A block ill-conditioned beside well-conditioned regressors is stripped of them by the Cholesky
solve, refined once, and tested from the blocked R of the stripped block and the residual: no
orthonormal basis of the regressors (an n × p copy beside them) and no Q of the block. The numbers
are those of the basis path (numpy's QR of the regressors, then of the stripped block) to 1e-10,
and a rank-deficient block counts the same columns."""

from __future__ import annotations

import math

import numpy as np
import pytest

import arxid
import arxid.diagnosis.nonlinearity as nl
from arxid._base.probabilities import f_sf
from arxid.diagnosis.added_variable import AddedVariableTest


def _basis_test(phi: np.ndarray, y: np.ndarray, z: np.ndarray) -> tuple[float, float, float, int] | None:
    """The basis path, written out: Q of Φ, the normalised block minus Q Q'z, its QR, and Q'e."""
    q = np.linalg.qr(phi)[0]
    e = y - q @ (q.T @ y)
    rss0 = float(e @ e)
    z = z[:, np.linalg.norm(z, axis=0) > 0]
    z = z / np.linalg.norm(z, axis=0)
    zr = z - q @ (q.T @ z)
    rn = np.linalg.norm(zr, axis=0)
    if not (rn > 1e-7).any():
        return None
    zr = zr[:, rn > 1e-7] / rn[rn > 1e-7]
    kept: list[int] = []
    for j in range(zr.shape[1]):  # a column counts when it is 1e-7 away from those counted before it
        if abs(np.linalg.qr(zr[:, [*kept, j]])[1][-1, -1]) > 1e-7:
            kept.append(j)
    qz = np.linalg.qr(zr[:, kept])[0]
    k, dof = qz.shape[1], phi.shape[0] - phi.shape[1] - qz.shape[1]
    drss = float(np.sum((qz.T @ e) ** 2))
    f = (drss / k) / ((rss0 - drss) / dof)
    return math.sqrt(drss / rss0), f, float(f_sf(f, k, dof)), k


def _regression(seed: int, n: int = 30_000, p: int = 8) -> tuple[np.ndarray, np.ndarray, np.random.Generator]:
    rng = np.random.default_rng(seed)
    phi = rng.standard_normal((n, p)) * np.logspace(0, 2, p)
    phi[:, -1] = 1.0  # a constant, as the dependence test's design has
    y = phi @ rng.standard_normal(p) + 0.3 * rng.standard_normal(n) + 0.006 * phi[:, 0] ** 2
    return phi, y, rng


def _blocks(phi: np.ndarray, rng: np.random.Generator) -> dict[str, np.ndarray]:
    n, p = phi.shape
    w = phi[:, 0] ** 2 + 0.2 * rng.standard_normal(n)
    inside, v = phi @ rng.standard_normal(p), rng.standard_normal(n)
    return {
        # one column 1e-5 (relative) away from the regressors' span: the cross-products cannot test it
        "ill-conditioned": np.column_stack([w, inside + 1e-5 * np.linalg.norm(inside) / math.sqrt(n) * v]),
        # the second column is the first plus regressors: one independent column
        "rank-deficient": np.column_stack([w, 3.0 * w + inside, rng.standard_normal(n)]),
        # nothing beyond the regressors
        "collinear": np.column_stack([inside, phi[:, 1] - 2 * phi[:, 2]]),
    }


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_stripped_block_gives_the_basis_paths_numbers(seed, monkeypatch):
    phi, y, rng = _regression(seed)
    test = AddedVariableTest(phi, y)
    assert test.gram is not None  # well-conditioned regressors: the Cholesky path
    stripped = []
    monkeypatch.setattr(test, "_stripped", lambda *a: stripped.append(1) or type(test)._stripped(test, *a))
    for name, z in _blocks(phi, rng).items():
        got, why = test.test(z)
        want = _basis_test(phi, y, z)
        if name == "collinear":
            assert got is None and want is None and "collinear" in why
            continue
        assert got is not None and want is not None
        np.testing.assert_allclose([got.score, got.f_statistic, got.p_value], want[:3], rtol=1e-10)
        assert got.n_columns == want[3] == 2  # the rank-deficient block's second column does not count
        assert 1e-12 < got.p_value < 1e-2
    assert len(stripped) == 3  # every block took the stripped path
    assert test._q is None  # and no orthonormal basis of the regressors was formed


def test_the_offset_blocks_are_stripped_alike():
    phi, y, rng = _regression(3)
    blocks = list(_blocks(phi[:, :-1], rng).values())[:2]  # without the constant, [z | 1] is a new block
    test = AddedVariableTest(phi[:, :-1], y)
    for (got, _), z in zip(test.tests(blocks, offset=True), blocks, strict=True):
        want = _basis_test(phi[:, :-1], y, np.column_stack([z, np.ones(len(z))]))
        assert got is not None and want is not None and got.n_columns == want[3]
        np.testing.assert_allclose([got.score, got.f_statistic, got.p_value], want[:3], rtol=1e-10)
    assert test._q is None


def _output_term_plant(seed: int) -> arxid.IOData:
    """Two inputs and an output term y(t-1)^3, the second input positive (so the output's mean is not
    zero and its standardised cube, beside y(t-1)^3, y(t-1) and the constant, is its square: a
    rank-deficient block), and a square of the second input that the model misses."""
    rng = np.random.default_rng(seed)
    n = 8000
    u1, u2 = rng.uniform(-1, 1, n), np.repeat(rng.uniform(0, 2, n // 10), 10)
    e = 0.05 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.2 * y[t - 1] - 0.5 * y[t - 2] + 0.5 * u1[t - 1] + 0.5 * u2[t - 2] + 0.03 * u2[t - 2] ** 2
        y[t] += e[t] - 0.02 * y[t - 1] ** 3
    return arxid.IOData(y, np.column_stack([u1, u2]), ts=0.01)


def _basis_strip(self: AddedVariableTest, zn: np.ndarray) -> np.ndarray:
    return zn - self.q @ (self.q.T @ zn)


@pytest.mark.parametrize("seed", [0, 1])
def test_the_dependence_test_names_the_same_signals(seed, monkeypatch):
    data = _output_term_plant(seed)
    model = arxid.arx(data, 2, [1, 1], [1, 2], effects=["y^3"])
    p_values, dropped = [], []
    holm = nl.holm
    monkeypatch.setattr(nl, "holm", lambda p: p_values.append(np.array(p)) or holm(p))
    stripped = AddedVariableTest._stripped

    def counted(self, z, keep, norms):
        res, why = stripped(self, z, keep, norms)
        dropped.append(res is not None and res.n_columns < keep.sum())
        return res, why

    monkeypatch.setattr(AddedVariableTest, "_stripped", counted)
    found = nl.nonlinear_dependence(model, data)
    monkeypatch.setattr(AddedVariableTest, "_strip", _basis_strip)
    with_basis = nl.nonlinear_dependence(model, data)
    assert any(dropped)  # a rank-deficient block took the stripped path
    assert [(d.signal, d.lags) for d in found] == [(d.signal, d.lags) for d in with_basis]
    assert [(d.signal, d.lags) for d in found] == [("u2", (2, 3))]  # the square of the input
    assert (p_values[0][:2] > 0.01).all()  # the output's lags: nothing found, p-values not at 0 or 1
    np.testing.assert_allclose(p_values[0], p_values[1], rtol=1e-10, atol=1e-300)


def test_the_share_of_a_block_nearly_explained_is_the_basis_paths():
    phi, y, rng = _regression(4)
    test = AddedVariableTest(phi, y)
    n = len(y)
    w, inside = phi[:, 0] ** 2 + 0.2 * rng.standard_normal(n), phi @ rng.standard_normal(phi.shape[1])
    z = np.column_stack([inside + 1e-6 * np.linalg.norm(inside) / math.sqrt(n) * w])
    got = test.share(z)  # too close to the regressors for its cross-products: stripped
    q = np.linalg.qr(phi)[0]
    zn = z / np.linalg.norm(z)
    zr = zn - q @ (q.T @ zn)
    v = zn.T @ test.e
    want = float(v @ np.linalg.solve(zr.T @ zr, v)) / test.rss0
    assert 1e-4 < got == pytest.approx(want, rel=1e-9)
    assert test._q is None
