"""The HTML report: analysis pieces, self-containment, plots against numpy references, the demo."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest

import arxid
from arxid.plots import report as plots
from arxid.report import Analysis, analyse, build_report, json_safe, render_html


def _battery_data(n=2500, seed=5):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    vbat = np.linspace(4.2, 3.4, n) + 0.01 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.9 * y[t - 1] + 0.3 * u[t - 1] * vbat[t - 1] + 0.02 * rng.standard_normal()
    return arxid.IOData(y, u, 0.01, output_name="y", input_names=("u",), extra={"vbat": vbat},
                        extra_units={"vbat": "V"})


@pytest.fixture(scope="module")
def analysis() -> Analysis:
    return analyse(_battery_data(), 0.7, grid={"na": [1, 2], "nb": [1, 2], "nk": [0, 1, 2]}, max_steps=2)


def test_json_safe_turns_nan_into_null_and_numpy_into_python():
    obj = {"a": np.float64("nan"), "b": [np.int64(3), np.inf, (1.5, np.bool_(True))], "c": np.arange(2.0)}
    out = json_safe(obj)
    assert out == {"a": None, "b": [3, None, [1.5, True]], "c": [0.0, 1.0]}
    json.dumps(out, allow_nan=False)


def test_analysis_picks_the_true_structure_and_finds_the_battery(analysis):
    assert analysis.model.nk == (1,)  # the true delay; the orders may grow to soak up the battery's drift
    assert analysis.table is not None and len(analysis.table) == 2 * 2 * 3
    d = analysis.diagnosis
    assert set(d) == {"model", "baseline", "residual_tests", "suspects", "ladder"}
    top = next(s for s in d["suspects"] if s["significant"])
    assert "vbat" in top["effect"]
    assert analysis.final_model.effects == tuple(analysis.ladder[-1]["effects"])
    assert analysis.ladder[-1]["rms_sim_val"] < 0.5 * analysis.ladder[0]["rms_sim_val"]
    # the final model's validation error is the ladder's last number
    assert analysis.final_model.rms(analysis.validation, analysis.horizon) == pytest.approx(
        analysis.ladder[-1]["rms_sim_val"], rel=1e-6)


def test_html_is_self_contained_and_complete(analysis):
    html = render_html(analysis, title="T <&> test", source="unit test")
    assert html.startswith("<!DOCTYPE html>") and html.rstrip().endswith("</html>")
    assert "T &lt;&amp;&gt; test" in html  # escaped
    srcs = re.findall(r'<img src="([^"]+)"', html)
    assert len(srcs) >= 8 and all(s.startswith("data:image/png;base64,") for s in srcs)
    assert not re.search(r'(src|href)="(?!data:|#)', html), "a link or source that is not embedded"
    assert "@media print" in html
    assert str(analysis.model) .splitlines()[0] in html  # the model equation
    for head in ("Data", "Order sweep", "Model equation", "Step-response checks", "Measured against simulated output",
                 "Residual tests", "Where it fails", "Which effect is missing", "Error ladder"):
        assert f". {head}</h2>" in html
    embedded = re.search(r'<script type="application/json" id="diagnosis">(.*?)</script>', html, re.S).group(1)
    # A script element's text is raw: a browser does not decode entities in it, so the JSON must be
    # readable as it stands (JSON.parse(el.textContent)), with "<" escaped so "</script>" cannot occur.
    assert json.loads(embedded)["ladder"] == json_safe(analysis.diagnosis["ladder"])
    assert "<" not in embedded and "&quot;" not in embedded


def test_build_report_with_fixed_orders_skips_the_sweep(tmp_path):
    rep = build_report(_battery_data(1200), 0.7, orders=(1, 1, 1), max_steps=1)
    assert rep.analysis.table is None
    assert "no sweep was run" in rep.html
    p = rep.save(tmp_path / "r.html")
    assert p.read_text() == rep.html
    assert "ARX(1,1,1)" in str(rep)


def test_correlation_matches_numpy():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal(300), rng.standard_normal(300)
    lags, r = plots.correlation(a, b, 5)
    ac, bc = a - a.mean(), b - b.mean()
    full = np.correlate(ac, bc, mode="full") / math.sqrt(ac @ ac * (bc @ bc))
    mid = len(a) - 1
    np.testing.assert_allclose(r, full[mid - 5: mid + 6], atol=1e-12)
    assert list(lags) == list(range(-5, 6))
    _, r0 = plots.correlation(a, a, 0)
    assert r0[0] == pytest.approx(1.0)


def test_binned_and_rolling_rms_known_answers():
    x = np.repeat([0.0, 1.0], 50)
    e = np.where(x > 0, 2.0, 1.0)
    c, r, n = plots.binned_rms(x, e, n_bins=2)
    np.testing.assert_allclose(c, [0.0, 1.0])
    np.testing.assert_allclose(r, [1.0, 2.0])
    assert list(n) == [50, 50]
    e2 = np.full(100, 3.0)
    e2[:10] = np.nan
    rr = plots.rolling_rms(e2, 5)
    np.testing.assert_allclose(rr[20:80], 3.0)
    assert np.isnan(rr[3])


def test_every_figure_renders_to_png(analysis):
    val = analysis.validation
    p = analysis.model.predict(val)
    import pandas as pd

    grid = pd.DataFrame([{"na": a, "nb": 1, "nk": k, "v": a + k + 1.0} for a in (1, 2) for k in (0, 1, 2)])
    figs = [plots.data_overview(val), plots.sweep_heatmap(grid, "v"),
            plots.step_checks([("a", np.ones(10))], 0.01, {"a": "too small"}),
            plots.measured_vs_simulated(val, [("m", p)]), plots.residual_correlations(val.y - p, {"u": val.u[:, 0]}),
            plots.error_in_time(val, [("m", val.y - p)]), plots.error_by_signal(val, val.y - p, ["y", "dy", "u", "vbat"]),
            plots.error_ladder([("ARX", 1.0), ("+ u*vbat", 0.2)])]
    for f in figs:
        uri = plots.figure_to_data_uri(f, dpi=40)
        assert uri.startswith("data:image/png;base64,iVBOR")  # PNG magic


def test_demo_tells_the_battery_story(tmp_path):
    """The demo on a short flight: the battery voltage is the missing effect and the error falls."""
    import io

    from arxid.demo import run_demo

    out = io.StringIO()
    res = run_demo(tmp_path / "demo.html", duration=10.0, stream=out)
    text = out.getvalue()
    assert res.missing_effect is not None and "vbat" in res.missing_effect, text
    assert res.error_fall is not None and res.error_fall > 0.5, text
    assert "Error ladder" in text and "before" in text
    assert (tmp_path / "demo.html").stat().st_size > 100_000
    json.dumps(json_safe(res.to_dict()), allow_nan=False)


def test_public_functions_document_their_parameters():
    import inspect

    from arxid import cli, demo, report

    fns = [report.analyse, report.render_html, report.build_report, report.run_sweep, report.diagnose_ladder,
           demo.run_demo, demo.demo_data, cli.load_data, plots.data_overview, plots.sweep_heatmap, plots.step_checks,
           plots.measured_vs_simulated, plots.residual_correlations, plots.error_in_time, plots.error_by_signal,
           plots.error_ladder]
    for fn in fns:
        doc = inspect.getdoc(fn) or ""
        assert doc, f"{fn.__qualname__} has no docstring"
        for name in inspect.signature(fn).parameters:
            assert name in doc, f"{fn.__qualname__}: parameter {name} undocumented"
