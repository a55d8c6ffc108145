"""Frequency-domain identification: the frequency response from data (:func:`frf`, Welch's H1 or
Blackman–Tukey, in open or closed loop), the step response of a rate loop by regularised
deconvolution (:func:`step_by_deconvolution`, as PIDtoolbox) and a continuous transfer function
fitted to a frequency response (:func:`tf_from_frequency`, MATLAB's ``tfest`` on an ``idfrd``).

Not named ``arxid.frequency``: that path still imports the frequency check
(:mod:`arxid.checks.frequency`) with a deprecation warning, for one more release."""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._base.lazy import lazy_package

if TYPE_CHECKING:  # the names of _PUBLIC, imported on first use (PEP 562)
    from ._frf import frf
    from ._model_response import model_response
    from ._response import FrequencyResponse
    from ._step import DeconvolvedStep, step_by_deconvolution
    from ._tf_fit import tf_from_frequency

_PUBLIC = {
    "frf": "_frf",
    "model_response": "_model_response",
    "FrequencyResponse": "_response",
    **dict.fromkeys(["step_by_deconvolution", "DeconvolvedStep"], "_step"),
    "tf_from_frequency": "_tf_fit",
}

__all__ = [
    "frf",
    "model_response",
    "FrequencyResponse",
    "step_by_deconvolution",
    "DeconvolvedStep",
    "tf_from_frequency",
]

lazy_package(__name__)
