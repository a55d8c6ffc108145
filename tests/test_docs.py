"""The examples in docstrings and in the README run and say what they claim."""

from __future__ import annotations

import doctest
import re
from pathlib import Path

import pytest

import arxid.data.iodata
import arxid.models.arx_model

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("module", [arxid.data.iodata, arxid.models.arx_model])
def test_docstring_examples(module):
    result = doctest.testmod(module, optionflags=doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


def test_readme_quick_start_is_two_commands_and_example_runs():
    text = (REPO / "README.md").read_text()
    quick = text.split("## Quick start", 1)[1].split("##", 1)[0]
    commands = [line.split("#")[0].strip() for line in quick.splitlines() if line.startswith("make ")]
    assert commands == ["make demo", "make test"]
    example = re.search(r"## Example\n+```python\n(.*?)```", text, re.S).group(1)
    namespace: dict = {}
    exec(compile(example, "README example", "exec"), namespace)
    model = namespace["model"]
    assert model.nk_ == (8,) and abs(model.parameters_[0] + 1.5) < 0.01


def test_every_public_function_documents_its_parameters():
    import inspect

    for fn in (arxid.arx, arxid.ArxModel.predict, arxid.ArxModel.simulate, arxid.IOData.from_csv):
        doc = inspect.getdoc(fn) or ""
        for name in inspect.signature(fn).parameters:
            if name in ("self", "cls", "kwargs"):
                continue
            assert re.search(rf"^\s*{name}\b", doc, re.M) or name in doc, (
                f"{fn.__qualname__}: parameter {name} undocumented"
            )
