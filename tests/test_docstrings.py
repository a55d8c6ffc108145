"""Every public callable of arxid has a numpydoc docstring that documents what it takes and gives.

Modelled on python-control's ``docstrings_test.py``. The public callables are the names in the
``__all__`` of :data:`PUBLIC_MODULES` (a module without ``__all__``: the public functions and
classes it defines), and the public methods and properties of the public classes (their own, not
inherited ones). For each:

* a docstring with a summary line (``__doc__`` itself: an inherited docstring does not count, nor
  the ``Name(field, ...)`` text ``dataclasses`` writes for a class without one);
* functions and methods whose signature has parameters other than ``self``/``cls``: a
  ``Parameters`` (or ``Other Parameters``) section naming every one of them, ``*args`` and
  ``**kwargs`` included (numpydoc's ``a, b : int`` lines name several);
* functions and methods that return something (a return annotation other than ``None``, or, without
  an annotation, a ``return <value>`` or a ``yield`` in their own body): a ``Returns`` or ``Yields``
  section;
* classes: a class whose body defines ``__init__`` documents its parameters in the class or the
  ``__init__`` docstring; dataclasses (generated ``__init__``), properties and exception classes
  need the summary line only.

Modules that do not exist (yet) are skipped with the reason; a module that exists but does not
import fails.
"""

from __future__ import annotations

import ast
import dataclasses
import importlib
import importlib.util
import inspect
import re
import textwrap
import types
from pathlib import Path

import pytest

PKG_DIR = Path(__file__).resolve().parents[1] / "python" / "arxid"

#: The documented modules; public submodules of the packages among them are added by :func:`modules`.
PUBLIC_MODULES = (
    "arxid",
    "arxid.data",
    "arxid.models.arx_model",
    "arxid.models.polynomial",
    "arxid.models.pem",
    "arxid.models.convert",
    "arxid.selection.search",
    "arxid.checks.comparison",
    "arxid.checks.residual_analysis",
    "arxid.checks.failures",
    "arxid.checks.binning",
    "arxid.selection.grid",
    "arxid.selection.engine",
    "arxid.selection.ranking",
    "arxid.selection.table",
    "arxid.selection.choice",
    "arxid.selection.refine",
    "arxid.diagnosis.suspects",
    "arxid.diagnosis.result",
    "arxid.diagnosis.ladder",
    "arxid.analysis.pipeline",
    "arxid.models.effects",
    "arxid.selection.sanity",
    "arxid.quadrotor.datasets",
    "arxid.analysis.report",
    "arxid.plots",
    "arxid.quadrotor",
    "arxid.quadrotor.mixer",
    "arxid.quadrotor.motor",
    "arxid.quadrotor.physical",
    "arxid.quadrotor.rotational",
    "arxid.quadrotor.setmembership",
    "arxid.quadrotor.thrust",
)


def module_path(name: str) -> Path | None:
    """Source file of an arxid module (``x.py`` or ``x/__init__.py``), None when there is none."""
    parts = name.split(".")[1:]
    base = PKG_DIR.joinpath(*parts) if parts else PKG_DIR
    for cand in (base / "__init__.py", base.with_suffix(".py")):
        if cand.is_file():
            return cand
    return None


def modules() -> list[str]:
    """:data:`PUBLIC_MODULES` plus the public submodules (on disk) of the packages among them."""
    out = list(PUBLIC_MODULES)
    for name in PUBLIC_MODULES:
        path = module_path(name)
        if name == "arxid" or path is None or path.name != "__init__.py":
            continue
        for sub in sorted(path.parent.iterdir()):
            stem = sub.stem if sub.suffix == ".py" else sub.name
            is_mod = (sub.suffix == ".py" and sub.name != "__init__.py") or (sub / "__init__.py").is_file()
            if is_mod and not stem.startswith("_") and f"{name}.{stem}" not in out:
                out.append(f"{name}.{stem}")
    return out


# ----------------------------------------------------------------------------------------------- numpydoc
def sections(doc: str) -> dict[str, list[str]]:
    """Lines of each numpydoc section (a title underlined with dashes), keyed by title."""
    lines = inspect.cleandoc(doc).splitlines()
    heads = [
        i for i in range(len(lines) - 1) if lines[i].strip() and re.fullmatch(r"-{3,}", lines[i + 1].strip() or "x")
    ]
    out: dict[str, list[str]] = {}
    for j, i in enumerate(heads):
        end = heads[j + 1] if j + 1 < len(heads) else len(lines)
        out.setdefault(lines[i].strip(), []).extend(lines[i + 2 : end])
    return out


