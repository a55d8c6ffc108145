"""The static map of an input against the shape the model feeds it through: the steady-state output
with the input held at each knot (with its band), and the shape scaled to it."""

from __future__ import annotations

from typing import Any

import numpy as np

from .data import new_figure

__all__ = ["plot_static_map"]


def plot_static_map(shape: Any, static: Any, output: str = "output") -> Any:
    """A figure of ``static`` (a :class:`~arxid.diagnosis.static_map.StaticMap`) with ``shape``.

    Parameters
    ----------
    shape : InputShape
        The shape the model feeds the input through.
    static : StaticMap
    output : str
        The output's label for the axis.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, axes = new_figure(height=2.8)
    ax = axes[0, 0]
    x = np.linspace(static.knots[0], static.knots[-1], 200)
    ax.errorbar(static.knots, static.steady, yerr=static.band, fmt="o", color="black", capsize=3,
                label="steady state, input held (±2 s.e.)")  # fmt: skip
    ax.plot(x, static.curve(shape, x), color="tab:blue", label=f"through {shape.text}")
    ax.plot(x, static.curve(None, x), color="grey", linestyle="--", label="linear input")
    ax.set_xlabel(static.input)
    ax.set_ylabel(f"{output} (steady state)")
    ax.legend(loc="best", fontsize="small")
    return fig
