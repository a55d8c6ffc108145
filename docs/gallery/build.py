"""Run the worked examples of ``examples/`` and write the gallery pages of the documentation site.

Each script runs in its own process with its figure folder as argument; its printed output, its
figures and its source become ``docs/gallery/generated/<name>.md`` (git-ignored, rebuilt by
``make docs``). A script that needs the measured data skips with a message when they are absent.
A script that fails fails the build.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = REPO / "examples"
GENERATED = REPO / "docs" / "gallery" / "generated"
sys.path.insert(0, str(REPO / "tests"))
from conftest import shared_data_dir  # noqa: E402  (one rule for where the measured data live)


def _markdown(docstring: str) -> str:
    """reST roles of the docstrings (:func:`x`) as code spans."""
    return re.sub(r":\w+:`~?([^`]+)`", r"`\1`", docstring)


def _run(script: Path, out: Path) -> str:
    env = dict(os.environ, MPLBACKEND="Agg")
    data = shared_data_dir()
    if data is not None:
        env["ARXID_SHARED_DATA"] = str(data)
    start = time.perf_counter()
    run = subprocess.run([sys.executable, str(script), str(out)], capture_output=True, text=True, env=env, cwd=REPO)
    if run.returncode != 0:
        sys.exit(f"gallery: {script.name} failed:\n{run.stdout}\n{run.stderr}")
    print(f"gallery: {script.name} ran in {time.perf_counter() - start:.1f} s")
    return run.stdout


def _page(script: Path) -> str:
    out = GENERATED / script.stem
    out.mkdir(parents=True, exist_ok=True)
    for old in out.glob("*.png"):
        old.unlink()
    printed = _run(script, out)
    source = script.read_text(encoding="utf-8")
    doc = source.split('"""')[1].strip()
    title, _, body = doc.partition("\n")
    figures = "\n\n".join(f"![{png.stem}]({script.stem}/{png.name})" for png in sorted(out.glob("*.png")))
    return (
        f"# {title.rstrip('.')}\n\n{_markdown(body.strip())}\n\n"
        f"Run it yourself: `python examples/{script.name} FIGURE_FOLDER`.\n\n"
        f"## What it prints\n\n```text\n{printed.rstrip()}\n```\n\n"
        + (f"## Figures\n\n{figures}\n\n" if figures else "")
        + f"## The script\n\n```python\n{source.rstrip()}\n```\n"
    )


def main() -> None:
    GENERATED.mkdir(parents=True, exist_ok=True)
    scripts = sorted(EXAMPLES.glob("*.py"))
    index = ["# Gallery", "", "Worked examples, run by `make docs` (and so in CI) on every build.", ""]
    for script in scripts:
        page = _page(script)
        (GENERATED / f"{script.stem}.md").write_text(page, encoding="utf-8")
        index.append(f"- [{page.splitlines()[0][2:]}]({script.stem}.md)")
    (GENERATED / "index.md").write_text("\n".join(index) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
