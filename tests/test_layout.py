"""Static layout rules of the package, checked on the source (``ast``) of ``python/arxid/**/*.py``.

Nothing here imports arxid, so the rules hold whatever state the modules are in.

(a) Short functions: no function or method is longer than :data:`MAX_FUNCTION_LINES` lines, counted
    from its ``def`` line (decorators excluded) to the last line of its body. Nested functions count
    towards the function that holds them and are checked on their own as well.

(b) No private names across modules: ``from .x import _name`` (or ``from arxid.x import _name``) is
    refused when ``_name`` is a *name* defined in another module. Importing a private *module* is
    fine (``from . import _core``, ``from . import _metrics as metrics``), and so is importing a
    public name from a private module (``from ._metrics import rms``). Dunder names
    (``__version__``) are not private.

(c) No absolute self-imports inside functions: ``import arxid``, ``import arxid.x`` and
    ``from arxid[.x] import ...`` inside a function body re-enter the package through its public
    entry point; a module of the package imports its siblings relatively.

(d) No import cycles between arxid modules. The graph has one node per module (a package is the
    node of its ``__init__``) and one edge per import statement, module-level and function-level
    alike (a function-level import is a deferred module-level one: it still needs the other module
    importable while this one is), and the imports under ``if TYPE_CHECKING:`` too: a name in a type
    hint is still a dependency of meaning.
    How an import statement becomes edges:

    * ``import a.b.c`` and ``from a.b.c import name`` are an edge to module ``a.b.c``; when
      ``a.b.c.name`` is itself a module (``from . import x``, ``from .pkg import sub``), the edge
      goes to that module instead, since only the submodule is needed, not the namespace of its
      package's ``__init__``. ``from . import name`` of a non-module name is an edge to the
      package's ``__init__``.
    * Importing a module first runs the ``__init__`` of every package around it. Those packages get
      an edge too, **except the packages that also contain the importing module**: Python runs a
      module's enclosing packages before the module itself, so they are already initialised (or on
      the import stack) and importing a sibling adds no dependency on them. Hence ``arxid/__init__``
      importing ``arxid.data`` and ``arxid.effects`` importing ``arxid.data`` is no cycle, while
      ``arxid.datasets`` importing ``arxid.quadrotor.mixer`` does depend on ``arxid.quadrotor``'s
      ``__init__`` (and so on everything that ``__init__`` imports).

    Every cycle is reported as its strongly connected component with each import statement
    (file:line) that forms one of its edges.

(e) No module over :data:`MAX_MODULE_LINES` lines.

(f) At most :data:`MAX_TOP_ENTRIES` entries directly in ``python/arxid/``: the layers live in
    subpackages (docs/architecture.md; the import-linter contracts in pyproject.toml enforce them).
"""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

PKG_DIR = Path(__file__).resolve().parents[1] / "python" / "arxid"
PKG = "arxid"
MAX_FUNCTION_LINES = 80
MAX_MODULE_LINES = 700
#: Entries directly in ``python/arxid/`` (files and folders, the compiled core and caches excluded).
MAX_TOP_ENTRIES = 15


# ----------------------------------------------------------------------------------------------- discovery
def module_name(path: Path) -> str:
    """Dotted module name of a file under :data:`PKG_DIR` (``arxid/x/__init__.py`` is ``arxid.x``)."""
    parts = list(path.relative_to(PKG_DIR.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def source_files() -> list[Path]:
    """Every ``.py`` file of the package, sorted."""
    return sorted(p for p in PKG_DIR.rglob("*.py") if "__pycache__" not in p.parts)


def known_modules() -> set[str]:
    """Names of the package's modules, Python sources, stubs and compiled extensions alike."""
    names = {module_name(p) for p in source_files()}
    for p in PKG_DIR.rglob("*"):
        if p.suffix in (".pyi", ".so", ".pyd") and "__pycache__" not in p.parts:
            stem = p.name.split(".")[0]
            names.add(module_name(p.with_name(stem + ".py")))
    return names


MODULES = known_modules()


def rel(path: Path) -> str:
    """``python/arxid/...`` path of a file, for messages."""
    return str(path.relative_to(PKG_DIR.parents[1]))


def is_package(path: Path) -> bool:
    """True for a package's ``__init__.py``."""
    return path.name == "__init__.py"


# ----------------------------------------------------------------------------------------------- AST walk
@dataclass(frozen=True)
class ImportSite:
    """One import statement: where it is and whether it runs at import time or inside a function."""

    path: Path
    node: ast.Import | ast.ImportFrom
    in_function: bool
    type_checking: bool


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def import_sites(path: Path, tree: ast.AST) -> list[ImportSite]:
    """Every import statement of ``tree`` with its context (function body, ``if TYPE_CHECKING:``)."""
    out: list[ImportSite] = []

    def visit(node: ast.AST, in_function: bool, type_checking: bool) -> None:
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            out.append(ImportSite(path, node, in_function, type_checking))
            return
        if isinstance(node, ast.If) and _is_type_checking(node.test):
            for child in node.body:
                visit(child, in_function, True)
            for child in node.orelse:
                visit(child, in_function, type_checking)
            return
        inner = in_function or isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda))
        for child in ast.iter_child_nodes(node):
            visit(child, inner, type_checking)

    visit(tree, False, False)
    return out


