"""Checking a model against measurements: free-run comparison (:func:`compare`), residual tests
(:func:`residuals`), where the model fails (:func:`where_it_fails`), the frequency check
(:func:`frequency_check`) and confidence bands."""

from .frequency import FrequencyCheck, frequency_check
from .residual_analysis import compare, residuals, where_it_fails

__all__ = ["compare", "residuals", "where_it_fails", "frequency_check", "FrequencyCheck"]
