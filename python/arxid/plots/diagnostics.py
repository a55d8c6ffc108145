"""Figures of the model checks: compare, residual tests (MATLAB ``resid`` style), where it fails,
the diagnosis and the ladder. Each draws its stored result object with the result's own bounds,
bins and verdicts; nothing is recomputed here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .. import _metrics as metrics
from .._format import horizon_text
from .data import new_figure, thin

__all__ = [
    "plot_comparison",
    "plot_residuals",
    "plot_failures",
    "plot_error_by_signal",
    "plot_diagnosis",
    "plot_ladder",
]


def _axes(ax: Any, n_rows: int = 1, height: float = 3.0, sharex: bool = False) -> tuple[Any, np.ndarray]:
    """The figure and axes to draw on: ``ax`` (one or several) when given, else a new figure."""
    if ax is None:
        return new_figure(n_rows, 1, height=height, sharex=sharex)
    axes = np.atleast_1d(np.asarray(ax, dtype=object)).reshape(-1, 1)
    return axes[0, 0].figure, axes


def plot_comparison(cmp: Any, ax: Any = None) -> Any:
    """Measured against predicted output (top) and the error of each model (bottom).

    Parameters
    ----------
    cmp : Comparison
    ax : pair of Axes, optional
        Where to draw (output, error); default a new figure.

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, axes = _axes(ax, 2, height=2.4, sharex=True)
    top, bottom = axes[0, 0], axes[1, 0]
    limit = metrics.divergence_limit(cmp.y)
    tt, y = thin(cmp.time, cmp.y)
    top.plot(tt, y, color="k", lw=1.0, label="measured")
    for i, (name, pred, fit, div) in enumerate(zip(cmp.names, cmp.predictions, cmp.fit_percent, cmp.diverged)):
        shown = np.where(np.abs(pred) <= limit, pred, np.nan)
        _, p, e = thin(cmp.time, shown, cmp.y - shown)
        label = f"{name}: " + ("diverged" if div else f"fit {fit:.1f} %")
        top.plot(tt, p, color=f"C{i}", lw=0.9, label=label)
        bottom.plot(tt, e, color=f"C{i}", lw=0.8, label=name)
    unit = f" [{cmp.output_unit}]" if getattr(cmp, "output_unit", "") else ""
    top.set_ylabel(cmp.output_name + unit)
    top.set_title(f"measured output and {horizon_text(cmp.horizon)}", fontsize=9)
    bottom.axhline(0, color="k", lw=0.5)
    bottom.set_ylabel("measured − model" + unit)
    bottom.set_xlabel("time [s]")
    for a in (top, bottom):
        a.grid(alpha=0.3)
        a.legend(fontsize=7, loc="upper right")
    return fig


def _stems(ax: Any, lags: np.ndarray, r: np.ndarray, bound: float, color: str, title: str) -> None:
    ax.vlines(lags, 0, r, color=color, lw=1.2)
    if math.isfinite(bound):
        out = np.abs(r) > bound
        ax.plot(lags[out], r[out], "o", color="C3", ms=3)
        ax.axhspan(-bound, bound, color=color, alpha=0.15, lw=0)
    ax.axhline(0, color="0.5", lw=0.5)
    ax.set_title(title, fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)


def plot_residuals(res: Any, axes: Any = None) -> Any:
    """Autocorrelation of the residual and cross-correlation with each signal, with the analysis'
    own 99 % bounds (lags outside in red) and verdicts.

    Parameters
    ----------
    res : ResidualAnalysis
    axes : sequence of Axes, optional
        One per panel (autocorrelation first, then each signal); default a new figure.

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = list(res.cross_correlation)
    fig, ax = _axes(axes, 1 + len(names), height=1.9)
    ax = ax[:, 0]
    verdict = "white" if res.is_white else "not white"
    lags, auto = res.lags[1:], res.autocorrelation[1:]
    _stems(
        ax[0],
        lags,
        auto,
        res.autocorrelation_bound,
        "C0",
        f"autocorrelation of the residual: Ljung–Box p = {res.ljung_box_p_value:.3g} ({verdict})",
    )
    for a, name in zip(ax[1:], names):
        p = res.cross_p_values.get(name, math.nan)
        tested = (
            "untested (no data)"
            if not math.isfinite(p)
            else f"p = {p:.3g}, " + ("independent" if p >= res.alpha else "NOT independent")
        )
        _stems(
            a,
            res.cross_lags,
            res.cross_correlation[name],
            res.cross_bounds[name],
            "C1",
            f"residual × {name} (positive lag: {name} leads): {tested}",
        )
    ax[-1].set_xlabel("lag [samples]")
    return fig


def plot_failures(fa: Any, ax: Any = None) -> Any:
    """Rolling RMS of the error in time, with the worst segments shaded (significant ones darker).

    Parameters
    ----------
    fa : FailureAnalysis
    ax : Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, axes = _axes(ax, 1, height=2.6)
    a = axes[0, 0]
    tt, r = thin(fa.time, fa.rolling_rms)
    a.plot(tt, r, color="C3", lw=1.0, label=f"{fa.model_name}: rolling RMS ({fa.window} samples)")
    for s in fa.worst_segments:
        a.axvspan(s.start_time, s.end_time, color="C3", alpha=0.3 if s.significant else 0.1, lw=0)
    a.set_xlabel("time [s]")
    a.set_ylabel("rolling RMS error")
    a.set_title(f"where in time the error sits ({horizon_text(fa.horizon)}; shaded: worst segments)", fontsize=9)
    a.grid(alpha=0.3)
    a.legend(fontsize=7)
    return fig


