"""Frozen records made cheaply on import: ``@record`` is ``@dataclass(frozen=True)`` with the same
fields, constructor, repr, equality, hash and immutability.

``@dataclass`` writes the source of every method it adds (``__init__``, ``__repr__``, ``__eq__``,
``__hash__``, ``__setattr__``, ``__delattr__``) and compiles each: about 1 ms a class, half the import
of the modules a diagnosis runs (56 classes). A record compiles its ``__init__`` alone (its signature
and its speed are the user's); the other methods are functions over the class's field names, made
without compiling anything. The class stays a dataclass for :func:`dataclasses.fields`,
:func:`~dataclasses.replace` and :func:`~dataclasses.asdict`; its ``__dataclass_params__`` tells what
:func:`dataclasses.dataclass` itself added (no methods), so a record derives from records, not from a
frozen ``@dataclass``.
"""

from __future__ import annotations

import dataclasses
import sys
from collections.abc import Callable, Sequence
from operator import attrgetter
from reprlib import recursive_repr
from typing import TYPE_CHECKING, Any, TypeVar, overload

if TYPE_CHECKING:  # type checkers read a record as the frozen dataclass it is
    from typing_extensions import dataclass_transform
else:

    def dataclass_transform(**kwargs):
        return lambda decorator: decorator


__all__ = ["record"]

T = TypeVar("T", bound=type)


class _Factory:
    """The default of a parameter whose field has a default factory (``<factory>``, as dataclasses)."""

    def __repr__(self) -> str:
        return "<factory>"


_FACTORY = _Factory()


@overload
def record(cls: T, /) -> T: ...
@overload
def record(*, eq: bool = True, repr: bool = True, kw_only: bool = False) -> Callable[[T], T]: ...


@dataclass_transform(frozen_default=True, field_specifiers=(dataclasses.field, dataclasses.Field))
def record(cls: Any = None, /, *, eq: bool = True, repr: bool = True, kw_only: bool = False) -> Any:
    """``@dataclass(frozen=True, eq=..., repr=..., kw_only=...)``, made without compiling the methods
    other than ``__init__``.

    Parameters
    ----------
    cls : type, optional
        The class (``@record``), or None for ``@record(eq=False)``.
    eq : bool
        Define ``__eq__`` (fields compared in order, as a tuple) and ``__hash__`` over the compared
        fields, as dataclasses.
    repr : bool
        Define ``__repr__``: ``Name(field=value, ...)`` over the fields with ``repr=True``.
    kw_only : bool
        Every field is a keyword-only parameter of ``__init__``.

    Returns
    -------
    type or callable
        The class, or the decorator.
    """

    def make(c: Any) -> Any:
        return _make(c, eq, repr, kw_only)

    return make if cls is None else make(cls)


def _make(cls: Any, eq: bool, repr_: bool, kw_only: bool) -> Any:
    body = dict(vars(cls))
    explicit_hash = "__hash__" in body and not (body["__hash__"] is None and "__eq__" in body)
    if not body.get("__doc__"):  # dataclasses would read the signature of object's __init__ (tokenize: 10 ms)
        cls.__doc__ = cls.__name__
    cls = dataclasses.dataclass(cls, init=False, repr=False, eq=False, kw_only=kw_only)  # fields only
    fields = dataclasses.fields(cls)
    _add(cls, "__init__", _init(cls, fields))
    if repr_:
        _add(cls, "__repr__", recursive_repr()(_repr([f.name for f in fields if f.repr])))
    if eq:
        _add(cls, "__eq__", _eq(_values([f.name for f in fields if f.compare])))
        if not explicit_hash:
            hashed = [f.name for f in fields if (f.compare if f.hash is None else f.hash)]
            _set(cls, "__hash__", _hash(_values(hashed)))
    names = tuple(f.name for f in fields)
    for name, method in (("__setattr__", _frozen_setattr(cls, names)), ("__delattr__", _frozen_delattr(cls, names))):
        if name in body:
            raise TypeError(f"Cannot overwrite attribute {name} in class {cls.__name__}")
        _set(cls, name, method)
    if not body.get("__doc__"):  # as dataclasses: the signature (made here after __init__)
        import inspect

        cls.__doc__ = cls.__name__ + str(inspect.signature(cls)).replace(" -> None", "")
    return cls


