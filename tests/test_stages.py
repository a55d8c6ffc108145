"""Two-stage sweeps (arxid.selection.stages): stage 1 ranks every structure by its one-step validation error
from the R factors (as MATLAB's arxstruc), stage 2 fits and simulates the best ``top`` exactly as an
exhaustive sweep does; grids over the memory or time budget are refused before anything is built."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.exceptions import OrderError
from arxid.selection import stages

GRID = dict(na=range(1, 4), nb=[range(1, 3), range(0, 3)], nk=[range(0, 4), range(1, 3)])


def _miso(n, seed, noise=0.05):
    """Two inputs: y = B1/A u1(t-2) + B2/A u2(t-1) + e/A."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 2))
    a = [1, -1.3, 0.45]
    y = lfilter([0, 0, 0.5, 0.2], a, u[:, 0]) + lfilter([0, -0.4], a, u[:, 1])
    y += lfilter([1], a, noise * rng.standard_normal(n))
    return arxid.IOData(y, u, ts=0.01)


@pytest.fixture(scope="module")
def data():
    return _miso(4000, 1), _miso(3000, 2)


@pytest.fixture(scope="module")
def exhaustive(data):
    est, val = data
    return arxid.sweep(est, **GRID, validation=val, progress=False, top=None)


def _key(res, i):
    return (int(res.na[i]), tuple(int(v) for v in res.nb[i]), tuple(int(v) for v in res.nk[i]))


def test_two_stage_equals_exhaustive_when_top_covers_the_grid(data, exhaustive):
    est, val = data
    n = len(exhaustive)
    assert n == 3 * 2 * 3 * 4 * 2
    assert (exhaustive.stage == 2).all()
    for top in (n, n + 5):
        res = arxid.sweep(est, **GRID, validation=val, progress=False, top=top)
        assert [_key(res, i) for i in range(n)] == [_key(exhaustive, i) for i in range(n)]
        np.testing.assert_array_equal(res.rms_val, exhaustive.rms_val)
        assert (res.stage == 2).all()


def test_stage_two_rows_are_the_exhaustive_rows_of_the_best_by_one_step_error(data, exhaustive):
    est, val = data
    top = 10
    res = arxid.sweep(est, **GRID, validation=val, progress=False, top=top)
    assert len(res) == len(exhaustive)
    assert int((res.stage == 2).sum()) == top
    # Stage 2 took the best `top` by one-step validation error of the exhaustive sweep.
    by_one_step = np.argsort(exhaustive.rms_val_one_step, kind="stable")[:top]
    chosen = {_key(exhaustive, i) for i in by_one_step}
    assert {_key(res, i) for i in range(top)} == chosen
    # ... ranked among themselves as the exhaustive sweep ranks them, with the same numbers.
    ex_rank = {_key(exhaustive, i): i for i in range(len(exhaustive))}
    ranks = [ex_rank[_key(res, i)] for i in range(top)]
    assert ranks == sorted(ranks)
    for i in range(top):
        j = ex_rank[_key(res, i)]
        np.testing.assert_array_equal(res.parameters[i], exhaustive.parameters[j])
        assert res.rms_val[i] == exhaustive.rms_val[j]
        assert res.rms_est[i] == exhaustive.rms_est[j]
    # Stage 1 rows: not simulated, ranked by one-step validation error, same losses and parameters.
    rest = np.arange(top, len(res))
    assert (res.stage[rest] == 1).all() and np.isnan(res.rms_val[rest]).all()
    assert (np.diff(res.rms_val_one_step[rest]) >= 0).all()
    for i in rest:
        j = ex_rank[_key(res, i)]
        assert res.rms_val_one_step[i] == pytest.approx(exhaustive.rms_val_one_step[j], rel=1e-10)
        assert res.fpe[i] == pytest.approx(exhaustive.fpe[j], rel=1e-10)
        np.testing.assert_allclose(res.parameters[i], exhaustive.parameters[j], rtol=1e-9, atol=1e-12)
    # best() only considers simulated structures; the table says which stage ranked each row.
    assert res.best().nb == exhaustive.best().nb
    table = res.table(n=len(res), sanity=False)
    assert "two stages" in table and "stage" in table.splitlines()[2]
    assert res.to_dict(sanity=False)["structures"][-1]["stage"] == 1


