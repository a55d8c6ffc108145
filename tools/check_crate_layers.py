"""The layers of the Rust crate, checked on its source (``rust/**/*.rs``), as import-linter checks the package's.

Each folder of ``rust/`` is one concept (a top-level file such as ``error.rs`` is one too), and the
concepts sit in :data:`LAYERS`, lowest first. A file may name its own concept and the layers below it
(``use crate::linalg::qr::...``, ``crate::arx::fit::fit(...)``, ``super::...``), never a layer above,
and never a concept beside it in its own layer. The crate root ``lib.rs`` declares every module and is
not checked. Also checked: no file over :data:`MAX_LINES` lines, and only the boundary (``python/``)
names pyo3 or numpy, so that the core never sees Python.

A new concept is a folder with a ``mod.rs`` (one or two lines saying what it is), declared in
``lib.rs``, and a place in :data:`LAYERS` (and in docs/architecture.md); its pyo3 functions go in
``python/<concept>.rs``.

Run from the repository root: ``python tools/check_crate_layers.py [rust-dir]``; exit status 1 and
one line per problem when the crate breaks a rule.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

#: The concepts, lowest layer first. Concepts in one tuple sit side by side: they may use the
#: layers below, not each other.
LAYERS: tuple[tuple[str, ...], ...] = (
    ("error",),
    ("linalg",),
    ("arx",),
    ("simulate",),
    ("sweep",),
    ("pem", "scoring", "io", "subspace"),
    ("python",),
)
MAX_LINES = 700
#: The only concept that may name pyo3 or numpy.
BOUNDARY = "python"
CRATE_ROOT = "lib.rs"

_COMMENT = re.compile(r"//[^\n]*|/\*.*?\*/", re.DOTALL)
_PATH = re.compile(r"\b(crate|(?:super::)*super)::(\{|[A-Za-z_]\w*)")
_PYTHON_CRATES = re.compile(r"(?<![\w:])(?:pyo3|numpy)::")


def module_path(file: Path, root: Path) -> list[str]:
    """The module path of a source file: ``linalg/qr.rs`` is ``[linalg, qr]``, ``io/mod.rs`` is ``[io]``."""
    parts = list(file.relative_to(root).with_suffix("").parts)
    return parts[:-1] if parts[-1] == "mod" else parts


def without_comments(text: str) -> str:
    """The source with its comments blanked, line breaks kept (so line numbers still hold)."""
    return _COMMENT.sub(lambda m: "\n" * m.group(0).count("\n"), text)


def group_heads(text: str, start: int) -> list[str]:
    """The first name of each path in the ``{...}`` group opening at ``text[start]``."""
    depth, item, heads = 0, "", []
    for ch in text[start:]:
        if ch == "{":
            depth += 1
            if depth == 1:
                continue
        elif ch == "}":
            depth -= 1
            if depth == 0:
                break
        if depth == 1 and ch == ",":
            heads.append(item)
            item = ""
        else:
            item += ch
    heads.append(item)
    names = [re.match(r"\s*([A-Za-z_]\w*)", h) for h in heads]
    return [n.group(1) for n in names if n and n.group(1) != "self"]


def used_concepts(text: str, module: list[str]) -> list[tuple[int, str, str]]:
    """``(line, concept, path as written)`` of every crate path in the (comment-free) source."""
    found = []
    for m in _PATH.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        if m.group(1) == "crate":
            base: list[str] = []
        else:
            ups = m.group(1).count("super")
            # A `super` beyond the crate root does not compile; rustc reports it, not this check.
            base = module[: len(module) - ups] if ups <= len(module) else []
        heads = group_heads(text, m.start(2)) if m.group(2) == "{" else [m.group(2)]
        for head in heads:
            full = base + [head]
            found.append((line, full[0], f"{m.group(1)}::{'::'.join(full[len(base) :])}"))
    return found


def root_exports(root: Path) -> dict[str, str]:
    """The concept behind each name the crate root re-exports (``pub use arx::fit::{fit, Fit};``)."""
    lib = root / CRATE_ROOT
    text = without_comments(lib.read_text(encoding="utf-8")) if lib.exists() else ""
    exports = {}
    for m in re.finditer(r"\bpub\s+use\s+(\w+)::([^;]*);", text):
        tail = m.group(2)
        names = re.findall(r"\w+", tail[tail.index("{") :]) if "{" in tail else [tail.split("::")[-1].strip()]
        exports.update(dict.fromkeys(names, m.group(1)))
    return exports


def concept_of(file: Path, root: Path) -> str:
    return file.relative_to(root).parts[0].removesuffix(".rs")


def layer_index(layers: tuple[tuple[str, ...], ...]) -> dict[str, int]:
    return {concept: i for i, layer in enumerate(layers) for concept in layer}


def order_text(layers: tuple[tuple[str, ...], ...]) -> str:
    return " < ".join(" | ".join(layer) for layer in layers)


def file_problems(file: Path, root: Path, layers: tuple[tuple[str, ...], ...], exports: dict[str, str]) -> list[str]:
    """What breaks a rule in one source file (``exports``: see :func:`root_exports`)."""
    rel = file.relative_to(root.parent) if root.parent != root else file
    text = file.read_text(encoding="utf-8")
    problems = []
    n_lines = len(text.splitlines())
    if n_lines > MAX_LINES:
        problems.append(f"{rel}: {n_lines} lines, more than {MAX_LINES}: split it along a seam of its concept")
    if file.relative_to(root).as_posix() == CRATE_ROOT:
        return problems
    rank = layer_index(layers)
    own = concept_of(file, root)
    if own not in rank:
        depth = len(file.relative_to(root).parts)
        place = rel.parents[depth - 2] if depth > 1 else rel  # the concept's folder: one line per concept
        return problems + [
            f"{place}: the concept {own!r} has no layer: add it to LAYERS in tools/check_crate_layers.py "
            f"(and to the crate's map in docs/architecture.md); the layers are {order_text(layers)}"
        ]
    code = without_comments(text)
    for line, head, written in used_concepts(code, module_path(file, root)):
        used = exports.get(head, head)
        if used == own or used not in rank or rank[used] < rank[own]:
            continue  # its own folder, a lower layer, or an item of the crate root itself
        where = "beside it in the same layer" if rank[used] == rank[own] else "in a higher layer"
        problems.append(
            f"{rel}:{line}: {own} uses {used} ({written}), {where}; the layers run {order_text(layers)}: "
            "move what both need down to a lower layer, or the user up"
        )
    for m in re.finditer(r"#\[path\b", code):
        problems.append(f"{rel}:{code.count(chr(10), 0, m.start()) + 1}: #[path] hides where a module lives")
    if own != BOUNDARY:
        for m in _PYTHON_CRATES.finditer(code):
            line = code.count("\n", 0, m.start()) + 1
            problems.append(f"{rel}:{line}: {own} names {m.group(0)[:-2]}: only rust/{BOUNDARY}/ may touch Python")
    return problems


def crate_problems(root: Path, layers: tuple[tuple[str, ...], ...] = LAYERS) -> list[str]:
    """Every problem in the crate under ``root`` (the folder holding ``lib.rs``)."""
    exports = root_exports(root)
    found = [p for file in sorted(root.rglob("*.rs")) for p in file_problems(file, root, layers, exports)]
    return list(dict.fromkeys(found))


def main(argv: list[str]) -> int:
    root = Path(argv[1]) if len(argv) > 1 else Path(__file__).resolve().parents[1] / "rust"
    problems = crate_problems(root)
    for p in problems:
        print(p)
    if problems:
        print(f"the crate breaks its layers ({order_text(LAYERS)}) or its size limit: {len(problems)} problem(s)")
        return 1
    n_files = sum(1 for _ in root.rglob("*.rs"))
    print(f"crate layers ok: {n_files} files, {order_text(LAYERS)}, none over {MAX_LINES} lines")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
