"""The Rust crate's layers and file sizes (``tools/check_crate_layers.py``), on the tree and on small bad trees.

The Python equivalents (no module over 700 lines, no import cycle) are in ``test_layout.py``; the
package's layers are import-linter's contracts in ``pyproject.toml``.
"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tools" / "check_crate_layers.py"
_spec = importlib.util.spec_from_file_location("check_crate_layers", SCRIPT)
assert _spec is not None and _spec.loader is not None
layers = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(layers)

LAYERS = (("error",), ("linalg",), ("arx",), ("pem", "io"), ("python",))


def crate(tmp_path: Path, files: dict[str, str]) -> Path:
    """A crate under ``tmp_path/rust`` with a root declaring nothing and these files."""
    root = tmp_path / "rust"
    for name, text in {"lib.rs": "pub mod arx;\npub mod linalg;\n", **files}.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text, encoding="utf-8")
    return root


def problems(tmp_path: Path, files: dict[str, str]) -> list[str]:
    return layers.crate_problems(crate(tmp_path, files), LAYERS)


def test_the_crate_keeps_its_layers_and_sizes():
    assert layers.crate_problems(ROOT / "rust") == []
    run = subprocess.run([sys.executable, str(SCRIPT)], capture_output=True, text=True, check=False)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "crate layers ok" in run.stdout


def test_every_concept_folder_has_a_layer_and_a_face():
    folders = {p.name for p in (ROOT / "rust").iterdir() if p.is_dir()}
    placed = {c for layer in layers.LAYERS for c in layer}
    assert folders <= placed, folders - placed
    for folder in folders:
        face = (ROOT / "rust" / folder / "mod.rs").read_text(encoding="utf-8")
        assert face.startswith("//! "), f"rust/{folder}/mod.rs does not say what the concept is"


def test_downward_and_own_folder_edges_pass(tmp_path):
    assert (
        problems(
            tmp_path,
            {
                "error.rs": "pub enum ArxError {}\n",
                "linalg/mod.rs": "//! LA\npub mod qr;\n",
                "linalg/qr.rs": "use crate::error::ArxError;\nuse super::mod_item;\n",
                "arx/fit.rs": "use crate::{error::ArxError, linalg::qr};\nuse crate::arx::structure::Data;\n",
                "pem/search.rs": "use super::super::arx::fit;\nfn f() { crate::linalg::qr::take_r(); }\n",
                "python/pem.rs": "use pyo3::prelude::*;\nuse crate::pem::search::pem;\n",
            },
        )
        == []
    )


@pytest.mark.parametrize(
    ("source", "expected"),
    [
        ("use crate::arx::structure::Data;\n", "rust/linalg/qr.rs:1: linalg uses arx (crate::arx), in a higher layer"),
        ("\n\nfn f() { crate::python::run(); }\n", "rust/linalg/qr.rs:3: linalg uses python (crate::python)"),
        ("use crate::{error::ArxError, arx::fit};\n", "linalg uses arx (crate::arx)"),
        ("use super::super::arx::fit;\n", "linalg uses arx (super::super::arx)"),
        ("use crate::Data;\n", "linalg uses arx (crate::Data)"),  # a root re-export is its concept
    ],
)
def test_an_upward_edge_is_named_with_its_line(tmp_path, source, expected):
    root = crate(tmp_path, {"linalg/qr.rs": source})
    (root / "lib.rs").write_text("pub mod arx;\npub use arx::structure::{Data, Structure};\n", encoding="utf-8")
    found = layers.crate_problems(root, LAYERS)
    assert len(found) == 1 and expected in found[0], found


def test_comments_are_not_edges(tmp_path):
    source = "//! See [`crate::python::run`].\n/* crate::python */\nfn f() {} // crate::pem::x\n"
    assert problems(tmp_path, {"linalg/qr.rs": source}) == []


def test_concepts_side_by_side_may_not_use_each_other(tmp_path):
    (found,) = problems(tmp_path, {"pem/search.rs": "use crate::io::csv_read;\n"})
    assert "pem uses io (crate::io), beside it in the same layer" in found


def test_a_concept_without_a_layer_is_refused(tmp_path):
    (found,) = problems(tmp_path, {"subspace/mod.rs": "//! Subspace\n", "subspace/lq/hankel.rs": "\n"})
    assert found.startswith("rust/subspace: the concept 'subspace' has no layer: add it to LAYERS"), found


def test_a_long_file_is_refused(tmp_path):
    (found,) = problems(tmp_path, {"arx/fit.rs": "// line\n" * (layers.MAX_LINES + 1)})
    assert found.startswith(f"rust/arx/fit.rs: {layers.MAX_LINES + 1} lines, more than {layers.MAX_LINES}")
    assert problems(tmp_path / "ok", {"arx/fit.rs": "// line\n" * layers.MAX_LINES}) == []


def test_only_the_boundary_touches_python(tmp_path):
    (found,) = problems(tmp_path, {"arx/fit.rs": "fn f(py: pyo3::Python<'_>) {}\n"})
    assert "rust/arx/fit.rs:1: arx names pyo3: only rust/python/ may touch Python" in found
    assert problems(tmp_path / "ok", {"python/arx.rs": "use numpy::PyArray1;\nfn f() { pyo3::x(); }\n"}) == []


def test_a_path_attribute_is_refused(tmp_path):
    (found,) = problems(tmp_path, {"arx/mod.rs": '#[path = "../elsewhere.rs"]\nmod fit;\n'})
    assert "#[path] hides where a module lives" in found


def test_the_script_fails_on_a_bad_tree(tmp_path):
    root = crate(tmp_path, {"linalg/qr.rs": "use crate::python::run;\n"})
    run = subprocess.run([sys.executable, str(SCRIPT), str(root)], capture_output=True, text=True, check=False)
    assert run.returncode == 1
    assert "rust/linalg/qr.rs:1: linalg uses python (crate::python), in a higher layer" in run.stdout
