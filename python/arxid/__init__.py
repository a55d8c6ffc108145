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

# ruff: noqa: F401 - the imports for type checkers are the public names (__all__ is built from _PUBLIC)
from __future__ import annotations

# First, before numpy and the core: a Ctrl-C while the arxid command starts exits 130.
from ._base import launch as _launch  # noqa: F401

# isort: split
import importlib
from typing import TYPE_CHECKING, Any

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

if TYPE_CHECKING:  # the names of _PUBLIC, imported on first use (__getattr__ below)
    from .analysis.pipeline import Analysis, analyse
    from .analysis.state_space import StateSpaceAnalysis, analyse_state_space
    from .checks import FeedbackTest, FrequencyCheck, compare, feedback, frequency_check, residuals, where_it_fails
    from .data.iodata import IOData
    from .diagnosis.ladder import Ladder
    from .diagnosis.suspects import Diagnosis, diagnose
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

#: The module of each public name. A name is imported when first used, so that ``import arxid``
#: (the command line's ``--help``, a fit of a small record) loads only what it uses.
_PUBLIC = {
    **dict.fromkeys(["IOData"], "arxid.data.iodata"),
    **dict.fromkeys(["ArxModel", "arx"], "arxid.models.arx_model"),
    **dict.fromkeys(["sweep", "SweepResult", "DEFAULT_GRID"], "arxid.selection.search"),
    **dict.fromkeys(["PolynomialModel"], "arxid.models.polynomial"),
    **dict.fromkeys(["iv", "IvModel"], "arxid.models.iv"),
    **dict.fromkeys(["oe", "armax", "bj", "polyest", "delayest"], "arxid.models.pem"),
    **dict.fromkeys(["tfest"], "arxid.models.tfest"),
    **dict.fromkeys(["procest"], "arxid.models.process_models"),
    **dict.fromkeys(["ssest"], "arxid.models.subspace"),
    **dict.fromkeys(["StateSpaceModel"], "arxid.models.state_space"),
    **dict.fromkeys(
        ["frf", "FrequencyResponse", "step_by_deconvolution", "DeconvolvedStep", "tf_from_frequency"],
        "arxid.frequency_domain",
    ),
    **dict.fromkeys(["refine", "RefinedSweep"], "arxid.selection.refine"),
    **dict.fromkeys(
        ["compare", "residuals", "where_it_fails", "frequency_check", "FrequencyCheck", "feedback", "FeedbackTest"],
        "arxid.checks",
    ),
    **dict.fromkeys(["diagnose", "Diagnosis"], "arxid.diagnosis.suspects"),
    **dict.fromkeys(["Ladder"], "arxid.diagnosis.ladder"),
    **dict.fromkeys(["analyse", "Analysis"], "arxid.analysis.pipeline"),
    **dict.fromkeys(["analyse_state_space", "StateSpaceAnalysis"], "arxid.analysis.state_space"),
}

__all__ = [
    *_PUBLIC,
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

if TYPE_CHECKING:
    from ._base.version import __version__ as __version__

_moved.install()

# Every subpackage is an attribute (``arxid.inputs.prbs(...)`` after a bare ``import arxid``); those
# that ``import arxid`` does not need (inputs, plots, quadrotor...) load on first use (PEP 562).
_SUBPACKAGES = (
    "analysis",
    "checks",
    "data",
    "diagnosis",
    "fleet",
    "frequency_domain",
    "inputs",
    "models",
    "plots",
    "quadrotor",
    "selection",
)
_LAZY_MODULES = {name: f"arxid.{name}" for name in _SUBPACKAGES}
_LAZY_MODULES.update((path.rpartition(".")[2], module) for path, module in _moved.PUBLIC.items())


def __getattr__(name: str) -> Any:
    if name == "__version__":  # read from the installed metadata (importlib.metadata: 0.1 s) when asked
        value = importlib.import_module("arxid._base.version").__version__
    elif name in _PUBLIC:
        value = getattr(importlib.import_module(_PUBLIC[name]), name)
    elif name in _LAZY_MODULES or name in _SUBPACKAGES:
        value = importlib.import_module(_LAZY_MODULES.get(name, f"arxid.{name}"))
    else:
        raise AttributeError(f"module 'arxid' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__) | set(_LAZY_MODULES))
