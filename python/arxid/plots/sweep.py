"""Heat map of a sweep's ranking error over (na, nk), one panel per nb."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._base.optional import require

__all__ = ["plot_sweep"]


#: Panels (nb values) drawn at most: a grown grid has up to 30, which would take matplotlib tens of
#: seconds to lay out; the panels nearest the chosen nb (else the best-ranked structure's) are drawn.
MAX_PANELS = 8


def plot_sweep(result: Any, nb_input: int = 0, chosen: int | None = None) -> Any:
    """Heat map of the validation error of every structure over (na, nk), one panel per nb (at
    most :data:`MAX_PANELS`, those nearest the chosen nb; the title says which).

    Parameters
    ----------
    result : SweepResult
    nb_input : int
        For several inputs: whose nb and nk span the panels and the columns; each cell shows the
        best structure over the other inputs' orders.
    chosen : int, optional
        Rank of the chosen structure, marked with a star.

    Returns
    -------
    matplotlib.figure.Figure
        Diverged or unfitted cells are grey; the chosen structure is marked.
    """
    Figure = require("matplotlib.figure", "plotting").Figure
    score = result.ranking_score().astype(float)
    score = np.where(result.diverged_val | result.diverged_est, np.nan, score)
    nas = np.unique(result.na)
    all_nbs = np.unique(result.nb[:, nb_input])
    centre = int(result.nb[0 if chosen is None else chosen, nb_input])
    nbs = np.sort(all_nbs[np.argsort(np.abs(all_nbs - centre), kind="stable")[:MAX_PANELS]])
    nks = np.unique(result.nk[:, nb_input])
    grids = {}
    for b in nbs:
        g = np.full((len(nas), len(nks)), np.nan)
        for i in np.flatnonzero(result.nb[:, nb_input] == b):
            r = np.searchsorted(nas, result.na[i])
            c = np.searchsorted(nks, result.nk[i, nb_input])
            if np.isfinite(score[i]) and not (score[i] >= g[r, c]):
                g[r, c] = score[i]
        grids[b] = g
    finite = np.concatenate([g[np.isfinite(g)] for g in grids.values()] + [np.zeros(0)])
    ncols = min(len(nbs), 4)
    nrows = int(np.ceil(len(nbs) / ncols))
    fig = Figure(figsize=(3.6 * ncols + 1.0, 3.0 * nrows + 0.6), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    from matplotlib.colors import LogNorm, Normalize
    from matplotlib.ticker import MaxNLocator

    positive = finite[finite > 0]
    norm = LogNorm(positive.min(), positive.max()) if positive.size and positive.max() > positive.min() else Normalize()
    image = None
    import matplotlib

    cmap = matplotlib.colormaps["viridis_r"].with_extremes(bad="0.75")
    for ax, b in zip(axes.flat, nbs):
        g = np.ma.masked_invalid(grids[b])
        image = ax.imshow(
            g,
            origin="lower",
            aspect="auto",
            cmap=cmap,
            norm=norm,
            extent=(nks[0] - 0.5, nks[-1] + 0.5, nas[0] - 0.5, nas[-1] + 0.5),
        )
        if chosen is not None and int(result.nb[chosen, nb_input]) == b:
            ax.plot(
                int(result.nk[chosen, nb_input]),
                int(result.na[chosen]),
                marker="*",
                color="red",
                markersize=12,
                ls="none",
                label=f"chosen: {result.structure_name(chosen)}",
            )
            from matplotlib.patches import Patch

            handles = ax.get_legend_handles_labels()[0] + [Patch(color="0.75", label="diverged or not fitted")]
            fig.legend(handles=handles, fontsize=8, loc="outside lower center", ncols=2)
        # Every order a tick while they fit; a grown grid (na up to 30) gets about 8 integer ticks,
        # which also keeps the layout's text measurements (the slow part of a large figure) few.
        ax.xaxis.set_major_locator(MaxNLocator(nbins=8, integer=True)) if len(nks) > 8 else ax.set_xticks(nks)
        ax.yaxis.set_major_locator(MaxNLocator(nbins=8, integer=True)) if len(nas) > 8 else ax.set_yticks(nas)
        ax.set_title(f"nb = {b}")
        ax.set_xlabel("nk")
        ax.set_ylabel("na")
    for ax in list(axes.flat)[len(nbs) :]:
        ax.set_visible(False)
    label = ("validation " if result.sort_by.startswith("val") else "") + result.measure + " RMS"
    if result.sort_by in ("fpe", "aic", "bic"):
        label = result.sort_by.upper()
    if image is not None:
        fig.colorbar(image, ax=axes, label=label)
    shown = "" if len(nbs) == len(all_nbs) else f"; nb {nbs[0]}..{nbs[-1]} of {all_nbs[0]}..{all_nbs[-1]} shown"
    fig.suptitle(f"ARX sweep, {len(result)} structures (grey: diverged or not fitted{shown})")
    return fig
