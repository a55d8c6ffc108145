"""The integrator verdict's settling evidence reads the poles of the structures it looks at (the
best few by free-run validation error), not of the whole table: the same evidence as the
whole-table computation it replaced, on a stable plant and an integrating one."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.selection.integrator import VOTERS, SettlingEvidence, slowest_time_constant
from arxid.selection.search import _settling_evidence


def stable_plant(seed: int, n: int = 3000) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter([0, 0, 0.5, 0.25], [1, -1.5, 0.7], u) + lfilter([1], [1, -1.5, 0.7], 0.02 * rng.standard_normal(n))
    return arxid.IOData(y, u, ts=0.01)


def integrating_plant(seed: int, n: int = 3000) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter([0, 0, 0.2], [1, -1.0], u) + 0.002 * rng.standard_normal(n)
    return arxid.IOData(y, u, ts=0.01)


def whole_table_evidence(res: arxid.SweepResult) -> SettlingEvidence:
    """The evidence as it was computed before: every structure's largest pole, then the best few."""
    score = np.where(np.isfinite(res.rms_val) & np.isfinite(res.fit_val), res.rms_val, np.inf)
    best = [int(i) for i in np.argsort(score, kind="stable")[:VOTERS] if np.isfinite(score[i])]
    max_pole = res.max_pole  # the whole table
    taus = [math.inf if max_pole[i] >= 1.0 else slowest_time_constant(res.parameters[i], int(res.na[i])) for i in best]
    return SettlingEvidence(
        tuple(res.structure_name(i) for i in best),
        tuple(taus),
        tuple(float(res.fit_val[i]) for i in best),
        res.n_est,
    )


def free_run_sweep(plant, expect: str | None) -> arxid.SweepResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", arxid.ArxidWarning)  # grid-edge notes
        return arxid.sweep(
            plant(1), na=range(1, 4), nb=range(1, 3), nk=range(0, 4), validation=plant(2), progress=False, expect=expect
        )


@pytest.mark.parametrize("plant", [stable_plant, integrating_plant])
def test_evidence_equals_the_whole_table_computation(plant):
    res = free_run_sweep(plant, expect="stable")  # free run on both plants
    new = _settling_evidence(res)
    assert "max_pole" not in res._cache  # the verdict solved the poles of its few structures only
    old = whole_table_evidence(res)
    assert new == old
    if plant is integrating_plant:  # the free-run models of an integrator put a pole on or outside the circle
        assert math.inf in new.time_constants and not new.settles
    else:
        assert all(math.isfinite(t) for t in new.time_constants) and new.settles


def test_a_default_sweep_reports_the_whole_table_evidence():
    res = free_run_sweep(stable_plant, expect=None)
    assert not res.integrating and res.integrator.settling is not None
    assert res.integrator.settling == whole_table_evidence(res)


def test_max_pole_of_some_rows_equals_the_whole_table_column():
    res = free_run_sweep(integrating_plant, expect="stable")
    rows = [7, 0, 3, 7, len(res) - 1]
    part = res.max_pole_of(rows)
    np.testing.assert_array_equal(part, res.max_pole[rows])
    np.testing.assert_array_equal(res.max_pole_of(rows), part)  # from the whole column, once it exists
    assert (res.max_pole >= 1.0).any() and (res.max_pole < 1.0).any()