def documented_parameters(doc: str) -> set[str]:
    """Names documented in the ``Parameters`` and ``Other Parameters`` sections (``*`` stripped)."""
    names: set[str] = set()
    secs = sections(doc)
    for title in ("Parameters", "Other Parameters"):
        body = [ln for ln in secs.get(title, []) if ln.strip()]
        if not body:
            continue
        indent = min(len(ln) - len(ln.lstrip()) for ln in body)
        for ln in body:
            if len(ln) - len(ln.lstrip()) != indent:
                continue  # a description line
            head = re.split(r"\s+:(?:\s|$)|:$", ln.strip(), maxsplit=1)[0]
            names.update(n.strip().lstrip("*") for n in head.split(",") if n.strip())
    return names


def has_summary(doc: str | None) -> bool:
    """A docstring whose first line says something."""
    return bool(doc and doc.strip() and inspect.cleandoc(doc).splitlines()[0].strip())


def has_returns(doc: str) -> bool:
    """A non-empty ``Returns`` or ``Yields`` section."""
    secs = sections(doc)
    return any(any(ln.strip() for ln in secs.get(t, [])) for t in ("Returns", "Yields"))


# ----------------------------------------------------------------------------------------------- callables
def own_body_returns_value(func) -> bool:
    """True when the function's own body (not nested functions) has ``return <value>`` or ``yield``."""
    try:
        src = textwrap.dedent(inspect.getsource(func))
    except (OSError, TypeError):
        return False
    tree = ast.parse(src)
    fn = next(n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)))
    stack = list(ast.iter_child_nodes(fn))
    while stack:
        node = stack.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            continue
        if isinstance(node, (ast.Yield, ast.YieldFrom)):
            return True
        if isinstance(node, ast.Return) and node.value is not None:
            if not (isinstance(node.value, ast.Constant) and node.value.value is None):
                return True
        stack.extend(ast.iter_child_nodes(node))
    return False


def returns_value(func) -> bool:
    """Whether a function returns something: its return annotation, else its source."""
    try:
        ann = inspect.signature(func).return_annotation
    except (TypeError, ValueError):
        return False
    if ann is not inspect.Signature.empty:
        return ann not in (None, type(None), "None", "NoReturn", "typing.NoReturn")
    return own_body_returns_value(func)


def parameters(func, bound: bool) -> list[str]:
    """Parameter names of ``func`` as the docstring should list them (without ``self``/``cls``)."""
    try:
        params = list(inspect.signature(func).parameters.values())
    except (TypeError, ValueError):
        return []
    if bound and params:
        params = params[1:]
    return [p.name for p in params]


def check_function(func, label: str, bound: bool = False) -> list[str]:
    """Problems of one function or method (``bound``: its first parameter is ``self``/``cls``)."""
    doc = func.__doc__
    if not has_summary(doc):
        return [f"{label}: no docstring"]
    problems = []
    names = parameters(func, bound)
    if names:
        if not sections(doc).get("Parameters") and not sections(doc).get("Other Parameters"):
            problems.append(f"{label}: no Parameters section (parameters: {', '.join(names)})")
        else:
            missing = [n for n in names if n not in documented_parameters(doc)]
            if missing:
                problems.append(f"{label}: Parameters section does not document {', '.join(missing)}")
    if returns_value(func) and not has_returns(doc):
        problems.append(f"{label}: returns a value but has no Returns (or Yields) section")
    return problems


def class_docstring(cls) -> str | None:
    """The class's own docstring (None for the ``Name(field, ...)`` text dataclasses make up)."""
    doc = cls.__dict__.get("__doc__")
    if doc and dataclasses.is_dataclass(cls) and doc.startswith(f"{cls.__name__}("):
        return None
    return doc


def defines_init(cls) -> bool:
    """True when the class body itself defines ``__init__`` (not dataclass-generated, not inherited)."""
    if "__init__" not in cls.__dict__:
        return False
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError, SyntaxError):
        return False
    body = next(n for n in ast.walk(tree) if isinstance(n, ast.ClassDef)).body
    return any(isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.name == "__init__" for n in body)


