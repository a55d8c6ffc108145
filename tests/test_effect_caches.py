"""Parsed effects and compiled layouts kept by signal names (:mod:`arxid.models.effects`): a ladder
parses and compiles the same effects hundreds of times, and the kept ones must give the answers a
fresh parse gives.

Known answers: the ladder of each plant with the caches on equals the ladder with them off (every
rung's suspects, p-values and validation errors, to the bit); plants: the thrust stand simulator
(two seeds: battery, dead zone, gain scaled by the battery) and a first-order plant with a cubic
output term, ``y = 0.8 y(t-1) + 0.5 u(t-1) - 0.3 y(t-1)^3``.
"""

from __future__ import annotations

import numpy as np
import pytest

import arxid
from arxid.exceptions import OrderError
from arxid.models import effects as fx


class _Forgetful(dict):
    """A cache that keeps nothing: every parse and layout is made afresh."""

    def __setitem__(self, key, value) -> None:
        pass


def _cubic_plant(seed: int) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    n = 2000
    u = rng.uniform(-1.0, 1.0, n).repeat(1)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.8 * y[t - 1] + 0.5 * u[t - 1] - 0.3 * y[t - 1] ** 3 + 0.01 * rng.standard_normal()
    return arxid.IOData(y, u, ts=0.01)


def _thrust(seed: int) -> arxid.IOData:
    return arxid.datasets.thrust_stand(seed=seed, duration=20.0, ts=0.01)


def _ladder_answer(data: arxid.IOData, orders: tuple[int, int, int]) -> tuple:
    est, val = data.split(0.6)
    ladder = arxid.Ladder.run(arxid.arx(est, *orders), est, val, restructure=True)
    rungs = [
        [(s.effect, s.significant, s.p_value_raw, s.p_value, s.rms_sim_val_after, s.note) for s in d.suspects]
        for d in ladder.diagnoses
    ]
    return ladder.to_json(), rungs


@pytest.mark.parametrize(
    ("plant", "orders"),
    [(lambda: _thrust(0), (4, 2, 2)), (lambda: _thrust(3), (2, 2, 1)), (lambda: _cubic_plant(5), (1, 1, 1))],
    ids=["thrust-0", "thrust-3", "cubic-5"],
)
def test_ladder_with_kept_effects_equals_a_fresh_parse(plant, orders, monkeypatch):
    data = plant()
    kept = _ladder_answer(data, orders)
    monkeypatch.setattr(fx, "_PARSED", _Forgetful())
    monkeypatch.setattr(fx, "_LAYOUTS", _Forgetful())
    fresh = _ladder_answer(data, orders)
    assert len(kept[1]) >= 2  # at least one rung was added: the caches served several models
    assert kept == fresh


def test_parsed_effect_is_kept_per_signal_names_and_errors_are_raised_each_time():
    rng = np.random.default_rng(0)
    a = arxid.IOData(rng.standard_normal(50), rng.standard_normal(50), 0.01, extra={"vbat": np.ones(50)})
    same_names = a[10:40]
    other_names = arxid.IOData(a.y, a.u, 0.01, input_names=("pwm",), extra={"vbat": np.ones(50)})
    e = fx.parse_effect("u1*vbat", a)
    assert fx.parse_effect("u1*vbat", same_names) is e  # a slice has the record's names
    assert fx.parse_effect("pwm*vbat", other_names).factors[0].signal == "pwm"
    with pytest.raises(OrderError, match="pwm"):
        fx.parse_effect("pwm*vbat", a)
    with pytest.raises(OrderError, match="pwm"):  # not kept as an answer
        fx.parse_effect("pwm*vbat", a)


def test_kept_layout_follows_each_calls_orders_and_still_checks_duplicates():
    rng = np.random.default_rng(1)
    data = arxid.IOData(rng.standard_normal(80), rng.standard_normal((80, 2)), 0.01, extra={"vbat": np.ones(80)})
    first = fx.compile_effects(("u2*vbat", "y^2", "const"), data, (2, 1), (1, 3), samples=False)
    other = fx.compile_effects(("u2*vbat", "y^2", "const"), data, (3, 2), (0, 1), samples=False)
    assert first.nb == (2, 1, 1, 1) and first.nk == (1, 3, 3, 0)
    assert other.nb == (3, 2, 2, 1) and other.nk == (0, 1, 1, 0)
    with pytest.raises(OrderError, match="listed twice"):
        fx.compile_effects(("const", "const"), data, (1, 1), (1, 1), samples=False)
