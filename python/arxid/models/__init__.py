"""Models and their estimation: ARX by Householder QR (:func:`arx`, :class:`ArxModel`), polynomial
models by instrumental variables (:func:`iv`, :class:`IvModel`, open and closed loop), polynomial
models by prediction-error minimisation (:func:`oe`, :func:`armax`, :func:`bj`, :func:`polyest`,
:class:`PolynomialModel`), the physical-effect grammar (``effects``), regressor layouts, fits of many
structures from one factor of their envelope (``envelope``), conversion
to python-control and scipy, continuous-time conversion, continuous-time models from sampled data
(:func:`tfest` by SRIVC, :func:`procest` process models), state-space models of several inputs and
outputs by subspace identification (:func:`ssest`, :class:`StateSpaceModel`), and model files.

The names below load on first use (PEP 562), as ``arxid``'s own: a module that needs one model
(``arxid diagnose`` on a small file needs the ARX model) does not pay for the others' imports."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._base.lazy import lazy_package

if TYPE_CHECKING:  # the names of _PUBLIC, imported on first use (__getattr__ below)
    from .arx_model import ArxModel, FittedLayout, arx
    from .continuous import c2d, d2c
    from .continuous_tf import ContinuousTransferFunction, pade
    from .convert import to_control, to_scipy
    from .fitted import FittedModel
    from .iv import IvModel, iv
    from .pem import armax, bj, delayest, oe, polyest
    from .polynomial import PolynomialModel, as_polynomial
    from .process_models import procest
    from .spec import parse_model_spec
    from .state_space import StateSpaceModel
    from .subspace import ssest
    from .tfest import tfest

#: The module of each public name.
_PUBLIC = {
    **dict.fromkeys(["ArxModel", "arx", "FittedLayout"], "arx_model"),
    **dict.fromkeys(["c2d", "d2c"], "continuous"),
    **dict.fromkeys(["ContinuousTransferFunction", "pade"], "continuous_tf"),
    **dict.fromkeys(["to_control", "to_scipy"], "convert"),
    **dict.fromkeys(["FittedModel"], "fitted"),
    **dict.fromkeys(["IvModel", "iv"], "iv"),
    **dict.fromkeys(["oe", "armax", "bj", "polyest", "delayest"], "pem"),
    **dict.fromkeys(["PolynomialModel", "as_polynomial"], "polynomial"),
    **dict.fromkeys(["procest"], "process_models"),
    **dict.fromkeys(["parse_model_spec"], "spec"),
    **dict.fromkeys(["StateSpaceModel"], "state_space"),
    **dict.fromkeys(["ssest"], "subspace"),
    **dict.fromkeys(["tfest"], "tfest"),
}

__all__ = [
    "ArxModel",
    "arx",
    "FittedLayout",
    "FittedModel",
    "PolynomialModel",
    "iv",
    "IvModel",
    "as_polynomial",
    "oe",
    "armax",
    "bj",
    "polyest",
    "delayest",
    "to_control",
    "to_scipy",
    "d2c",
    "c2d",
    "ContinuousTransferFunction",
    "pade",
    "tfest",
    "procest",
    "parse_model_spec",
    "ssest",
    "StateSpaceModel",
]


lazy_package(__name__)
