"""The state-space report in headless Chromium: every plot loads, nothing is fetched, no errors, the
page is drawn (skipped with a reason when no Chromium is installed)."""

from __future__ import annotations

import json
import re

import pytest

from arxid.analysis.report.state_space import render_state_space_html
from arxid.analysis.state_space import analyse_state_space
from test_browser import _PROBE, _assert_not_blank, _run, browser  # noqa: F401 - the fixture
from test_state_space_analysis import decoupled_plant

pytestmark = pytest.mark.browser


@pytest.fixture(scope="module")
def report_file(tmp_path_factory):
    page = render_state_space_html(analyse_state_space(decoupled_plant(3000)), source="decoupled plant")
    path = tmp_path_factory.mktemp("ss-report") / "report.html"
    path.write_text(page, encoding="utf-8")
    return path


def test_the_state_space_report_renders_every_plot_without_errors(browser, report_file, tmp_path):  # noqa: F811
    probed = tmp_path / "probed.html"
    probed.write_text(report_file.read_text().replace("<head>", "<head>" + _PROBE, 1))
    res = _run(browser, ["--virtual-time-budget=10000", "--dump-dom", probed.as_uri()], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    m = re.search(r'<pre id="__probe">(.*?)</pre>', res.stdout, re.S)
    assert m, res.stderr[-2000:]
    probe = json.loads(
        m.group(1).replace("&quot;", '"').replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">")
    )
    assert probe["n"] == 8 and probe["broken"] == [] and probe["external"] == [] and probe["errors"] == []
    sections = probe["sections"]
    assert sections["coupling"]["drawn"] == 1 and sections["order"]["drawn"] == 1
    assert "Steady-state gains" in sections["coupling"]["text"]
    assert "No search for a missing effect" in sections["not-run"]["text"]
    _assert_not_blank(browser, report_file, tmp_path)
