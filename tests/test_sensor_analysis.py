"""The whole analysis of a plant whose sensor clips: the ladder ends on the sensor shape (a Wiener
model), and the checks, the comparison, the JSON and the report take that model as it is.

Before, `analyse` stopped with "expected a fitted arxid.ArxModel, got WienerModel" whenever the
ladder ended on a sensor step: the checks of where the model fails and the comparison refused it.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import arxid
from arxid.analysis.report import render_html
from arxid.models.wiener import WienerModel

GRID = {"na": [1, 2, 3], "nb": [1, 2], "nk": [0, 1, 2]}


def clipping_sensor(seed: int) -> tuple[arxid.IOData, float]:
    """A second-order plant read by a sensor that clips at 80 % of the largest true output."""
    rng = np.random.default_rng(seed + 10)
    n = 2500
    u = np.repeat(rng.uniform(0.2, 1.5, n // 10), 10)
    vbat = 11 + 0.5 * np.cumsum(rng.standard_normal(n)) / 50
    x = np.zeros(n)
    for t in range(2, n):
        x[t] = 1.2 * x[t - 1] - 0.4 * x[t - 2] + 0.3 * u[t - 1] + 0.1 * u[t - 2]
    level = 0.8 * x.max()
    y = np.clip(x, -10, level) + 0.01 * rng.standard_normal(n)
    return arxid.IOData(y, u, ts=0.01, extra={"vbat": vbat}), level


@pytest.fixture(scope="module", params=[2, 3])
def analysed(request):
    data, level = clipping_sensor(request.param)
    return arxid.analyse(data, grid=GRID), level


def test_the_ladder_ends_on_the_sensor_and_the_analysis_completes(analysed):
    a, level = analysed
    last = a.ladder.steps[-1]
    assert isinstance(last.model, WienerModel) and last.added.startswith("sensor: ")
    sensor = last.model.sensor
    assert sensor.kind == "saturation" and abs(sensor.params[1] / level - 1) <= 0.05
    # the comparison measures the Wiener model itself: the ladder's error, well below the chosen model's
    names, rms = a.comparison.names, a.comparison.rms
    assert names[1] == "+ " + last.added
    assert rms[1] == pytest.approx(last.rms_sim_val, rel=1e-12) and rms[1] < 0.3 * rms[0]
    assert len(a.failures) == 2  # where each model fails, the Wiener model too


def test_a_sensor_step_counts_as_an_added_effect(analysed):
    a, _ = analysed
    j = json.loads(a.to_json())
    step = j["ladder"][-1]
    assert step["kind"] == "effect" and step["effects"][-1] == step["added"]
    assert step["orders"]["na"] == a.ladder.steps[-1].model.linear.na_
    fall = j["error_fall"]
    assert fall["structure"] == 0.0 and fall["effects"] == pytest.approx(fall["total"]) and fall["total"] > 0.7


def test_only_linear_models_get_a_frequency_check(analysed):
    """A clipped output has no frequency response of its own: the chosen model is checked, the
    Wiener model is not (no check naming it, no free-run bands that would be of its linear part)."""
    a, _ = analysed
    assert [f.model_name for f in a.frequency] == [a.model.structure_name()]
    assert a.bands == ()


def test_the_report_renders_with_the_sensor_model(analysed):
    a, _ = analysed
    html = render_html(a)
    assert a.ladder.steps[-1].added in html and "then the sensor reads" in html
