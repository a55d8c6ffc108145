"""One truth: the API, the CLI (--json) and the HTML report give the same numbers for the same data.

One data set (a plant with a hidden battery gain) goes through ``arxid.analyse`` with its defaults,
``arxid diagnose --json``, ``arxid report --json`` (and the HTML it writes) and ``arxid sweep --json``;
every number they have in common must be identical.
"""

from __future__ import annotations

import io
import json
import re
from contextlib import redirect_stdout

import numpy as np
import pytest

import arxid
from arxid._base import metrics
from arxid.analysis.cli import main
from arxid.analysis.pipeline import choose
from arxid.analysis.report import json_safe


def _write_csv(path, n=3000, seed=11):
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 20 + 1), 20)[:n]
    vbat = np.linspace(4.2, 3.4, n) + 0.005 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(2, n):
        y[t] = 1.2 * y[t - 1] - 0.4 * y[t - 2] + 0.25 * u[t - 1] * vbat[t - 1] + 0.01 * rng.standard_normal()
    rows = "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(y, u, vbat))
    path.write_text("y,u,vbat\n" + rows + "\n")
    return arxid.IOData.from_csv(path, output="y", inputs=["u"], extra=["vbat"], ts=0.01)


def _cli_json(*argv):
    buf = io.StringIO()
    with redirect_stdout(buf):
        assert main(list(argv)) == 0
    return json.loads(buf.getvalue())


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("one_truth")
    csv = tmp / "log.csv"
    data = _write_csv(csv)
    api = arxid.analyse(data)
    common = [str(csv), "--output", "y", "--inputs", "u", "--extra", "vbat", "--ts", "0.01", "--json", "--no-progress"]
    diag = _cli_json("diagnose", *common)
    html_path = tmp / "r.html"
    rep = _cli_json("report", *common, "-o", str(html_path))
    sweep = _cli_json("sweep", *common)
    return data, api, diag, rep, sweep, html_path.read_text()


KEYS = ("model", "choice", "baseline", "residual_tests", "suspects", "ladder", "comparison", "where_it_fails")


def test_cli_diagnose_and_report_print_what_the_api_computed(runs):
    _, api, diag, rep, _, _ = runs
    expected = json_safe(api.to_dict())
    assert api.missing_effect is not None and "vbat" in api.missing_effect  # the case is not trivial
    for key in KEYS:
        assert diag[key] == expected[key], key
        assert rep[key] == expected[key], key


def test_html_embeds_and_shows_the_api_numbers(runs):
    _, api, _, _, _, html = runs
    embedded = json.loads(re.search(r'id="diagnosis">(.*?)</script>', html, re.S).group(1))
    expected = json_safe(api.to_dict())
    for key in KEYS:
        assert embedded[key] == expected[key], key
    rt = api.residual_tests
    shown = re.sub(r"<[^>]+>", " ", html)
    # the residual table shows the analysis' own bounds and verdicts
    for name, d in rt.to_dict()["cross_correlation"].items():
        assert f"{d['bound']:.3g}" in shown and name in shown
    assert f"±{rt.autocorrelation_bound:.3g}" in shown
    # the ladder and the suspects show the API's errors
    for step in api.ladder.steps:
        assert f"{step.rms_sim_val:.4g}" in shown
    top = api.diagnosis.top
    assert f"Missing effect: {top.effect}" in shown and f"{top.rms_sim_val_after:.4g}" in shown


def test_cli_and_api_choose_the_same_structure_with_their_defaults(runs):
    data, api, diag, _, sweep, _ = runs
    est, val = data.split(arxid.analysis.DEFAULT_SPLIT)
    res = arxid.sweep(est, validation=val, progress=False)  # the API's default grid
    model, choice = choose(res)
    assert sweep["grid"] == {k: list(v) for k, v in arxid.DEFAULT_GRID.items()}
    assert sweep["best"]["structure"] == model.structure_name() == api.model.structure_name()
    assert diag["model"]["structure"] == model.structure_name()
    assert np.array_equal(np.asarray(sweep["best"]["parameters"]), model.parameters_)


def test_every_number_has_one_definition(runs):
    """The numbers the pipeline reports equal the metrics module applied to the predictions."""
    _, api, _, _, _, _ = runs
    val, h = api.validation, api.horizon
    pred = api.model.predict(val, h)
    assert api.diagnosis.rms_sim_val == metrics.prediction_rms(val.y, pred) == api.comparison.rms[0]
    assert api.diagnosis.fit_val == metrics.fit_percent(val.y, pred) == api.comparison.fit_percent[0]
    assert api.failures[0].rms == pytest.approx(metrics.rms(val.y - pred), rel=1e-15)
    row = api.sweep.summary(top=api.choice.rank + 1)["structures"][api.choice.rank]
    assert row["rms_val"] == pytest.approx(api.diagnosis.rms_sim_val, rel=1e-9)
    assert row["fit_val"] == pytest.approx(api.diagnosis.fit_val, rel=1e-9)


def test_divergence_rule_is_the_cores():
    y = np.array([1.0, -2.0, np.nan])
    assert metrics.DIVERGENCE_FACTOR == arxid._base._core.DIVERGENCE_FACTOR
    assert metrics.divergence_limit(y) == 2.0 * metrics.DIVERGENCE_FACTOR
    assert not metrics.diverged(y, [1999.0, np.nan, 0.0]) and metrics.diverged(y, [2001.0, 0.0, 0.0])
    assert metrics.diverged(y, [np.inf, 0.0, 0.0]) and metrics.fit_percent(y, [np.inf, 0, 0]) == -np.inf


