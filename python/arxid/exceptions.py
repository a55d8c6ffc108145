"""The arxid exception family.

Every error arxid raises on purpose is an :class:`ArxidError`, which subclasses :class:`ValueError`
so that ``except ValueError`` keeps working. Messages say what is wrong and how to fix it.
"""

from __future__ import annotations

__all__ = [
    "ArxidError",
    "DataError",
    "OrderError",
    "IdentifiabilityError",
    "NotFittedError",
    "MissingDependencyError",
    "ConversionError",
    "ConvergenceError",
    "ArxidWarning",
]


class ArxidError(ValueError):
    """Base class of every error arxid raises on purpose."""


class DataError(ArxidError):
    """The data cannot be used as given: wrong shape or dtype, NaN/inf where it matters, too short,
    unknown columns, a corrupt model file."""


class OrderError(ArxidError):
    """Model orders or delays are invalid (negative, wrong count for the inputs, unknown effect)."""


class IdentifiabilityError(ArxidError):
    """The data cannot determine the parameters: collinear regressors or an input that does not
    excite the system.

    Attributes
    ----------
    regressors : tuple of str
        Names of the regressors involved (the dependent one last), when known.
    """

    def __init__(self, message: str, regressors: tuple[str, ...] = ()):
        super().__init__(message)
        self.regressors = tuple(regressors)


class ConvergenceError(ArxidError):
    """Prediction-error iterations (``oe``, ``armax``, ``bj``) could not proceed; the message says why."""


class NotFittedError(ArxidError, AttributeError):
    """A fitted attribute was used before the model was fitted."""


class ConversionError(ArxidError):
    """A model has no exact conversion of the requested kind (continuous time with a zero-order hold,
    pole-zero matching); the message says why and which method to use instead."""


class ArxidWarning(UserWarning):
    """Something the user should know that does not stop the work (a structure skipped by the step
    sanity check, an optional dependency missing). Filter it with ``warnings.simplefilter``."""


class MissingDependencyError(ArxidError, ImportError):
    """An optional dependency is not installed; the message names the extra that installs it
    (``pip install 'arxid[plot]'``). Also an :class:`ImportError`, so ``except ImportError`` works."""
