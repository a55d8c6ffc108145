"""The shortcuts that cut a diagnosis's fixed costs give the answers of the long way, to the bit
(issue 42, part 5): a shape scan's projection readied once, its values kept by their digits and its
grid's values projected in one call of the core with the lags gathered there
(:class:`arxid._base.orthonormal.Projector`, :mod:`arxid.diagnosis.shape_cost`), a sensor scan's
fits made by the core without a fitted model per sensor (:class:`arxid.models.wiener.SensorScan`),
and a fit's memory estimate and input check made once per size and per input matrix
(:mod:`arxid.models.arx_solver`).

Known answers: the ladder of each plant with the shortcuts equals the ladder without them (every
rung's suspects, p-values and validation errors, every step's error); plants: the thrust stand
simulator (two seeds: battery, dead zone, gain scaled by the battery), a Hammerstein dead zone of
half-width 0.3 (``x = 1.2 x(t-1) - 0.4 x(t-2) + 0.3 f(t-1) + 0.1 f(t-2)``) and the same linear
dynamics read through a sensor that clips at 80 % of its peak (the Wiener fits). The rank rule
read as Python numbers equals numpy's on independent and dependent columns.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import arxid
from arxid._base import _core
from arxid._base.orthonormal import RANK_FACTOR, Projector
from arxid.diagnosis import shape_cost
from arxid.exceptions import ArxidError, IdentifiabilityError
from arxid.models import arx_solver, wiener
from arxid.models.excitation import check_excitation
from arxid.models.input_shapes import InputShape, parse_shape


def _thrust(seed: int) -> arxid.IOData:
    return arxid.datasets.thrust_stand(seed=seed, duration=20.0, ts=0.01)


def _second_order(seed: int, kind: str) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    n = 2500
    u = np.repeat(rng.uniform(-1.0, 1.5, n // 10), 10)
    f = np.sign(u) * np.maximum(np.abs(u) - 0.3, 0.0) if kind == "dead zone" else u
    x = np.zeros(n)
    for t in range(2, n):
        x[t] = 1.2 * x[t - 1] - 0.4 * x[t - 2] + 0.3 * f[t - 1] + 0.1 * f[t - 2]
    y = np.minimum(x, 0.8 * x.max()) if kind == "sensor" else x
    return arxid.IOData(y + 0.01 * rng.standard_normal(n), u, ts=0.01)


def _ladder_answer(data: arxid.IOData, orders: tuple[int, int, int]) -> tuple:
    est, val = data.split(0.6)
    ladder = arxid.Ladder.run(arxid.arx(est, *orders), est, val)
    rungs = [
        [(s.effect, s.significant, s.p_value_raw, s.p_value, s.rms_sim_val_after, s.note) for s in d.suspects]
        for d in ladder.diagnoses
    ]
    return [(s.added, s.rms_sim_val, s.fit_val) for s in ladder.steps], rungs


def _every_value_anew(self, values):
    """A scan's values one at a time, without the kept digits: the shape made, written as the
    effect's text and read back by the grammar, evaluated, its lags gathered in numpy and projected
    (the core's general projection) each time."""
    out = []
    names = set(self.cost.data.signal_names) | {"y", "u1"}
    for v in values:
        shape = InputShape(self.cost.kind, self.cost.signal, v)
        try:
            read = parse_shape(shape.text, names, shape.effect)
        except ArxidError:
            out.append(math.inf)
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            series = read.evaluate(self.signal)
        if np.isinf(series).any():
            out.append(math.inf)
            continue
        z = series[self.index]
        out.append(self.projector.rss(z) if np.isfinite(z).all() else self.cost.refit(shape))
    return out


def _wiener_fitted_each_time(self, sensor):
    """A sensor's fit and free run through a fitted Wiener model, a new IOData each time."""
    try:
        w = wiener.fit_wiener(self.model, self.data, sensor, self.floor)
    except ArxidError:
        return None
    try:
        return w.linear.a, w.predict(self.data, None)
    except ArxidError:
        return w.linear.a, None


def _numpy_rss(self, z):
    """The projected loss with the rank rule in numpy, as it was written before the Projector."""
    r, squares = _core.projected_r(self.basis, self.y_perp, z)
    dependent = ~(np.abs(np.diag(r)[: z.shape[1]]) > RANK_FACTOR * z.shape[0] * np.sqrt(squares))
    return math.inf if dependent.any() else float(r[-1, -1] ** 2)


@pytest.mark.parametrize(
    ("plant", "orders"),
    [
        (lambda: _thrust(0), (4, 2, 2)),
        (lambda: _thrust(3), (2, 2, 1)),
        (lambda: _second_order(0, "dead zone"), (2, 2, 1)),
        (lambda: _second_order(1, "sensor"), (2, 2, 1)),
    ],
    ids=["thrust-0", "thrust-3", "dead-zone", "sensor"],
)
def test_ladder_with_the_shortcuts_equals_the_long_way(plant, orders, monkeypatch):
    data = plant()
    short = _ladder_answer(data, orders)
    monkeypatch.setattr(shape_cost._Projection, "rss_many", _every_value_anew)
    monkeypatch.setattr(Projector, "rss", _numpy_rss)
    monkeypatch.setattr(wiener.SensorScan, "free_run", _wiener_fitted_each_time)
    monkeypatch.setattr(arx_solver, "check_inputs_vary", check_excitation)
    monkeypatch.setattr(arx_solver, "fit_memory", _core.fit_memory)
    long = _ladder_answer(data, orders)
    # a rung was added (the shortcuts served several models), or the sensor shapes were fitted
    assert len(short[1]) >= 2 or any(s[0].startswith("sensor:") for s in short[1][0])
    assert short == long


def test_rank_rule_in_python_numbers_equals_numpy():
    rng = np.random.default_rng(4)
    q = np.linalg.qr(rng.standard_normal((800, 3)))[0]
    y = rng.standard_normal(800)
    y -= q @ (q.T @ y)
    free = rng.standard_normal((800, 2))
    cases = [free, np.column_stack([free[:, 0], q[:, 1]]), np.column_stack([free[:, 0], 2.0 * free[:, 0]])]
    projector = Projector(q, y)
    for z in cases:
        r, dependent = projector.r(z)
        _, squares = _core.projected_r(q, y, z)
        expected = ~(np.abs(np.diag(r)[:2]) > RANK_FACTOR * 800 * np.sqrt(squares))
        assert dependent == expected.tolist()
        assert projector.rss(z) == _numpy_rss(projector, z)
    assert [projector.r(z)[1] for z in cases] == [[False, False], [False, True], [False, True]]


def test_a_constant_input_is_refused_every_time_and_a_varying_one_is_checked_once():
    """Only a pass is kept: the same record refused twice; records that share an input matrix (an
    output read through a sensor shape) pass on the first one's check."""
    y = np.random.default_rng(0).standard_normal(300)
    flat = arxid.IOData(y, np.full(300, 2.0), ts=0.1)
    for _ in range(2):
        with pytest.raises(IdentifiabilityError, match="constant"):
            arxid.arx(flat, 1, 1, 1)
    data = arxid.IOData(y, np.random.default_rng(1).standard_normal((300, 1)), ts=0.1)
    arxid.arx(data, 1, 1, 1)
    assert arx_solver._VARY[id(data.u)][1] == frozenset({0})
    other_output = data.with_samples(y=2.0 * y)
    assert other_output.u is data.u  # the same input matrix: no second check
    assert arxid.arx(other_output, 1, 1, 1).parameters_.shape == (2,)


def test_a_scans_grid_in_one_call_equals_its_values_one_at_a_time():
    """The grid's values projected in one call of the core (the lags gathered there) give each
    value's loss of the value alone, to the bit: a dead zone on the thrust stand, some values twice."""
    data = _thrust(1)
    model = arxid.arx(data, 2, 2, 1)
    top = float(np.max(np.abs(data.u)))
    widths = [(f * top,) for f in (0.05, 0.2, 0.2, 0.31, 0.9, 2.0)]
    batch = shape_cost.ShapeCost(model, data, "dead zone", "pwm", True)
    alone = shape_cost.ShapeCost(model, data, "dead zone", "pwm", True)
    got = batch.many(widths)
    assert batch._fast is not None
    assert got == [alone(w) for w in widths]
    assert math.isinf(got[-1])  # a dead zone wider than the input: rank deficient, as the refit says


def test_lags_gathered_by_the_core_equal_numpys_and_a_missing_lag_is_flagged():
    rng = np.random.default_rng(5)
    n = 600
    q = np.linalg.qr(rng.standard_normal((n, 3)))[0]
    y = rng.standard_normal(n)
    y -= q @ (q.T @ y)
    series = rng.standard_normal((3, n + 2))
    series[2, 10] = np.nan
    index = np.column_stack([np.arange(n) + 2, np.arange(n) + 1]).astype(np.int64)
    projector = Projector(q, y)
    got = projector.shaped_rss(series, index)
    assert got[:2] == [projector.rss(s[index]) for s in series[:2]]
    assert got[2] is None
