"""Packages whose public names load on first use, as ``arxid``'s own (PEP 562): a module that
needs one name of a subpackage does not pay for the imports of the others (``arxid diagnose`` on a
small file fits ARX models, not the continuous-time estimators, and reads no list of logs)."""

from __future__ import annotations

import importlib
import sys
from types import ModuleType
from typing import Any

__all__ = ["LazyPackage", "lazy_package"]


class LazyPackage(ModuleType):
    """A package whose ``_PUBLIC`` (each public name and the module under the package that defines
    it, ``{"arx": "arx_model"}``) is imported when a name is first read, then kept in the package.

    A name spelt as its module (``iv`` in ``iv``, ``refine`` in ``refine``) stays the name when
    that module is imported by another path: the import system binds a submodule to its package,
    and the package binds the name instead, as an ``__init__`` importing it would have left it.
    """

    def __getattr__(self, name: str) -> Any:  # only for names not yet in the package
        modules = vars(self).get("_PUBLIC", {})
        if name not in modules:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(f"{self.__name__}.{modules[name]}"), name)
        setattr(self, name, value)
        return value

    def __setattr__(self, name: str, value: Any) -> None:
        if isinstance(value, ModuleType) and vars(self).get("_PUBLIC", {}).get(name) == name and hasattr(value, name):
            value = getattr(value, name)
        super().__setattr__(name, value)

    def __dir__(self) -> list[str]:
        return sorted(set(vars(self)) | set(vars(self).get("_PUBLIC", {})))


def lazy_package(name: str) -> None:
    """Make the package ``name`` (its ``__init__`` calls this with ``__name__``, after defining
    ``_PUBLIC``) a :class:`LazyPackage`.

    Parameters
    ----------
    name : str
        The package's ``__name__``.
    """
    sys.modules[name].__class__ = LazyPackage
