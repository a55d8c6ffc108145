"""Optional dependencies: imported where they are used, never at ``import arxid``.

The base install is numpy, scipy and threadpoolctl. A feature that needs more either raises
:class:`~arxid.exceptions.MissingDependencyError` naming the extra that installs it
(:func:`require`), or quietly does without, warning once per process (:func:`optional`).
"""

from __future__ import annotations

import importlib
import warnings
from types import ModuleType

from ..exceptions import ArxidWarning, MissingDependencyError

__all__ = ["EXTRAS", "require", "optional"]

# The extra of pyproject.toml that installs each optional distribution (import name -> extra).
EXTRAS = {"matplotlib": "plot", "control": "control", "tqdm": "progress", "pandas": "pandas", "pyulog": "px4"}

_PACKAGES = {"control": "python-control"}  # names a user would search for, where they differ
_warned: set[str] = set()


def _hint(module: str, purpose: str) -> str:
    top = module.split(".")[0]
    return f"{purpose} needs {_PACKAGES.get(top, top)}, which is not installed: pip install 'arxid[{EXTRAS[top]}]'"


def require(module: str, purpose: str) -> ModuleType:
    """The module, or a typed error that says which extra installs it.

    Parameters
    ----------
    module : str
        Import name, e.g. ``"matplotlib.figure"``; its top-level package must be in :data:`EXTRAS`.
    purpose : str
        What needs it, for the message (``"plotting"``, ``"to_control"``).

    Returns
    -------
    module

    Raises
    ------
    MissingDependencyError
        When the package is not installed.
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MissingDependencyError(_hint(module, purpose)) from None


def optional(module: str, purpose: str) -> ModuleType | None:
    """The module, or None with one :class:`~arxid.exceptions.ArxidWarning` per process.

    Parameters
    ----------
    module : str
        Import name; its top-level package must be in :data:`EXTRAS`.
    purpose : str
        What is skipped without it, for the warning (``"the progress bar"``).

    Returns
    -------
    module or None
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        if module not in _warned:
            _warned.add(module)
            warnings.warn(_hint(module, purpose) + "; going on without it", ArxidWarning, stacklevel=3)
        return None
