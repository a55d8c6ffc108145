"""arxid: classical system identification (ARX models and discrete transfer functions) that helps
you find the physical effect your model is missing.

A Rust core (faer) fits ARX models by Householder QR and sweeps every (na, nb, nk) structure from a
single factorization; this package prepares data, checks models, diagnoses them and exports them to
python-control and scipy.
"""

from __future__ import annotations

from .data import IOData
from .exceptions import ArxidError, DataError, IdentifiabilityError, NotFittedError, OrderError
from .model import ArxModel, arx

__all__ = [
    "IOData",
    "ArxModel",
    "arx",
    "ArxidError",
    "DataError",
    "OrderError",
    "IdentifiabilityError",
    "NotFittedError",
]

__version__ = "0.1.0"

# ``sweep`` and ``diagnose`` name both a module and its main function. Importing the modules here,
# before binding the functions, means a later ``import arxid.sweep`` finds them in ``sys.modules``
# and never rebinds the package attribute to the module: ``arxid.sweep(...)`` always works.
from . import diagnose as _diagnose_module  # noqa: E402
from . import diagnostics as _diagnostics_module  # noqa: E402
from . import sweep as _sweep_module  # noqa: E402
from .diagnose import Diagnosis, Ladder, diagnose  # noqa: E402
from .diagnostics import compare, residuals, where_it_fails  # noqa: E402
from .sweep import SweepResult, sweep  # noqa: E402

__all__ += ["sweep", "SweepResult", "compare", "residuals", "where_it_fails", "diagnose", "Diagnosis", "Ladder",
            "quadrotor", "datasets", "effects"]

# Subpackages with heavier or optional dependencies load on first use.
_LAZY_MODULES = ("quadrotor", "datasets", "effects", "report", "cli")


def __getattr__(name: str):
    if name in _LAZY_MODULES:
        import importlib

        module = importlib.import_module(f".{name}", __name__)
        globals()[name] = module
        return module
    raise AttributeError(f"module 'arxid' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
