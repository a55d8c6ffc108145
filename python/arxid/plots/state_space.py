"""Figures of a state-space model: the singular values and the order criterion that chose its
order (:func:`plot_singular_values`), and the coupling of its inputs and outputs as a heat map
(:func:`plot_coupling`)."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._base.optional import require

__all__ = ["plot_singular_values", "plot_coupling"]

#: Orders past the chosen one drawn at most (the criterion grows steadily beyond the minimum).
SHOWN_PAST_ORDER = 12


def plot_singular_values(model: Any) -> Any:
    """The weighted projection's singular values, and the singular value criterion over the order
    with the model's order marked.

    Parameters
    ----------
    model : StateSpaceModel

    Returns
    -------
    matplotlib.figure.Figure
        Left: singular values (log scale), those kept as states filled. Right: SVC(n), the chosen
        order starred (and the criterion's minimum ringed when the caller fixed another order).
    """
    Figure = require("matplotlib.figure", "plotting").Figure
    fig = Figure(figsize=(9.0, 3.4), layout="constrained")
    left, right = fig.subplots(1, 2)
    n = model.order
    values = np.asarray(model.singular_values, dtype=float)[: n + SHOWN_PAST_ORDER]
    index = np.arange(1, len(values) + 1)
    kept = index <= n
    left.semilogy(index[kept], values[kept], "o", color="C0", label=f"kept as states ({n})")
    left.semilogy(index[~kept], values[~kept], "o", mfc="none", color="0.5", label="discarded")
    left.set_xlabel("index")
    left.set_ylabel("singular value")
    left.set_title(f"{model.method.upper()} weighted projection")
    left.legend(fontsize=8)
    criterion = np.asarray(model.order_criterion, dtype=float)[: n + SHOWN_PAST_ORDER + 1]
    orders = np.arange(len(criterion))
    right.plot(orders, criterion, ".-", color="C0")
    if n < len(criterion):
        how = "fixed" if model.order_fixed else "chosen"
        right.plot(n, criterion[n], "*", color="red", markersize=14, ls="none", label=f"{how}: {n} states")
    best = int(np.nanargmin(criterion)) if np.isfinite(criterion).any() else None
    if model.order_fixed and best is not None and best != n:
        right.plot(best, criterion[best], "o", mfc="none", color="red", markersize=12, label=f"minimum: {best}")
    from matplotlib.ticker import MaxNLocator

    right.xaxis.set_major_locator(MaxNLocator(integer=True))
    left.xaxis.set_major_locator(MaxNLocator(integer=True))
    right.set_xlabel("order (states)")
    right.set_ylabel("SVC(n)")
    right.set_title("singular value criterion")
    right.legend(fontsize=8)
    return fig


def plot_coupling(coupling: Any) -> Any:
    """Heat map of the share of each output's motion that each input's path carries.

    Parameters
    ----------
    coupling : Coupling
        From :func:`arxid.analysis.coupling.coupling`.

    Returns
    -------
    matplotlib.figure.Figure
        Rows: outputs; columns: inputs; each cell holds its value (grey: not available).
    """
    Figure = require("matplotlib.figure", "plotting").Figure
    import matplotlib

    values = np.asarray(coupling.share, dtype=float)
    scaled = np.isfinite(values).any()
    if not scaled:  # no data: the peak gains
        values = np.asarray(coupling.peak, dtype=float)
    ny, nu = values.shape
    fig = Figure(figsize=(1.2 * nu + 2.6, 0.7 * ny + 1.6), layout="constrained")
    ax = fig.subplots()
    cmap = matplotlib.colormaps["Blues"].with_extremes(bad="0.8")
    finite = values[np.isfinite(values)]
    top = float(finite.max()) if finite.size else 1.0
    image = ax.imshow(np.ma.masked_invalid(values), cmap=cmap, vmin=0.0, vmax=top or 1.0, aspect="auto")
    for i in range(ny):
        for j in range(nu):
            v = values[i, j]
            text = f"{v:.2g}" if np.isfinite(v) else "n/a"
            ax.text(j, i, text, ha="center", va="center", fontsize=9, color="white" if v > 0.6 * top else "black")
    ax.set_xticks(range(nu), coupling.input_names, rotation=30, ha="right")
    ax.set_yticks(range(ny), coupling.output_names)
    ax.set_xlabel("input")
    ax.set_ylabel("output")
    label = "RMS from this input alone / RMS of the output" if scaled else "peak gain"
    fig.colorbar(image, ax=ax, label=label)
    ax.set_title("coupling: input → output")
    return fig
