"""Regenerate the screenshots of the demo report in docs/images (1280 px wide, headless Chromium).

Run from the repository root: ``.venv/bin/python docs/make_screenshots.py`` (needs ``chromium``).
"""

from __future__ import annotations

import io
import json
import re
import shutil
import subprocess
import tempfile
from pathlib import Path

from PIL import Image

from arxid.analysis.demo import run_demo

WIDTH = 1280
OUT = Path(__file__).resolve().parent / "images"
# (file, first section, last section): each picture runs from the top of one section to the end of another
SHOTS = (
    ("report-data-sweep.png", None, "sweep"),
    ("report-compare-residuals.png", "compare", "residuals"),
    ("report-frequency.png", "frequency", "frequency"),
    ("report-suspects-ladder.png", "suspects", "ladder"),
)
PROBE = """<script>window.addEventListener('load', function () {
  var o = {height: document.documentElement.scrollHeight};
  document.querySelectorAll('section').forEach(function (s) {
    var r = s.getBoundingClientRect(); o[s.id] = [r.top + window.scrollY, r.bottom + window.scrollY]; });
  var p = document.createElement('pre'); p.id = '__probe'; p.textContent = JSON.stringify(o);
  document.body.appendChild(p); });</script>"""


def _chromium(args: list[str], profile: Path) -> str:
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        raise SystemExit("no chromium found")
    cmd = [browser, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars", f"--user-data-dir={profile}"]
    return subprocess.run(cmd + args, capture_output=True, text=True, timeout=180, check=True).stdout


def main() -> None:
    tmp = Path(tempfile.mkdtemp())
    report = tmp / "demo.html"
    run_demo(report, stream=io.StringIO())
    probed = tmp / "probed.html"
    probed.write_text(report.read_text().replace("<head>", "<head>" + PROBE, 1))
    dom = _chromium([f"--window-size={WIDTH},1000", "--virtual-time-budget=10000", "--dump-dom", probed.as_uri()], tmp)
    pos = json.loads(re.search(r'<pre id="__probe">(.*?)</pre>', dom, re.S).group(1).replace("&quot;", '"'))
    shot = tmp / "full.png"
    height = int(pos["height"]) + 20
    _chromium([f"--window-size={WIDTH},{height}", f"--screenshot={shot}", report.as_uri()], tmp)
    full = Image.open(shot).convert("RGB")
    OUT.mkdir(exist_ok=True)
    for name, first, last in SHOTS:
        top = 0 if first is None else int(pos[first][0]) - 10
        crop = full.crop((0, top, WIDTH, int(pos[last][1]) + 10))
        crop.quantize(colors=128, method=Image.Quantize.MEDIANCUT).save(OUT / name, optimize=True)
        print(OUT / name, crop.size)


if __name__ == "__main__":
    main()
