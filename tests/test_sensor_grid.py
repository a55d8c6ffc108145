"""The sensor shapes scanned for an output (arxid.diagnosis.sensor_shapes): the levels of a clipping
sensor from one call of the quantiles, as from one call per level."""

from __future__ import annotations

import numpy as np
import pytest

from arxid.diagnosis.sensor_shapes import _sensor_grid
from arxid.models.wiener import SensorShape, noise_floor


def _one_by_one(y: np.ndarray) -> list[SensorShape]:
    """The saturations as the scan built them before: each level its own quantile."""
    y = y[np.isfinite(y)]
    lo, hi = float(np.min(y)), float(np.max(y))
    out = []
    for q in np.linspace(0.0, 0.03, 4):
        top, bottom = float(np.quantile(y, 1 - q)), float(np.quantile(y, q))
        out += [SensorShape("saturation", (bottom, top)), SensorShape("saturation", (lo - (hi - lo), top))]
        out += [SensorShape("saturation", (bottom, hi + (hi - lo)))]
    return out


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("offset", [0.0, 5.0])  # two-sided (a dead band too) and one-sided (a power law)
def test_saturation_levels_equal_the_one_by_one_quantiles(seed, offset):
    rng = np.random.default_rng(seed)
    y = offset + 2.0 * np.sin(np.arange(20001) / (40.0 + seed)) + 0.01 * rng.standard_normal(20001)
    y[rng.integers(0, y.size, 30)] = np.nan
    grid = _sensor_grid(y, noise_floor(y))
    saturations = [s for s in grid if s.kind == "saturation"]
    assert [s.params for s in saturations] == [s.params for s in _one_by_one(y)]  # bit for bit
    kinds = {s.kind for s in grid}
    assert ("dead zone" in kinds) == (offset == 0.0) and ("power" in kinds) == (offset > 0.0)
