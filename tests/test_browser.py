"""The HTML report in a real browser: headless Chromium renders it offline, every plot loads, no errors.

Skipped with a reason when no Chromium is installed (``apt-get install chromium``; ``.ci/run`` does).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

pytestmark = pytest.mark.browser

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable", "chrome")


def _browser() -> str | None:
    env = os.environ.get("ARXID_BROWSER")
    if env and shutil.which(env):
        return shutil.which(env)
    for name in BROWSERS:
        path = shutil.which(name)
        if path:
            return path
    return None


@pytest.fixture(scope="module")
def browser():
    path = _browser()
    if path is None:
        pytest.skip("no headless Chromium found (install the Debian package 'chromium' or set ARXID_BROWSER)")
    return path


@pytest.fixture(scope="module")
def report_file(tmp_path_factory):
    """A full report of a small system whose gain follows a draining battery."""
    import arxid
    from arxid.analysis.report import build_report

    rng = np.random.default_rng(3)
    n = 2500
    u = rng.standard_normal(n)
    vbat = np.linspace(4.2, 3.4, n) + 0.01 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(1, n):
        y[t] = 0.9 * y[t - 1] + 0.3 * u[t - 1] * vbat[t - 1] + 0.02 * rng.standard_normal()
    data = arxid.IOData(y, u, 0.01, output_name="y", input_names=("u",), extra={"vbat": vbat})
    rep = build_report(data, split=0.7, grid={"na": [1, 2], "nb": [1], "nk": [0, 1, 2]}, max_steps=2)
    path = tmp_path_factory.mktemp("report") / "report.html"
    rep.save(path)
    return path


_PROBE = """<script>
window.__errors = [];
window.addEventListener('error', function (e) {
  var what = e.message || (e.target && (e.target.alt || e.target.src || e.target.href)) || 'resource';
  window.__errors.push('error: ' + String(what).slice(0, 120));
}, true);
(function () { var ce = console.error; console.error = function () {
  window.__errors.push('console.error: ' + Array.prototype.join.call(arguments, ' '));
  ce.apply(console, arguments); }; })();