def plot_error_by_signal(fa: Any, other: Any = None, max_panels: int = 8) -> Any:
    """Residual RMS binned by each signal, from the analysis' own bins (significant in red).

    Parameters
    ----------
    fa : FailureAnalysis
    other : FailureAnalysis, optional
        A second model's analysis drawn over it (e.g. after an effect was added).
    max_panels : int
        Signals shown at most (most significant first).

    Returns
    -------
    matplotlib.figure.Figure
    """
    bins = list(fa.by_signal)[:max_panels]
    cols = 2
    rows = max(1, math.ceil(len(bins) / cols))
    fig, axes = new_figure(rows, cols, height=1.9)
    for a in axes.ravel()[len(bins) :]:
        a.set_visible(False)
    significant = set(fa.significant_signals)
    for a, b in zip(axes.ravel(), bins):
        color = "C3" if b.signal in significant else "C0"
        a.plot(b.centers, b.rms, "o-", color=color, ms=3, lw=1.0, label=fa.model_name)
        if other is not None and b.signal in {x.signal for x in other.by_signal}:
            ob = other.bins(b.signal)
            a.plot(ob.centers, ob.rms, "o-", color="C2", ms=3, lw=1.0, label=other.model_name)
        a.set_title(
            f"by {b.signal}: p = {b.p_value:.2g}" + (" (significant)" if b.signal in significant else ""), fontsize=8
        )
        a.tick_params(labelsize=7)
        a.grid(alpha=0.3)
    if bins:
        axes.ravel()[0].legend(fontsize=7)
    fig.suptitle("one-step residual RMS by operating point (equal-count bins; red: significant)", fontsize=9)
    return fig


def plot_diagnosis(diag: Any, n: int = 12) -> Any:
    """Score (partial correlation) and validation change of the top suspects.

    Parameters
    ----------
    diag : Diagnosis
    n : int
        Suspects shown.

    Returns
    -------
    matplotlib.figure.Figure
    """
    sus = list(diag.suspects[:n])
    fig, axes = new_figure(1, 2, height=0.4 * len(sus) + 2)
    ax1, ax2 = axes[0]
    y = np.arange(len(sus))[::-1]
    colors = ["C2" if s.significant else "C0" for s in sus]
    ax1.barh(y, [np.nan_to_num(s.score) for s in sus], color=colors)
    ax1.set_yticks(y, [s.effect for s in sus])
    ax1.set_xlabel("partial correlation with residual")
    change = [100 * s.improvement if s.refitted and np.isfinite(s.improvement) else 0.0 for s in sus]
    ax2.barh(y, change, color=colors)
    ax2.set_yticks(y, [""] * len(sus))
    ax2.axvline(100 * diag.min_improvement, color="0.4", ls="--", lw=0.8)
    ax2.set_xlabel("validation error fall [%]")
    fig.suptitle(f"missing-effect suspects for {diag.model.structure_name()} (green: significant)")
    return fig


def plot_ladder(ladder: Any, ax: Any = None) -> Any:
    """Validation error after each step of the ladder, with what each step added.

    Parameters
    ----------
    ladder : Ladder
    ax : Axes, optional

    Returns
    -------
    matplotlib.figure.Figure
    """
    fig, axes = _axes(ax, 1, height=max(1.2 + 0.45 * len(ladder.steps), 2.2))
    a = axes[0, 0]
    steps = ladder.steps[::-1]
    vals = np.array([s.rms_sim_val if np.isfinite(s.rms_sim_val) else np.nan for s in steps])
    a.barh(range(len(vals)), np.nan_to_num(vals), color=["C0"] * (len(vals) - 1) + ["C2"])
    a.set_yticks(range(len(vals)), [f"+ {s.added}" if s.added else s.structure for s in steps], fontsize=8)
    for i, v in enumerate(vals):
        a.text(v if np.isfinite(v) else 0, i, f" {v:.4g}", va="center", fontsize=8)
    a.set_xlabel(f"validation RMS error ({horizon_text(ladder.horizon)})")
    a.set_title("the error falls as the missing effects are added (top: first model)", fontsize=9)
    a.grid(alpha=0.3, axis="x")
    if np.isfinite(vals).any():
        a.set_xlim(0, np.nanmax(vals) * 1.2)
    return fig
