"""Figures of arxid's results, drawn from the stored result objects (nothing is recomputed here).

Every function returns a :class:`matplotlib.figure.Figure` built without pyplot; those that draw
one panel take ``ax=`` to draw into an existing axes instead.
"""

from __future__ import annotations

from .bode import plot_bode
from .data import data_overview, figure_to_data_uri, step_checks
from .diagnostics import (
    plot_comparison,
    plot_diagnosis,
    plot_error_by_signal,
    plot_failures,
    plot_ladder,
    plot_residuals,
)
from .state_space import plot_coupling, plot_singular_values
from .sweep import plot_sweep

__all__ = [
    "data_overview",
    "figure_to_data_uri",
    "step_checks",
    "plot_comparison",
    "plot_diagnosis",
    "plot_error_by_signal",
    "plot_failures",
    "plot_ladder",
    "plot_residuals",
    "plot_sweep",
    "plot_bode",
    "plot_singular_values",
    "plot_coupling",
]
