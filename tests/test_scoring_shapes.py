"""A threshold found by the scan is named ``dz`` or ``sat`` by the residual each leaves in place of
the input: the products of both from one pass over the model's regressors
(``_core.dead_zone_and_saturation_products``), each the same bits as from a pass of its own."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid._base import _core
from arxid.diagnosis.extension import candidate_list
from arxid.diagnosis.scoring import Scoring


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("width", [1, 3])
def test_both_shapes_in_one_pass_are_each_alone_to_the_bit(seed, width):
    rng = np.random.default_rng(seed)
    n = 20_000
    a, e = rng.standard_normal((n, 5)), rng.standard_normal(n)
    lagged = np.ascontiguousarray(rng.standard_normal((n, width)))
    lagged[::97] = 0.0  # sign(0) = 0
    ts = np.array([0.3 + 0.1 * seed, 0.8])
    cross, zz = _core.dead_zone_and_saturation_products(a, e, lagged, ts)
    for t, dead_zone in enumerate((True, False)):
        alone = _core.threshold_products(a, e, lagged, ts[t : t + 1], dead_zone)
        assert np.array_equal(cross[:, :, t], alone[0][:, :, 0])
        assert np.array_equal(zz[:, :, t], alone[1][:, :, 0])


def _record(seed: int, n: int = 6000, gaps: bool = False) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.uniform(-2, 2, (n, 2))
    x = np.sign(u[:, 0]) * np.maximum(np.abs(u[:, 0]) - 0.5, 0) + 0.4 * u[:, 1]
    y = lfilter([0, 0.5, 0.2], [1, -1.2, 0.4], x) + 0.01 * rng.standard_normal(n)
    if gaps:
        u[[100, 2000, 2001]] = np.nan
    return arxid.IOData(y, u, 0.01)


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("gaps", [False, True])
def test_the_residual_of_each_shape_is_that_of_its_own_pass(seed, gaps):
    d = _record(seed, gaps=gaps)
    model = arxid.ArxModel(na=2, nb=(2, 2), nk=(1, 1)).fit(d)
    sc = Scoring(model, d, candidate_list("auto", model, d)[0])
    keep = [j for j, nm in enumerate(sc.base_regressors) if not nm.startswith("u1(")]
    both = sc._both_shapes("u1", 0.5)
    assert set(both) == {"dz", "sat"}  # with gaps, the samples gathered on the model's rows
    for op in ("dz", "sat"):
        assert sc._shape_rss(op, keep, "u1", 0.5, both.get(op)) == sc._shape_rss(op, keep, "u1", 0.5)
    assert sc._threshold_shape("u1", 0.5) == "dz"