def resolve_from(site: ImportSite) -> str | None:
    """Absolute module name of a ``from ... import`` statement's module (None outside arxid)."""
    node = site.node
    assert isinstance(node, ast.ImportFrom)
    if node.level == 0:
        base = node.module or ""
    else:
        here = module_name(site.path).split(".")
        # a package's __init__ is its own "." ; a plain module's "." is its package
        anchor = here if is_package(site.path) else here[:-1]
        anchor = anchor[: len(anchor) - (node.level - 1)]
        base = ".".join(anchor + ([node.module] if node.module else []))
    return base if base == PKG or base.startswith(PKG + ".") else None


def imported_modules(site: ImportSite) -> list[str]:
    """Modules of arxid that one import statement names directly (see rule (d))."""
    node = site.node
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name == PKG or a.name.startswith(PKG + ".")]
    base = resolve_from(site)
    if base is None:
        return []
    out = []
    for alias in node.names:
        sub = f"{base}.{alias.name}"
        out.append(sub if sub in MODULES else base)
    return out


def parse_all() -> tuple[dict[Path, ast.Module], list[str]]:
    """The AST of every source file, and ``file:line: error`` for those that do not parse (the rules
    below skip them; :func:`test_sources_parse` fails on them)."""
    trees, errors = {}, []
    for path in source_files():
        try:
            trees[path] = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        except SyntaxError as exc:
            errors.append(f"{rel(path)}:{exc.lineno}: {exc.msg}")
    return trees, errors


TREES, PARSE_ERRORS = parse_all()


def test_sources_parse():
    assert not PARSE_ERRORS, "source files that do not parse (the other layout rules skip them):\n  " + "\n  ".join(
        PARSE_ERRORS
    )


# ----------------------------------------------------------------------------------------------- (a)
def _code_start(fn: ast.FunctionDef | ast.AsyncFunctionDef) -> int:
    """First line that counts: the ``def`` line, or the line after the docstring when there is one
    (a numpydoc docstring documents; it is not code a reader has to hold in mind at once)."""
    first = fn.body[0]
    if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) and isinstance(first.value.value, str):
        return (first.end_lineno or first.lineno) + 1
    return fn.lineno


def long_functions() -> list[str]:
    """``file:line: name has N lines`` for every function longer than the limit."""
    bad = []
    for path, tree in TREES.items():
        stack: list[tuple[ast.AST, str]] = [(tree, "")]
        while stack:
            node, prefix = stack.pop()
            for child in ast.iter_child_nodes(node):
                name = prefix
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    name = f"{prefix}{child.name}"
                if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    length = (child.end_lineno or child.lineno) - _code_start(child) + 1
                    if length > MAX_FUNCTION_LINES:
                        bad.append(f"{rel(path)}:{child.lineno}: {module_name(path)}.{name} has {length} lines")
                stack.append((child, f"{name}." if name != prefix else prefix))
    return sorted(bad)


def test_functions_are_short():
    bad = long_functions()
    assert not bad, (
        f"{len(bad)} function(s) longer than {MAX_FUNCTION_LINES} lines (code after the docstring); "
        "split them into named stages:\n  " + "\n  ".join(bad)
    )


# ----------------------------------------------------------------------------------------------- (b)
def private_name_imports() -> list[str]:
    """``file:line: from X import _name`` for every private name imported from another arxid module."""
    bad = []
    for path, tree in TREES.items():
        for site in import_sites(path, tree):
            if not isinstance(site.node, ast.ImportFrom):
                continue
            base = resolve_from(site)
            if base is None:
                continue
            for alias in site.node.names:
                name = alias.name
                private = name.startswith("_") and not (name.startswith("__") and name.endswith("__"))
                if private and f"{base}.{name}" not in MODULES:
                    bad.append(f"{rel(path)}:{site.node.lineno}: imports private name {name!r} from {base}")
    return sorted(bad)


def test_no_private_names_across_modules():
    bad = private_name_imports()
    assert not bad, (
        "private names imported from other arxid modules (make them public in their module, or move them "
        "into a private module that is imported as a module):\n  " + "\n  ".join(bad)
    )


# ----------------------------------------------------------------------------------------------- (c)
def absolute_self_imports_in_functions() -> list[str]:
    """``file:line: import ...`` for every ``import arxid...`` / ``from arxid... import`` in a function."""
    bad = []
    for path, tree in TREES.items():
        for site in import_sites(path, tree):
            node = site.node
            if not site.in_function:
                continue
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names if a.name == PKG or a.name.startswith(PKG + ".")]
                if names:
                    bad.append(f"{rel(path)}:{node.lineno}: import {', '.join(names)} inside a function")
            elif node.level == 0 and node.module and (node.module == PKG or node.module.startswith(PKG + ".")):
                bad.append(f"{rel(path)}:{node.lineno}: from {node.module} import ... inside a function")
    return sorted(bad)


