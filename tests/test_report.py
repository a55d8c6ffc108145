"""The HTML report: analysis pieces, self-containment, plots against numpy references, the demo."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import arxid
from arxid import plots
from arxid.analysis.pipeline import Analysis, analyse
from arxid.analysis.report import build_report, json_safe, render_html


def _battery_data(n=2500, seed=5):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    vbat = np.linspace(4.2, 3.4, n) + 0.01 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.9 * y[t - 1] + 0.3 * u[t - 1] * vbat[t - 1] + 0.02 * rng.standard_normal()
    return arxid.IOData(
        y, u, 0.01, output_name="y", input_names=("u",), extra={"vbat": vbat}, extra_units={"vbat": "V"}
    )


@pytest.fixture(scope="module")
def analysis() -> Analysis:
    return analyse(_battery_data(), split=0.7, grid={"na": [1, 2], "nb": [1, 2], "nk": [0, 1, 2]}, max_steps=2)


def test_json_safe_turns_nan_into_null_and_numpy_into_python():
    obj = {"a": np.float64("nan"), "b": [np.int64(3), np.inf, (1.5, np.bool_(True))], "c": np.arange(2.0)}
    out = json_safe(obj)
    assert out == {"a": None, "b": [3, None, [1.5, True]], "c": [0.0, 1.0]}
    json.dumps(out, allow_nan=False)


def test_analysis_picks_the_true_structure_and_finds_the_battery(analysis):
    assert analysis.model.nk_ == (1,)  # the true delay; the orders may grow to soak up the battery's drift
    assert analysis.sweep is not None and len(analysis.sweep) == 2 * 2 * 3
    d = analysis.to_dict()
    assert {"model", "baseline", "residual_tests", "suspects", "ladder", "choice", "comparison"} <= set(d)
    assert "vbat" in analysis.missing_effect
    assert analysis.final_model.effects == analysis.ladder.steps[-1].effects
    assert analysis.ladder.errors[-1] < 0.5 * analysis.ladder.errors[0]
    # the final model's validation error is the ladder's last number, and the comparison's
    assert analysis.final_model.rms(analysis.validation, analysis.horizon) == pytest.approx(
        analysis.ladder.errors[-1], rel=1e-12
    )
    assert analysis.comparison.rms[-1] == analysis.ladder.errors[-1]
    assert analysis.comparison.rms[0] == analysis.diagnosis.rms_sim_val == analysis.ladder.errors[0]


def test_html_is_self_contained_and_complete(analysis):
    html = render_html(analysis, title="T <&> test", source="unit test")
    assert html.startswith("<!DOCTYPE html>") and html.rstrip().endswith("</html>")
    assert "T &lt;&amp;&gt; test" in html  # escaped
    srcs = re.findall(r'<img src="([^"]+)"', html)
    assert len(srcs) >= 8 and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert not re.search(r'(src|href)="(?!data:|#)', html), "a link or source that is not embedded"
    assert "@media print" in html
    assert str(analysis.model).splitlines()[0] in html  # the model equation
    for head in (
        "Data",
        "Order sweep",
        "Model equation",
        "Step-response checks",
        "Measured against simulated output",
        "Residual tests",
        "Where it fails",
        "Which effect is missing",
        "Error ladder",
    ):
        assert f". {head}</h2>" in html
    embedded = re.search(r'<script type="application/json" id="diagnosis">(.*?)</script>', html, re.S).group(1)
    # A script element's text is raw: a browser does not decode entities in it, so the JSON must be
    # readable as it stands (JSON.parse(el.textContent)), with "<" escaped so "</script>" cannot occur.
    assert json.loads(embedded)["ladder"] == json_safe(analysis.to_dict()["ladder"])
    assert "<" not in embedded and "&quot;" not in embedded


def test_a_number_as_validation_is_refused_with_the_split_to_use():
    data = _battery_data(1200)
    with pytest.raises(arxid.ArxidError, match=r"split=0\.6"):
        analyse(data, 0.6, orders=(1, 1, 1), max_steps=1)
    a = analyse(data, split=0.6, orders=(1, 1, 1), max_steps=1)
    assert a.estimation.n_samples == data.split(0.6)[0].n_samples


def test_build_report_with_fixed_orders_skips_the_sweep(tmp_path):
    rep = build_report(_battery_data(1200), orders=(1, 1, 1), max_steps=1)
    assert rep.analysis.sweep is None
    assert "no sweep was run" in rep.html
    p = rep.save(tmp_path / "r.html")
    assert p.read_text() == rep.html
    assert "ARX(1,1,1)" in str(rep)


def test_every_figure_renders_to_png(analysis):
    a = analysis
    figs = [
        plots.data_overview(a.validation),
        plots.plot_sweep(a.sweep, chosen=a.choice.rank),
        plots.step_checks([("a", np.ones(10))], 0.01, {"a": "too small"}),
        plots.plot_comparison(a.comparison),
        plots.plot_residuals(a.residual_tests),
        plots.plot_failures(a.failures[0]),
        plots.plot_error_by_signal(a.failures[0], a.failures[-1]),
        plots.plot_diagnosis(a.diagnosis),
        plots.plot_ladder(a.ladder),
    ]
    for f in figs:
        uri = plots.figure_to_data_uri(f, dpi=40)
        assert uri.startswith("data:image/png;base64,iVBOR")  # PNG magic


def test_plots_draw_into_given_axes(analysis):
    from matplotlib.figure import Figure

    fig = Figure()
    ax = fig.subplots()
    assert analysis.ladder.plot(ax=ax) is fig and analysis.failures[0].plot(ax=ax) is fig
    top, bottom = Figure().subplots(2, 1)
    assert analysis.comparison.plot(ax=[top, bottom]) is top.figure


def test_residual_plot_marks_exactly_the_lags_the_analysis_calls_outside(analysis):
    """The plot draws the analysis' own bounds: red points are the lags ``cross_outside`` lists."""
    rt = analysis.residual_tests
    fig = plots.plot_residuals(rt)
    axes = fig.axes
    for ax, name in zip(axes[1:], rt.cross_correlation):
        red = [line for line in ax.get_lines() if line.get_marker() == "o"]
        xs = red[0].get_xdata() if red else []
        assert list(xs) == list(rt.cross_outside(name))


def test_demo_tells_the_battery_story(demo_run):
    """The demo on a short flight: the battery voltage is the missing effect and the error falls."""
    path, text, res = demo_run
    assert res.missing_effect is not None and "vbat" in res.missing_effect, text
    assert res.error_fall is not None and res.error_fall > 0.5, text
    assert "Error ladder" in text and "before" in text
    assert path.stat().st_size > 100_000
    json.dumps(json_safe(res.to_dict()), allow_nan=False)