def _set(cls: type, name: str, fn: Callable) -> None:
    fn.__name__ = name
    fn.__qualname__ = f"{cls.__qualname__}.{name}"
    fn.__module__ = cls.__module__
    setattr(cls, name, fn)


def _add(cls: type, name: str, fn: Callable) -> None:
    """As dataclasses: a method the class body defines stays."""
    if name not in vars(cls):
        _set(cls, name, fn)


def _values(names: Sequence[str]) -> Callable[[Any], tuple]:
    """The tuple of the fields ``names`` of an object."""
    if len(names) > 1:
        return attrgetter(*names)
    if names:
        one = attrgetter(names[0])
        return lambda obj: (one(obj),)
    return lambda obj: ()


def _repr(names: Sequence[str]) -> Callable:
    def __repr__(self):
        return self.__class__.__qualname__ + "(" + ", ".join(f"{n}={getattr(self, n)!r}" for n in names) + ")"

    return __repr__


def _eq(values: Callable[[Any], tuple]) -> Callable:
    def __eq__(self, other):
        if other.__class__ is self.__class__:
            return values(self) == values(other)
        return NotImplemented

    return __eq__


def _hash(values: Callable[[Any], tuple]) -> Callable:
    def __hash__(self):
        return hash(values(self))

    return __hash__


def _frozen_setattr(cls: type, names: tuple[str, ...]) -> Callable:
    def __setattr__(self, name, value):
        if type(self) is cls or name in names:
            raise dataclasses.FrozenInstanceError(f"cannot assign to field {name!r}")
        super(cls, self).__setattr__(name, value)

    return __setattr__


def _frozen_delattr(cls: type, names: tuple[str, ...]) -> Callable:
    def __delattr__(self, name):
        if type(self) is cls or name in names:
            raise dataclasses.FrozenInstanceError(f"cannot delete field {name!r}")
        super(cls, self).__delattr__(name)

    return __delattr__


def _init(cls: type, fields: Sequence[dataclasses.Field]) -> Callable:
    """The ``__init__`` dataclasses writes for a frozen class. Its defaults and annotations are set on
    the compiled function rather than written in its source, which halves the compile time."""
    missing = dataclasses.MISSING
    given = sorted((f for f in fields if f.init), key=lambda f: bool(f.kw_only))  # keyword-only last
    seen_default = False
    for f in given:
        if f.kw_only:
            break
        if f.default is not missing or f.default_factory is not missing:
            seen_default = True
        elif seen_default:
            raise TypeError(f"non-default argument {f.name!r} follows default argument")
    self_name = "__dataclass_self__" if "self" in {f.name for f in fields} else "self"
    names: dict[str, Any] = {"__dataclass_set__": object.__setattr__, "__dataclass_factory__": _FACTORY}
    lines = []
    for f in fields:
        value = f.name
        if f.default_factory is not missing:
            names[f"__dataclass_dflt_{f.name}__"] = f.default_factory
            value = f"__dataclass_dflt_{f.name}__()"
            if f.init:
                value += f" if {f.name} is __dataclass_factory__ else {f.name}"
        elif not f.init:
            continue  # read from the class attribute, as dataclasses
        lines.append(f"  __dataclass_set__({self_name}, {f.name!r}, {value})")
    if hasattr(cls, "__post_init__"):
        lines.append(f"  {self_name}.__post_init__()")
    positional = [f.name for f in given if not f.kw_only]
    keywords = [f.name for f in given if f.kw_only]
    source = (
        f"def __create_fn__({', '.join(names)}):\n"
        f" def __init__({', '.join([self_name, *positional, *(['*'] if keywords else []), *keywords])}):\n"
        + ("\n".join(lines) or "  pass")
        + "\n return __init__"
    )
    module = sys.modules.get(cls.__module__)
    made: dict[str, Any] = {}
    exec(compile(source, "<string>", "exec", dont_inherit=True), vars(module) if module is not None else {}, made)
    init = made["__create_fn__"](**names)
    defaults = {f.name: _FACTORY if f.default_factory is not missing else f.default for f in given}
    defaults = {name: value for name, value in defaults.items() if value is not missing}
    init.__defaults__ = tuple(defaults[name] for name in positional if name in defaults) or None
    init.__kwdefaults__ = {name: defaults[name] for name in keywords if name in defaults} or None
    init.__annotations__ = {**{f.name: f.type for f in given}, "return": None}
    return init