def _arxstruc(est, val, grid, lag):
    """MATLAB arxstruc re-implemented in numpy: one Gram matrix of the largest regressor on the
    estimation rows, then per structure a Cholesky solve and the validation loss as a quadratic form
    of the validation Gram matrix (MATLAB's V, the mean squared one-step error)."""
    na_max = max(s[0] for s in grid)
    m = est.n_inputs
    lo = [min(s[2][i] for s in grid) for i in range(m)]
    hi = [max(s[2][i] + s[1][i] - 1 for s in grid) for i in range(m)]

    def regressor(d):
        rows = np.arange(lag, d.n_samples)
        cols = [-d.y[rows - i] for i in range(1, na_max + 1)]
        for i in range(m):
            cols += [d.u[rows - k, i] for k in range(lo[i], hi[i] + 1)]
        return np.column_stack(cols + [d.y[rows]])

    a, av = regressor(est), regressor(val)
    g, gv, q = a.T @ a, av.T @ av, a.shape[1] - 1
    out = []
    for na, nb, nk in grid:
        cols = list(range(na))
        off = na_max
        for i in range(m):
            cols += [off + nk[i] - lo[i] + j for j in range(nb[i])]
            off += hi[i] - lo[i] + 1
        c = np.linalg.cholesky(g[np.ix_(cols, cols)])
        theta = np.linalg.solve(c.T, np.linalg.solve(c, g[cols, q]))
        v = theta @ gv[np.ix_(cols, cols)] @ theta - 2 * theta @ gv[cols, q] + gv[q, q]
        out.append(v / len(av))
    return np.array(out)


def test_stage_one_equals_a_numpy_arxstruc(data):
    est, val = data
    grid3 = dict(na=range(0, 3), nb=[range(1, 3), range(1, 4)], nk=[range(0, 3), range(0, 4)])
    res = arxid.sweep(est, **grid3, validation=val, progress=False, top=1, sort_by="val_one_step")
    assert int((res.stage == 1).sum()) == len(res) - 1
    grid = [(_key(res, i)) for i in range(len(res))]
    loss = _arxstruc(est, val, grid, res.first_lag)
    np.testing.assert_allclose(res.rms_val_one_step**2, loss, rtol=1e-8)
    # The ranking by one-step validation error is arxstruc's ordering (selstruc's table).
    assert (np.diff(loss) >= -1e-12 * loss[:-1]).all()


_REFUSAL = """
import tracemalloc
import numpy as np
import arxid
from arxid._base import _core
from test_stages import _miso

def no_core(*args, **kwargs):
    raise AssertionError("the core was called")

_core.sweep = no_core
est, val = _miso(4000, 1), _miso(3000, 2)
big = _miso(400, 3)
three = arxid.IOData(big.y, np.column_stack([big.u, big.u[:, 0]]), ts=0.01)
grid = dict(na=range(1, 4), nb=[range(1, 3), range(0, 3)], nk=[range(0, 4), range(1, 3)])
sweep = arxid.sweep  # loads the sweep's modules (arxid's names load on first use) before the count starts
tracemalloc.start()
for kw in (
    dict(data=three, na=range(1, 11), nb=range(1, 41), nk=range(0, 60)),  # 1.4e11 structures: memory
    dict(data=est, validation=val, top=None, max_seconds=1e-5, **grid),  # 144 simulated: beyond 10 us
):
    data = kw.pop("data")
    try:
        sweep(data, progress=False, **kw)
    except arxid.DataError as exc:
        print(exc)
print("peak", tracemalloc.get_traced_memory()[1])
"""


def test_a_grid_over_the_budget_is_refused_before_anything_is_built():
    # In a fresh interpreter: tracemalloc counts every thread's allocations, and a test session may
    # hold background threads (a Dask client's event loop) that allocate at any time.
    out = subprocess.run(
        [sys.executable, "-c", _REFUSAL],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=os.path.dirname(__file__),
        check=True,
    ).stdout
    assert "too large: 138,240,000,000 structures" in out
    assert "too slow to sweep: 144 structures (all simulated" in out
    peak = int(out.rsplit("peak", 1)[1])
    assert peak < 2**20, f"{peak} bytes allocated before refusing"


def test_estimated_time_counts_each_stage():
    one = stages.estimated_seconds(1_000_000, None, 10, 31, 400_000, 200_000, 1)
    two = stages.estimated_seconds(1_000_000, 1000, 10, 31, 400_000, 200_000, 1)
    assert one == pytest.approx(1e6 * 2e5 * 12 * 1e-10 + 2 * 4e5 * 31**2 * 1e-10)
    assert two == pytest.approx(1e3 * 2e5 * 12 * 1e-10 + 1e6 * 5e-7 + 2 * 4e5 * 31**2 * 1e-10)
    assert stages.estimated_seconds(100, 1000, 10, 31, 400_000, 200_000, 2) == pytest.approx(
        (100 * 2e5 * 12 * 1e-10 + 2 * 4e5 * 31**2 * 1e-10) / 2
    )


@pytest.mark.parametrize("top", [0, -3, 2.5, True, "all"])
def test_top_must_be_a_positive_integer_or_none(data, top):
    est, _ = data
    with pytest.raises(OrderError, match="top must be an integer >= 1"):
        arxid.sweep(est, na=1, nb=1, nk=1, progress=False, top=top)
