"""``@record`` behaves as ``@dataclass(frozen=True)``: the same class body under each decorator gives the
same signature, repr, equality, hash, immutability, defaults and dataclass functions."""

from __future__ import annotations

import dataclasses
import inspect
import pickle
from dataclasses import dataclass, field

import pytest

from arxid._base.records import record


def pair(make):
    """The class ``make(decorator)`` defines, under ``@dataclass(frozen=True, ...)`` and ``@record(...)``."""

    def frozen_dataclass(**options):
        return dataclass(frozen=True, **options)

    return make(frozen_dataclass), make(record)


def plain(decorate):
    @decorate()
    class Point:
        """A point."""

        x: float
        y: float = 0.0
        tags: list = field(default_factory=list)
        note: str = field(default="", repr=False, compare=False)
        cached: int = field(default=3, init=False)

    return Point


def keywords(decorate):
    @decorate(eq=False, kw_only=True)
    class Base:
        """A base of keyword-only fields."""

        a: int
        b: tuple = ()

    @decorate(eq=False)
    class Child(Base):
        """Its own fields positional, the base's by keyword."""

        c: str = "c"

    return Child


def undocumented(decorate):
    @decorate()
    class Bare:
        n: int
        items: list = field(default_factory=list)

    return Bare


@pytest.mark.parametrize("make", [plain, keywords, undocumented])
def test_the_signature_fields_and_match_args_are_the_dataclass_ones(make):
    expected, got = pair(make)
    assert str(inspect.signature(got)) == str(inspect.signature(expected))
    assert [(f.name, f.init, f.repr, f.compare, f.kw_only) for f in dataclasses.fields(got)] == [
        (f.name, f.init, f.repr, f.compare, f.kw_only) for f in dataclasses.fields(expected)
    ]
    assert got.__match_args__ == expected.__match_args__
    assert got.__doc__ == expected.__doc__
    assert got.__init__.__annotations__ == expected.__init__.__annotations__
    assert got.__init__.__qualname__ == expected.__init__.__qualname__


def test_the_repr_equality_and_hash_are_the_dataclass_ones():
    expected, got = pair(plain)
    e, g = expected(1.5, tags=[1], note="n"), got(1.5, tags=[1], note="n")
    assert repr(g) == repr(e) and repr(g).endswith(".Point(x=1.5, y=0.0, tags=[1], cached=3)")
    assert (g.x, g.y, g.tags, g.note, g.cached) == (e.x, e.y, e.tags, e.note, e.cached)
    with pytest.raises(TypeError, match="unhashable"):
        hash(g)  # a list field, as the dataclass
    a, b = got(1.0, 2.0, (), "one"), got(1.0, 2.0, (), "other")
    assert a == b and hash(a) == hash(b) == hash(expected(1.0, 2.0, (), "x"))  # note: not compared
    assert a != got(1.0, 3.0, ()) and a != expected(1.0, 2.0, ()) and a != (1.0, 2.0)
    assert got(1.0).tags is not got(1.0).tags  # a new list each time


def test_eq_false_and_repr_false_leave_the_object_ones():
    expected, got = pair(keywords)
    g = got("x", a=1)
    assert g != got("x", a=1) and g == g and hash(g) == object.__hash__(g)
    assert repr(g) == repr(expected("x", a=1)).replace(expected.__qualname__, got.__qualname__)

    @record(repr=False)
    class Quiet:
        """No repr of its own."""

        n: int

    assert repr(Quiet(1)).startswith("<") and Quiet(1) == Quiet(1)


def test_a_record_is_frozen_as_a_dataclass():
    expected, got = pair(plain)
    for cls in (expected, got):
        p = cls(1.0)
        with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'x'"):
            p.x = 2.0
        with pytest.raises(dataclasses.FrozenInstanceError, match="cannot assign to field 'other'"):
            p.other = 2.0
        with pytest.raises(dataclasses.FrozenInstanceError, match="cannot delete field 'y'"):
            del p.y

        class Sub(cls):  # a plain subclass may add attributes, not change fields
            pass

        s = Sub(1.0)
        s.extra = 1
        with pytest.raises(dataclasses.FrozenInstanceError):
            s.x = 3.0


def test_replace_asdict_and_pickle_work_on_a_record():
    _, got = pair(plain)
    p = got(1.0, tags=[2])
    q = dataclasses.replace(p, y=5.0)
    assert (q.x, q.y, q.tags) == (1.0, 5.0, [2]) and dataclasses.is_dataclass(q)
    assert dataclasses.asdict(p) == {"x": 1.0, "y": 0.0, "tags": [2], "note": "", "cached": 3}
    assert dataclasses.astuple(p) == (1.0, 0.0, [2], "", 3)


def test_post_init_runs_and_a_record_pickles():
    seen = []

    @record
    class Checked:
        """Checks its value."""

        n: int

        def __post_init__(self):
            seen.append(self.n)
            if self.n < 0:
                raise ValueError("negative")

    assert Checked(2).n == 2 and seen == [2]
    with pytest.raises(ValueError, match="negative"):
        Checked(-1)
    globals()["Checked"] = Checked  # pickle finds the class by its module and name
    Checked.__qualname__ = "Checked"
    try:
        assert pickle.loads(pickle.dumps(Checked(4))) == Checked(4)
    finally:
        del globals()["Checked"]


def test_the_errors_are_the_dataclass_ones():
    expected, got = pair(plain)
    for cls in (expected, got):
        with pytest.raises(TypeError, match=r"missing 1 required positional argument: 'x'"):
            cls()
    for decorate in (dataclass(frozen=True), record):
        with pytest.raises(TypeError, match="non-default argument 'b' follows default argument"):

            @decorate
            class Wrong:
                a: int = 0
                b: int

    with pytest.raises(TypeError, match="Cannot overwrite attribute __setattr__"):

        @record
        class Mutable:
            a: int

            def __setattr__(self, name, value):
                pass
