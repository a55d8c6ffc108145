"""Figures for the diagnostics: compare, residuals (MATLAB ``resid`` style), where-it-fails,
diagnosis and ladder.

Every function returns a :class:`matplotlib.figure.Figure` built without pyplot (safe with the Agg
backend and in servers); save it with ``fig.savefig(path)``.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["plot_comparison", "plot_residuals", "plot_failures", "plot_diagnosis", "plot_ladder"]


def _figure(width: float = 8.0, height: float = 5.0):
    try:
        from matplotlib.figure import Figure
    except ImportError:  # pragma: no cover
        raise ImportError("plots need matplotlib: pip install 'arxid[plot]'") from None
    return Figure(figsize=(width, height), layout="constrained")


def _hlabel(horizon):
    return "simulated (free run)" if horizon is None else ("one-step prediction" if horizon == 1 else f"{horizon}-step prediction")


def plot_comparison(cmp):
    """Measured against predicted output (top) and the error of each model (bottom)."""
    fig = _figure(9, 6)
    ax1, ax2 = fig.subplots(2, 1, sharex=True, height_ratios=[2, 1])
    ax1.plot(cmp.time, cmp.y, color="0.3", lw=1.0, label="measured")
    for name, pred, fit, div in zip(cmp.names, cmp.predictions, cmp.fit_percent, cmp.diverged):
        shown = np.where(np.abs(pred) < 1e3 * (np.nanmax(np.abs(cmp.y)) + 1e-300), pred, np.nan)
        label = f"{name}: " + ("diverged" if div else f"fit {fit:.1f}%")
        (line,) = ax1.plot(cmp.time, shown, lw=1.0, label=label)
        ax2.plot(cmp.time, cmp.y - shown, lw=0.8, color=line.get_color())
    ax1.set_ylabel(cmp.output_name)
    ax1.set_title(f"measured and {_hlabel(cmp.horizon)}")
    ax1.legend(loc="best", fontsize="small")
    ax2.axhline(0, color="0.5", lw=0.5)
    ax2.set_ylabel("error")
    ax2.set_xlabel("time [s]")
    return fig


def plot_residuals(res):
    """Autocorrelation of the residual and cross-correlation with each signal, 99% bands."""
    names = list(res.cross_correlation)
    fig = _figure(8, 2.4 * (1 + len(names)))
    axes = np.atleast_1d(fig.subplots(1 + len(names), 1))
    ax = axes[0]
    ax.vlines(res.lags, 0, res.autocorrelation, color="C0")
    ax.plot(res.lags, res.autocorrelation, "o", color="C0", ms=3)
    b = res.autocorrelation_bound
    ax.axhspan(-b, b, color="C0", alpha=0.15, lw=0)
    ax.axhline(0, color="0.5", lw=0.5)
    ax.set_title(f"autocorrelation of residual e (Ljung–Box p = {res.ljung_box_p_value:.3g})")
    ax.set_xlabel("lag")
    for ax, name in zip(axes[1:], names):
        r = res.cross_correlation[name]
        ax.vlines(res.cross_lags, 0, r, color="C1")
        ax.plot(res.cross_lags, r, "o", color="C1", ms=3)
        b = res.cross_bounds[name]
        if math.isfinite(b):
            ax.axhspan(-b, b, color="C1", alpha=0.15, lw=0)
        ax.axhline(0, color="0.5", lw=0.5)
        untested = "" if math.isfinite(b) else ": untested, no data"
        ax.set_title(f"cross-correlation of e with {name} (positive lag: {name} leads){untested}")
        ax.set_xlabel("lag")
    return fig


def plot_failures(fa):
    """Error and rolling RMS in time with the worst segments shaded; residual RMS by signal."""
    bins = list(fa.by_signal)
    ncols = min(3, max(len(bins), 1))
    nrows = 1 + math.ceil(len(bins) / ncols)
    fig = _figure(10, 2.6 * nrows)
    grid = fig.add_gridspec(nrows, ncols)
    ax = fig.add_subplot(grid[0, :])
    ax.plot(fa.time, fa.error, color="0.6", lw=0.6, label="error")
    ax.plot(fa.time, fa.rolling_rms, color="C3", lw=1.2, label=f"rolling rms ({fa.window} samples)")
    for s in fa.worst_segments:
        ax.axvspan(s.start_time, s.end_time, color="C3", alpha=0.15, lw=0)
    ax.set_title(f"where it fails: error in time ({_hlabel(fa.horizon)})")
    ax.set_xlabel("time [s]")
    ax.legend(loc="best", fontsize="small")
    k = max(len(bins), 1)
    for i, b in enumerate(bins):
        ax = fig.add_subplot(grid[1 + i // ncols, i % ncols])
        widths = np.diff(b.edges)
        sig = b.p_value * k < fa.alpha
        ax.bar(b.edges[:-1], b.rms, width=widths, align="edge", color="C3" if sig else "C0", alpha=0.7,
               edgecolor="white")
        ax.set_title(f"{b.signal}: p = {b.p_value:.2g}", fontsize="small")
        ax.set_ylabel("residual rms", fontsize="small")
    return fig


def plot_diagnosis(diag, n: int = 12):
    """Score (partial correlation) and validation change of the top suspects."""
    sus = list(diag.suspects[:n])
    fig = _figure(9, 0.4 * len(sus) + 2)
    ax1, ax2 = fig.subplots(1, 2, sharey=True)
    y = np.arange(len(sus))[::-1]
    labels = [s.effect for s in sus]
    colors = ["C2" if s.significant else "C0" for s in sus]
    ax1.barh(y, [np.nan_to_num(s.score) for s in sus], color=colors)
    ax1.set_yticks(y, labels)
    ax1.set_xlabel("partial correlation with residual")
    change = [100 * s.improvement if s.refitted and np.isfinite(s.improvement) else 0.0 for s in sus]
    ax2.barh(y, change, color=colors)
    ax2.axvline(100 * diag.min_improvement, color="0.4", ls="--", lw=0.8)
    ax2.set_xlabel("validation error fall [%]")
    fig.suptitle(f"missing-effect suspects for {diag.model.structure_name()} (green: significant)")
    return fig


def plot_ladder(ladder):
    """Validation error after each step of the ladder."""
    fig = _figure(7, 4)
    ax = fig.subplots()
    x = np.arange(len(ladder.steps))
    err = [s.rms_sim_val if np.isfinite(s.rms_sim_val) else np.nan for s in ladder.steps]
    ax.plot(x, err, "o-", color="C3")
    for xi, e, s in zip(x, err, ladder.steps):
        if np.isfinite(e):
            ax.annotate(f"{e:.3g}", (xi, e), textcoords="offset points", xytext=(0, 6), ha="center", fontsize="small")
    ax.set_xticks(x, [s.added or "start" for s in ladder.steps], rotation=20)
    ax.set_ylabel("validation rms error")
    ax.set_ylim(bottom=0)
    ax.set_title(f"the error falls ({_hlabel(ladder.horizon)})")
    return fig
