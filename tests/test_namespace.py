"""``import arxid`` reaches every subpackage as an attribute, and loads the optional ones only when used."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import arxid

SUBPACKAGES = sorted(
    p.name
    for p in (Path(arxid.__file__).parent).iterdir()
    if (p / "__init__.py").is_file() and not p.name.startswith("_")
)


def test_every_subpackage_is_an_attribute_of_a_bare_import_and_listed_by_dir():
    # a fresh interpreter: this test session has imported the subpackages already
    code = (
        "import sys, arxid\n"
        "assert 'arxid.inputs' not in sys.modules and 'arxid.plots' not in sys.modules\n"
        f"for name in {SUBPACKAGES!r}:\n"
        "    assert name in dir(arxid), name\n"
        "    assert getattr(arxid, name).__name__ == 'arxid.' + name\n"
        "print(arxid.inputs.prbs(4).n_samples)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "15"
    assert {"analysis", "inputs", "plots", "quadrotor", "selection"} <= set(SUBPACKAGES)
