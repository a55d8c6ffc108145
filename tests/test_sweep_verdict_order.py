"""The integrator verdict reads the few best structures of a grid without sorting all of it: the
structures it reads are exactly those a full stable sort puts first, ties included."""

from __future__ import annotations

import numpy as np
import pytest

from arxid.selection.ranking import first_in_order


@pytest.mark.parametrize("k", [1, 5, 80, 999, 1000, 5000])
def test_first_of_the_stable_sort_with_ties_and_infinities(k):
    rng = np.random.default_rng(3)
    values = rng.integers(0, 40, 1000).astype(float)  # many ties
    values[rng.choice(1000, 100, replace=False)] = np.inf
    full = np.argsort(values, kind="stable")
    got = first_in_order(values, k)
    assert got.size >= min(k, values.size)
    np.testing.assert_array_equal(got, full[: got.size])
    # Every value tied with the k-th smallest is kept, so the prefix does not depend on the cut.
    if got.size < values.size:
        assert values[full[got.size]] > values[got[-1]]


def test_all_infinite_gives_grid_order():
    values = np.full(50, np.inf)
    np.testing.assert_array_equal(first_in_order(values, 5), np.arange(50))
