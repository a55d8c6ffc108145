"""Module paths that moved into subpackages, importable for one more release.

``import arxid.orders`` (and the like) warns with a :class:`DeprecationWarning` naming the new path
and returns the module that now holds the code. The public modules of the ``arxid`` namespace
(``arxid.datasets``, ``arxid.report``, ...) import by their public path without a warning.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import sys
import warnings
from types import CodeType, ModuleType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from importlib.abc import Loader, MetaPathFinder

    class _Finder(MetaPathFinder, Loader): ...

else:  # the import system needs only the methods: importlib.abc imports importlib.resources (20 ms)
    _Finder = object

__all__ = ["MOVED", "PUBLIC", "install"]

#: Old module path -> the module that holds its code now.
MOVED = {
    "arxid.orders": "arxid.selection.search",
    "arxid.missing": "arxid.diagnosis.suspects",
    "arxid.validation": "arxid.checks",
    "arxid.model": "arxid.models.arx_model",
    "arxid.polynomial": "arxid.models.polynomial",
    "arxid.pem": "arxid.models.pem",
    "arxid.continuous": "arxid.models.continuous",
    "arxid.frequency": "arxid.checks.frequency",
    "arxid.uncertainty": "arxid.checks.bands",
    "arxid.ladder": "arxid.diagnosis.ladder",
    "arxid.sanity": "arxid.selection.sanity",
    "arxid.diagnosis.fleet_diagnose": "arxid.diagnosis.cluster_records",
    "arxid.diagnosis.fleet_scoring": "arxid.diagnosis.statistics",
    "arxid.diagnosis.fleet_refit": "arxid.diagnosis.pooled_refits",
}

#: Public modules of the ``arxid`` namespace (``arxid.datasets``, ...) that live in a subpackage:
#: importable by their public path without a warning.
PUBLIC = {
    "arxid.datasets": "arxid.quadrotor.datasets",
    "arxid.effects": "arxid.models.effects",
    "arxid.convert": "arxid.models.convert",
    "arxid.report": "arxid.analysis.report",
    "arxid.demo": "arxid.analysis.demo",
    "arxid.cli": "arxid.analysis.cli",
}


class _Moved(_Finder):
    """Finds the paths of :data:`MOVED` and :data:`PUBLIC` and loads them as the modules that hold the code."""

    def find_spec(
        self, fullname: str, path: object = None, target: object = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname not in MOVED and fullname not in PUBLIC:
            return None
        return importlib.machinery.ModuleSpec(fullname, self)

    def __init__(self) -> None:
        self._specs: dict[str, importlib.machinery.ModuleSpec | None] = {}

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        new = PUBLIC.get(spec.name) or MOVED[spec.name]
        if spec.name in MOVED:
            warnings.warn(
                f"{spec.name} moved to {new}; the old path will be removed in the next release: "
                f"import from {new}, or use the names of the arxid package itself",
                DeprecationWarning,
                stacklevel=2,
            )
        module = importlib.import_module(new)
        self._specs[spec.name] = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        """The module ran under its new name already; give it back its own spec, which the import
        system replaced with the old path's (its relative imports resolve from ``__spec__``)."""
        spec = module.__spec__
        if spec is not None and spec.name in self._specs:
            module.__spec__ = self._specs.pop(spec.name)

    def get_code(self, fullname: str) -> CodeType:
        """What ``python -m <old path>`` runs: the ``main`` of the module that holds the code now."""
        new = PUBLIC.get(fullname) or MOVED[fullname]
        return compile(f"import sys\nfrom {new} import main\nsys.exit(main())\n", f"<{fullname}>", "exec")


def install() -> None:
    """Put the finder of old paths at the end of :data:`sys.meta_path` (once)."""
    if not any(isinstance(f, _Moved) for f in sys.meta_path):
        sys.meta_path.append(_Moved())