window.addEventListener('load', function () {
  var imgs = Array.prototype.slice.call(document.images);
  var res = (performance.getEntriesByType('resource') || []).map(function (r) { return r.name; });
  var out = {n: imgs.length,
             broken: imgs.filter(function (i) { return !(i.complete && i.naturalWidth > 0 && i.naturalHeight > 0); })
                         .map(function (i) { return i.alt; }),
             external: res.filter(function (n) { return n.indexOf('data:') !== 0; }),
             errors: window.__errors,
             diagnosis: (function () {
               try { return JSON.parse(document.getElementById('diagnosis').textContent).ladder.length; }
               catch (e) { return 'unreadable: ' + e; } })(),
             sections: (function () { var o = {};
               Array.prototype.forEach.call(document.querySelectorAll('section'), function (s) {
                 var imgs = Array.prototype.slice.call(s.querySelectorAll('img'));
                 o[s.id] = {text: s.innerText,
                            drawn: imgs.filter(function (i) { return i.naturalWidth > 0; }).length};
               }); return o; })()};
  var pre = document.createElement('pre'); pre.id = '__probe'; pre.textContent = JSON.stringify(out);
  document.body.appendChild(pre);
});
</script>"""


def _run(browser: str, args: list[str], tmp_path: Path) -> subprocess.CompletedProcess:
    cmd = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--hide-scrollbars",
        "--no-first-run",
        "--no-default-browser-check",
        "--disable-extensions",
        "--disable-background-networking",
        f"--user-data-dir={tmp_path / 'profile'}",
        "--enable-logging=stderr",
        "--v=0",
        *args,
    ]
    for attempt in range(2):  # headless Chromium occasionally crashes at start-up on a loaded machine  # noqa: B007
        try:
            res = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        except subprocess.TimeoutExpired:
            pytest.fail("headless Chromium did not finish within 120 s")
        if res.returncode >= 0:
            break
    return res


def _probe(browser: str, report: Path, tmp_path: Path) -> dict:
    """Render ``report`` with the probe script; what the page loaded, logged and shows per section."""
    html = report.read_text()
    probed = tmp_path / "probed.html"
    probed.write_text(html.replace("<head>", "<head>" + _PROBE, 1))
    res = _run(browser, ["--virtual-time-budget=10000", "--dump-dom", probed.as_uri()], tmp_path)
    assert res.returncode == 0, res.stderr[-2000:]
    m = re.search(r'<pre id="__probe">(.*?)</pre>', res.stdout, re.S)
    assert m, "the page's load handler did not run:\n" + res.stderr[-2000:]
    probe = json.loads(
        m.group(1).replace("&quot;", '"').replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">")
    )
    assert probe["n"] == html.count("<img "), probe
    assert probe["n"] >= 8
    assert probe["broken"] == [], f"plots that did not load: {probe['broken']}"
    assert probe["external"] == [], f"the report fetched {probe['external']}: it must be self-contained"
    assert probe["errors"] == [], probe["errors"]
    assert isinstance(probe["diagnosis"], int) and probe["diagnosis"] >= 1, probe["diagnosis"]  # embedded JSON parses
    # what the browser itself logged about the page (console messages carry the page's URL)
    page_lines = [
        ln
        for ln in res.stderr.splitlines()
        if ("CONSOLE" in ln or "Uncaught" in ln or "Failed to load resource" in ln or "net::ERR" in ln)
    ]
    assert page_lines == [], "\n".join(page_lines)
    return probe


def _assert_not_blank(browser: str, report: Path, tmp_path: Path, height: int = 2400) -> None:
    from PIL import Image

    shot = tmp_path / "shot.png"
    res = _run(
        browser,
        [f"--window-size=1280,{height}", "--virtual-time-budget=10000", f"--screenshot={shot}", report.as_uri()],
        tmp_path,
    )
    assert res.returncode == 0 and shot.is_file(), res.stderr[-2000:]
    img = np.asarray(Image.open(shot).convert("L"), dtype=float)
    assert img.shape[0] >= 2000 and img.shape[1] >= 1000
    inked = (img < 200).mean()  # text, table lines and plots
    assert inked > 0.02, f"only {inked:.2%} of the screenshot is drawn: the page looks blank"
    assert img.std() > 20
    # the plots are drawn, not only text: a band of the page holds mid-tone colours (lines, colour maps)
    rgb = np.asarray(Image.open(shot).convert("RGB"), dtype=float)
    colourful = (rgb.max(axis=2) - rgb.min(axis=2) > 60).mean()
    assert colourful > 0.002, "no coloured plot pixels in the screenshot"


def _assert_frequency_section(probe: dict) -> None:
    freq = probe["sections"]["frequency"]
    assert freq["drawn"] >= 1, "the frequency section has no plot"
    assert re.search(
        r"the model (misses the data (between|at) [\d.]+|matches the data within the uncertainty)", freq["text"]
    )


def test_report_renders_with_every_plot_loaded_and_no_errors(browser, report_file, tmp_path):
    probe = _probe(browser, report_file, tmp_path)
    _assert_frequency_section(probe)


def test_report_screenshot_is_not_blank(browser, report_file, tmp_path):
    _assert_not_blank(browser, report_file, tmp_path)


def test_demo_report_in_the_browser(browser, demo_run, tmp_path):
    """The report ``make demo`` writes (on a shorter flight): loads offline, every plot drawn."""
    path = demo_run[0]
    probe = _probe(browser, path, tmp_path)
    _assert_frequency_section(probe)
    ladder = probe["sections"]["ladder"]["text"]
    assert "vbat" in ladder and "effect" in ladder
    residuals = probe["sections"]["residuals"]["text"]
    assert "The residuals are white:" in residuals  # plain words before the details
    assert residuals.index("The residuals are white:") < residuals.index("Details")
    _assert_not_blank(browser, path, tmp_path)


@pytest.mark.realdata
def test_silverbox_report_in_the_browser(browser, shared_data, tmp_path):
    """Silverbox (cubic spring, 14,350 samples of the multisine part, ARX(4,3,0)): the ladder adds
    y^3+const first, and the report says which kind of step each was. Its rungs are physical effects
    (a structure step such as nb+1 stands on its own only when no effect is significant)."""
    import arxid
    from arxid.analysis.report import build_report

    data = arxid.IOData.from_csv(
        shared_data / "silverbox" / "SNLS80mV.csv",
        output="V2",
        inputs=["V1"],
        ts=1 / 610.35,
        units={"V2": "V", "V1": "V"},
    )
    rep = build_report(data[40650:55000], orders=(4, 3, 0), max_steps=2, source="Silverbox SNLS80mV.csv")
    path = rep.save(tmp_path / "silverbox.html")
    probe = _probe(browser, path, tmp_path)
    ladder = probe["sections"]["ladder"]["text"]
    assert re.search(r"\n1\ty\^3\+const\teffect\t", ladder) and "structure change" not in ladder, ladder
    assert re.search(r"The added effects \(y\^3\+const.*?\) removed \d+ % of the validation error", ladder), ladder
    _assert_frequency_section(probe)
    assert "output: V2 [V]" in probe["sections"]["data"]["text"]  # --units / units= reach the report
    _assert_not_blank(browser, path, tmp_path)