def test_criteria_match_matlab_formulas():
    rss, n, p = 2.5, 100, 4
    v = rss / n
    assert metrics.fpe(rss, n, p) == pytest.approx(v * (1 + p / n) / (1 - p / n), rel=1e-15)
    assert metrics.aic(rss, n, p) == pytest.approx(n * np.log(v) + 2 * p + n * (np.log(2 * np.pi) + 1), rel=1e-15)
    assert metrics.naic(rss, n, p) == pytest.approx(np.log(v) + 2 * p / n, rel=1e-15)
    assert metrics.aicc(rss, n, p) == pytest.approx(metrics.aic(rss, n, p) + 2 * p * (p + 1) / (n - p - 1), rel=1e-15)
    assert metrics.bic(rss, n, p) == pytest.approx(
        n * np.log(v) + p * np.log(n) + n * (np.log(2 * np.pi) + 1), rel=1e-15
    )
    np.testing.assert_allclose(metrics.fpe(np.array([rss, rss]), n, np.array([p, p])), metrics.fpe(rss, n, p))
    assert metrics.rms([3.0, np.nan, -4.0]) == pytest.approx(np.sqrt(12.5)) and np.isnan(metrics.rms([np.nan]))


def _write_oe_csv(path, n=3000, seed=5):
    """An output-error plant (two poles, delay 2) under 10 % output noise whose input gain sags with
    the supply voltage vbat: the OE model misses ``u*vbat``."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.uniform(-1, 1, n // 20 + 1), 20)[:n]
    vbat = np.linspace(4.2, 3.4, n) + 0.005 * rng.standard_normal(n)
    x = np.zeros(n)
    for t in range(3, n):
        x[t] = 1.5 * x[t - 1] - 0.7 * x[t - 2] + 0.25 * u[t - 2] * vbat[t - 2]
    y = x + 0.1 * np.std(x) * rng.standard_normal(n)
    rows = "\n".join(f"{a:.17g},{b:.17g},{c:.17g}" for a, b, c in zip(y, u, vbat))
    path.write_text("y,u,vbat\n" + rows + "\n")
    return arxid.IOData.from_csv(path, output="y", inputs=["u"], extra=["vbat"], ts=0.01)


@pytest.fixture(scope="module")
def oe_runs(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("one_truth_oe")
    csv = tmp / "oe.csv"
    data = _write_oe_csv(csv)
    api = arxid.analyse(data, model="oe:1,2,2")
    common = [str(csv), "--output", "y", "--inputs", "u", "--extra", "vbat", "--ts", "0.01", "--json", "--no-progress"]
    diag = _cli_json("diagnose", *common, "--model", "oe:1,2,2")
    html_path = tmp / "oe.html"
    rep = _cli_json("report", *common, "--model", "oe:1,2,2", "-o", str(html_path))
    return api, diag, rep, html_path.read_text()


def test_an_oe_model_shows_the_same_numbers_in_the_api_the_cli_and_the_report(oe_runs):
    api, diag, rep, html = oe_runs
    assert api.model.kind == "OE" and api.sweep is None and api.choice.rank is None
    assert api.missing_effect == "u*vbat"  # the case is not trivial
    expected = json_safe(api.to_dict())
    assert expected["model"]["kind"] == "OE" and expected["model"]["nf"] == [2]
    embedded = json.loads(re.search(r'id="diagnosis">(.*?)</script>', html, re.S).group(1))
    for key in KEYS:
        assert diag[key] == expected[key], key
        assert rep[key] == expected[key], key
        assert embedded[key] == expected[key], key
    shown = re.sub(r"<[^>]+>", " ", html)
    # the model in MATLAB's form, and each parameter with its standard error
    assert "Discrete-time OE model: y(t) = [B(z)/F(z)]u(t) + e(t)" in html
    for label, value, se in zip(api.model.parameter_labels(), api.model.parameters_, api.model.standard_errors_):
        assert f"{label}" in shown and f"{value:.4g}" in shown and f"{se:.3g}" in shown
    # the residual tests say what they test for an output-error model
    assert not api.residual_tests.whiteness_expected
    assert expected["residual_tests"]["ljung_box"]["whiteness_expected"] is False
    assert "which an output-error model allows" in shown
    for step in api.ladder.steps:
        assert f"{step.rms_sim_val:.4g}" in shown


def test_pooled_moments_of_parts_equal_the_moments_of_the_whole():
    rng = np.random.default_rng(5)
    y = 1e4 + rng.standard_normal(10_000)  # a large mean: Σy² − nȳ² would lose digits here
    y[300:320] = np.nan
    cuts = [0, 17, 4000, 4001, 9000, 10_000]
    parts = [metrics.centred_moments([y[a:b]]) for a, b in zip(cuts, cuts[1:])]
    n, mean, m2 = metrics.pooled_moments(parts + [(0, np.nan, np.nan)])
    finite = y[np.isfinite(y)]
    assert n == finite.size
    np.testing.assert_allclose(mean, finite.mean(), rtol=1e-14)
    np.testing.assert_allclose(m2, np.sum((finite - finite.mean()) ** 2), rtol=1e-10)
    # Side by side: one pooling per column; a column without samples has no moments.
    many = metrics.pooled_moments(np.stack([np.array(parts), np.array([(0, np.nan, np.nan)] * len(parts))], axis=1))
    np.testing.assert_allclose(many[0], (n, mean, m2), rtol=1e-14)
    assert many[1][0] == 0 and np.isnan(many[1][1:]).all()
    # The samples a sweep scores start at the first lag in each experiment.
    segments = [(0, 4000), (4000, 10_000)]
    got = metrics.scored_moments(y, segments, 3)
    ref = np.concatenate([y[3:4000], y[4003:]])
    ref = ref[np.isfinite(ref)]
    np.testing.assert_allclose(got, (ref.size, ref.mean(), np.sum((ref - ref.mean()) ** 2)), rtol=1e-10)
