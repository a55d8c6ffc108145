"""Checking a model against measurements.

* :mod:`~arxid.checks.comparison` -- free-run comparison (:func:`compare`) and the prediction error
  the other checks start from (:func:`prediction_error`, :func:`prediction`, :func:`error_rms`)
* :mod:`~arxid.checks.residual_analysis` -- residual tests: whiteness and independence
  (:func:`residuals`); :mod:`~arxid.checks.correlation` -- its lagged correlations and
  prewhitening filters (a signal's filter fitted once per record)
* :mod:`~arxid.checks.failures` -- where the model fails, in time and by operating point
  (:func:`where_it_fails`)
* :mod:`~arxid.checks.frequency` -- the frequency check (:func:`frequency_check`)
* :mod:`~arxid.checks.bands` -- confidence bands of the step, free-run and frequency responses
* :mod:`~arxid.checks.feedback` -- is there feedback from the output to the input (:func:`feedback`)
* :mod:`~arxid.checks.state_space` -- a state-space model in these checks: its prediction of each
  output, and the results of a model of several outputs by output name (:class:`PerOutput`)
"""

from .comparison import Comparison, compare, error_rms, prediction, prediction_error
from .failures import FailureAnalysis, SignalBins, WorstSegment, where_it_fails
from .feedback import FeedbackTest, feedback
from .frequency import FrequencyCheck, frequency_check
from .residual_analysis import ResidualAnalysis, residuals
from .state_space import PerOutput

__all__ = [
    "compare",
    "Comparison",
    "prediction",
    "prediction_error",
    "error_rms",
    "residuals",
    "ResidualAnalysis",
    "where_it_fails",
    "FailureAnalysis",
    "WorstSegment",
    "SignalBins",
    "frequency_check",
    "FrequencyCheck",
    "feedback",
    "FeedbackTest",
    "PerOutput",
]
