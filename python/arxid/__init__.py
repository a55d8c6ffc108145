"""arxid: classical system identification (ARX models and discrete transfer functions) that helps
you find the physical effect your model is missing.

A Rust core (faer) fits ARX models by Householder QR and sweeps every (na, nb, nk) structure from a
single factorization; this package prepares data, checks models, diagnoses them and exports them to
python-control and scipy.

The map (one subpackage per layer, top to bottom; docs/architecture.md has the rules):

* :mod:`arxid.analysis` — :func:`analyse`, the one pipeline behind the CLI, the report and the demo;
* :mod:`arxid.diagnosis` — :func:`diagnose`, :class:`Diagnosis`, :class:`Ladder`;
* :mod:`arxid.selection` — :func:`sweep`, :class:`SweepResult`, :data:`DEFAULT_GRID`, :func:`refine`;
* :mod:`arxid.checks` — :func:`compare`, :func:`residuals`, :func:`where_it_fails`,
  :func:`frequency_check`, confidence bands; :mod:`arxid.fleet` — many logs, Dask;
* :mod:`arxid.frequency_domain` — :func:`frf`, :class:`FrequencyResponse`,
  :func:`step_by_deconvolution`, :func:`tf_from_frequency`;
* :mod:`arxid.models` — :func:`arx`, :class:`ArxModel`, :class:`PolynomialModel`, :func:`oe`,
  :func:`armax`, :func:`bj`, :func:`polyest`, :func:`delayest`, continuous-time models
  (:func:`tfest`, :func:`procest`), effects, conversion, model files;
* :mod:`arxid.quadrotor` — mixer, motor, thrust, set membership, the simulators (``arxid.datasets``);
  :mod:`arxid.plots`;
* :mod:`arxid.data` — :class:`IOData`, CSV, logs; ``arxid._base`` — the compiled core and the metrics.
"""

from __future__ import annotations

import importlib
from typing import Any

from . import fleet  # noqa: F401 - gives the models their fits of many logs (client=, per_experiment=True)
from .analysis.pipeline import Analysis, analyse
from .checks import FeedbackTest, FrequencyCheck, compare, feedback, frequency_check, residuals, where_it_fails
from .data.iodata import IOData
from .diagnosis.ladder import Ladder
from .diagnosis.suspects import Diagnosis, diagnose
from .exceptions import (
    ArxidError,
    ArxidWarning,
    ConvergenceError,
    ConversionError,
    DataError,
    IdentifiabilityError,
    MissingDependencyError,
    NotFittedError,
    OrderError,
)
from .frequency_domain import DeconvolvedStep, FrequencyResponse, frf, step_by_deconvolution, tf_from_frequency
from .models.arx_model import ArxModel, arx
from .models.iv import IvModel, iv
from .models.pem import armax, bj, delayest, oe, polyest
from .models.polynomial import PolynomialModel
from .models.process_models import procest
from .models.state_space import StateSpaceModel
from .models.subspace import ssest
from .models.tfest import tfest
from .selection.refine import RefinedSweep, refine
from .selection.search import DEFAULT_GRID, SweepResult, sweep

__all__ = [
    "IOData",
    "ArxModel",
    "arx",
    "sweep",
    "SweepResult",
    "DEFAULT_GRID",
    "PolynomialModel",
    "iv",
    "IvModel",
    "oe",
    "armax",
    "bj",
    "polyest",
    "delayest",
    "tfest",
    "procest",
    "ssest",
    "StateSpaceModel",
    "frf",
    "FrequencyResponse",
    "step_by_deconvolution",
    "DeconvolvedStep",
    "tf_from_frequency",
    "refine",
    "RefinedSweep",
    "compare",
    "residuals",
    "where_it_fails",
    "frequency_check",
    "FrequencyCheck",
    "feedback",
    "FeedbackTest",
    "diagnose",
    "Diagnosis",
    "Ladder",
    "analyse",
    "Analysis",
    "ArxidError",
    "DataError",
    "OrderError",
    "IdentifiabilityError",
    "NotFittedError",
    "MissingDependencyError",
    "ConvergenceError",
    "ConversionError",
    "ArxidWarning",
    "quadrotor",
    "datasets",
    "effects",
]

from ._base import moved as _moved  # noqa: E402
from ._base.version import __version__ as __version__  # noqa: E402

_moved.install()

# Subpackages with heavier or optional dependencies load on first use.
_LAZY_MODULES = {"quadrotor": "arxid.quadrotor", "plots": "arxid.plots"}
_LAZY_MODULES.update((path.rpartition(".")[2], module) for path, module in _moved.PUBLIC.items())


def __getattr__(name: str) -> Any:
    if name in _LAZY_MODULES:
        module = importlib.import_module(_LAZY_MODULES[name])
        globals()[name] = module
        return module
    raise AttributeError(f"module 'arxid' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