def check_class(cls, label: str) -> list[str]:
    """Problems of a class: its docstring, constructor parameters, public methods and properties."""
    doc = class_docstring(cls)
    if not has_summary(doc):
        return [f"{label}: no docstring"]
    if issubclass(cls, BaseException):
        return []
    problems = []
    if defines_init(cls):
        names = parameters(cls.__init__, bound=True)
        documented = documented_parameters(doc or "") | documented_parameters(cls.__init__.__doc__ or "")
        missing = [n for n in names if n not in documented]
        if missing:
            problems.append(f"{label}: the class or __init__ docstring does not document {', '.join(missing)}")
    for name, attr in vars(cls).items():
        if name.startswith("_"):
            continue
        where = f"{label}.{name}"
        if isinstance(attr, property):
            if not has_summary(attr.fget.__doc__ if attr.fget else None):
                problems.append(f"{where}: property has no docstring")
        elif hasattr(attr, "func") and type(attr).__name__ == "cached_property":
            if not has_summary(attr.func.__doc__):
                problems.append(f"{where}: property has no docstring")
        elif isinstance(attr, staticmethod):
            problems += check_function(attr.__func__, where, bound=False)
        elif isinstance(attr, classmethod):
            problems += check_function(attr.__func__, where, bound=True)
        elif inspect.isfunction(attr):
            problems += check_function(attr, where, bound=True)
    return problems


def public_objects(mod: types.ModuleType) -> list[tuple[str, object]]:
    """``(name, object)`` of the module's public callables (``__all__``, else what it defines)."""
    names = getattr(mod, "__all__", None)
    if names is None:
        names = [
            n
            for n, v in vars(mod).items()
            if not n.startswith("_") and getattr(v, "__module__", None) == mod.__name__ and callable(v)
        ]
    out = []
    for name in names:
        if module_path(f"{mod.__name__}.{name}") is not None:
            continue  # a submodule: checked as a module of its own
        obj = getattr(mod, name)
        if isinstance(obj, types.ModuleType) or not callable(obj):
            continue
        if not str(getattr(obj, "__module__", "")).startswith("arxid"):
            continue
        out.append((name, obj))
    return out


def module_problems(mod: types.ModuleType) -> list[str]:
    """Every docstring problem of a module's public callables."""
    problems = []
    for _, obj in public_objects(mod):
        label = f"{obj.__module__}.{getattr(obj, '__qualname__', getattr(obj, '__name__', '?'))}"
        if inspect.isclass(obj):
            problems += check_class(obj, label)
        elif inspect.isfunction(obj):
            problems += check_function(obj, label)
        elif not has_summary(getattr(obj, "__doc__", None)):
            problems.append(f"{label}: no docstring")
    return problems


@pytest.mark.parametrize("name", modules())
def test_public_docstrings(name):
    if module_path(name) is None:
        pytest.skip(f"module {name} does not exist (yet)")
    mod = importlib.import_module(name)
    problems = module_problems(mod)
    assert not problems, f"{len(problems)} docstring problem(s) in {name}:\n  " + "\n  ".join(problems)


# ----------------------------------------------------------------------------------------------- self-checks
def _good(a, b, *args, c=1, **kwargs):
    """Summary.

    Parameters
    ----------
    a, b : int
        Two numbers.
    *args
        More.
    c : int, optional
    **kwargs
        Options.

    Returns
    -------
    int
    """
    return a + b


def _missing(a, b):
    """Summary.

    Parameters
    ----------
    a : int
        Not b.
    """
    if a:
        return None
    return b


def _nothing(a: int) -> None:
    """Summary.

    Parameters
    ----------
    a : int
    """
    return None


def _gen(n):
    """Summary.

    Parameters
    ----------
    n : int
    """
    yield from range(n)


def test_checker_accepts_complete_docstring():
    assert check_function(_good, "_good") == []
    assert documented_parameters(_good.__doc__ or "") == {"a", "b", "args", "c", "kwargs"}


def test_checker_names_what_is_missing():
    assert check_function(_missing, "m._missing") == [
        "m._missing: Parameters section does not document b",
        "m._missing: returns a value but has no Returns (or Yields) section",
    ]
    assert check_function(_nothing, "_nothing") == []
    assert check_function(_gen, "g") == ["g: returns a value but has no Returns (or Yields) section"]


def test_checker_on_classes():
    @dataclasses.dataclass
    class Point:
        x: float

        @property
        def norm(self) -> float:
            return abs(self.x)

        def scaled(self, k):
            """Scaled copy.

            Parameters
            ----------
            k : float

            Returns
            -------
            Point
            """
            return Point(self.x * k)

    assert check_class(Point, "Point") == ["Point: no docstring"]
    Point.__doc__ = "A point."
    assert check_class(Point, "Point") == ["Point.norm: property has no docstring"]

    class Plain:
        """Summary."""

        def __init__(self, size):
            self.size = size

    assert check_class(Plain, "Plain") == ["Plain: the class or __init__ docstring does not document size"]
