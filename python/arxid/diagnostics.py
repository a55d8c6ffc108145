"""Deprecated alias of :mod:`arxid.validation` (renamed so it cannot be confused with the missing-effect
diagnosis in :mod:`arxid.missing`); it will be removed in the next release."""

import warnings

from .validation import *  # noqa: F403
from .validation import __all__  # noqa: F401

warnings.warn(
    "arxid.diagnostics is deprecated: import from arxid.validation (compare, residuals, where_it_fails)",
    DeprecationWarning,
    stacklevel=2,
)