def test_no_absolute_self_imports_in_functions():
    bad = absolute_self_imports_in_functions()
    assert not bad, (
        "functions of the package import arxid through its top level; import the sibling module "
        "relatively (from .x import y):\n  " + "\n  ".join(bad)
    )


# ----------------------------------------------------------------------------------------------- (d)
def ancestors(module: str) -> list[str]:
    """Enclosing packages of a module, outermost first (``arxid.a.b`` -> ``arxid``, ``arxid.a``)."""
    parts = module.split(".")
    return [".".join(parts[:i]) for i in range(1, len(parts))]


def own_packages(path: Path) -> set[str]:
    """Packages whose ``__init__`` has run before the module of ``path`` runs (itself, for a package)."""
    name = module_name(path)
    return set(ancestors(name)) | ({name} if is_package(path) else set())


def import_graph() -> dict[str, dict[str, list[str]]]:
    """``{importer: {imported: [file:line, ...]}}`` of the package (rule (d))."""
    graph: dict[str, dict[str, list[str]]] = {module_name(p): {} for p in TREES}
    for path, tree in TREES.items():
        src = module_name(path)
        mine = own_packages(path)
        for site in import_sites(path, tree):
            for target in imported_modules(site):
                deps = [target] + [a for a in ancestors(target) if a not in mine]
                for dep in deps:
                    if dep != src and dep in graph:
                        graph[src].setdefault(dep, []).append(f"{rel(path)}:{site.node.lineno}")
    return graph


def strongly_connected(graph: dict[str, dict[str, list[str]]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on_stack: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            v, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = counter
                    counter += 1
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(graph[child]))))
                elif child in on_stack:
                    low[v] = min(low[v], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def import_cycles() -> list[str]:
    """One message per cycle: its modules, then every import (file:line) that is an edge inside it."""
    graph = import_graph()
    msgs = []
    for comp in strongly_connected(graph):
        members = set(comp)
        lines = [f"cycle between {', '.join(comp)}:"]
        for src in comp:
            for dst, where in sorted(graph[src].items()):
                if dst in members:
                    lines += [f"    {w}: {src} imports {dst}" for w in where]
        msgs.append("\n".join(lines))
    return msgs


def test_modules_are_at_most_700_lines():
    """(e) No module longer than :data:`MAX_MODULE_LINES` lines: a longer one holds more than one concept."""
    long = {
        rel(p): n for p in source_files() if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_MODULE_LINES
    }
    assert not long, f"modules over {MAX_MODULE_LINES} lines (split them by responsibility): {long}"


def test_the_package_root_shows_the_architecture():
    """(f) At most :data:`MAX_TOP_ENTRIES` entries in ``python/arxid/``: the subpackages and the few files
    every layer shares (the compiled core, built there by maturin, and ``__pycache__`` not counted)."""
    entries = sorted(p.name for p in PKG_DIR.iterdir() if p.name != "__pycache__" and not p.name.startswith("_core."))
    assert len(entries) <= MAX_TOP_ENTRIES, f"{len(entries)} entries in python/arxid: {entries}"


def test_no_import_cycles():
    cycles = import_cycles()
    assert not cycles, "import cycles between arxid modules (rule (d) of this file's docstring):\n  " + "\n  ".join(
        cycles
    )


# ----------------------------------------------------------------------------------------------- self-checks
def _site(code: str, path: Path) -> list[ImportSite]:
    return import_sites(path, ast.parse(code))


@pytest.mark.parametrize(
    ("code", "path", "expected"),
    [
        ("from .data import IOData", PKG_DIR / "effects.py", ["arxid.data"]),
        ("from . import data", PKG_DIR / "effects.py", ["arxid.data"]),
        ("from . import IOData", PKG_DIR / "effects.py", ["arxid"]),
        ("from .mixer import Mixer", PKG_DIR / "quadrotor" / "__init__.py", ["arxid.quadrotor.mixer"]),
        ("from ..data import IOData", PKG_DIR / "quadrotor" / "motor.py", ["arxid.data"]),
        ("from .quadrotor.mixer import Mixer", PKG_DIR / "datasets.py", ["arxid.quadrotor.mixer"]),
        ("import arxid.data", PKG_DIR / "cli.py", ["arxid.data"]),
        ("import numpy", PKG_DIR / "cli.py", []),
    ],
)
def test_import_resolution(code, path, expected):
    (site,) = _site(code, path)
    assert imported_modules(site) == expected


def test_type_checking_and_function_context():
    code = (
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n    from .model import ArxModel\n"
        "def f():\n    from . import data\n"
    )
    sites = _site(code, PKG_DIR / "sanity.py")
    assert [(s.in_function, s.type_checking) for s in sites] == [(False, False), (False, True), (True, False)]


def test_cycle_finder():
    graph = {"a": {"b": ["x:1"]}, "b": {"c": ["x:2"]}, "c": {"a": ["x:3"]}, "d": {"a": ["x:4"]}}
    assert strongly_connected(graph) == [["a", "b", "c"]]
