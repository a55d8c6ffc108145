"""Models and their estimation: ARX by Householder QR (:func:`arx`, :class:`ArxModel`), polynomial
models by instrumental variables (:func:`iv`, :class:`IvModel`, open and closed loop), polynomial
models by prediction-error minimisation (:func:`oe`, :func:`armax`, :func:`bj`, :func:`polyest`,
:class:`PolynomialModel`), the physical-effect grammar (``effects``), regressor layouts, fits of many
structures from one factor of their envelope (``envelope``), conversion
to python-control and scipy, continuous-time conversion, continuous-time models from sampled data
(:func:`tfest` by SRIVC, :func:`procest` process models), state-space models of several inputs and
outputs by subspace identification (:func:`ssest`, :class:`StateSpaceModel`), and model files."""

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
