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

# Names defined in modules that are imported on first use (they pull in heavier dependencies).
_LAZY = {
    "sweep": "sweep",
    "SweepResult": "sweep",
    "compare": "diagnostics",
    "residuals": "diagnostics",
    "where_it_fails": "diagnostics",
    "diagnose": "diagnose",
    "Diagnosis": "diagnose",
    "Ladder": "diagnose",
    "quadrotor": None,
    "datasets": None,
    "effects": None,
}
__all__ += [k for k in _LAZY if k not in __all__]


def __getattr__(name: str):
    if name in _LAZY:
        import importlib

        module = importlib.import_module(f".{_LAZY[name] or name}", __name__)
        value = module if _LAZY[name] is None else getattr(module, name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'arxid' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__))
