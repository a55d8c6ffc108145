"""Figures of the model checks: compare, residual tests (MATLAB ``resid`` style), where it fails,
the diagnosis and the ladder. Each draws its stored result object with the result's own bounds,
bins and verdicts; nothing is recomputed here.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from .._base import metrics
from .._base.formatting import horizon_text
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


#: Records longer than this are drawn as a min/max envelope plus a zoom on the worst window.
LONG_RECORD = 3000


def _envelope(ax: Any, t: np.ndarray, y: np.ndarray, color: str, label: str, lw: float = 0.9) -> None:
    """A curve, or for a long record its min/max envelope per pixel-sized bucket (shaded)."""
    if len(t) <= LONG_RECORD:
        ax.plot(t, y, color=color, lw=lw, label=label)
        return
    tt, yy = thin(t, y, max_points=1200)
    lo, hi = yy[0::2], yy[1::2]
    ax.fill_between(tt[0::2], lo, hi, color=color, alpha=0.45, lw=0, label=label + " (min–max envelope)")


def _band(ax: Any, t: np.ndarray, band: Any, color: str, sl: slice = slice(None)) -> None:
    """The band shaded; for a long record per pixel-sized bucket from its lowest lower to its
    highest upper bound (the band drawn never narrower than the computed one)."""
    if band is None:
        return
    tt, lower, upper = t[sl], band.lower[sl], band.upper[sl]
    if len(tt) > LONG_RECORD:
        tt, lo2, hi2 = thin(tt, lower, upper, max_points=1200)
        tt, lower, upper = tt[0::2], lo2[0::2], hi2[1::2]
    ax.fill_between(tt, lower, upper, color=color, alpha=0.25, lw=0)


def _zoom_slice(cmp: Any, zoom: tuple[float, float] | None) -> slice | None:
    """The samples of the zoom window, widened to at least 400 samples (None: no zoom)."""
    n = len(cmp.time)
    if zoom is None or n <= LONG_RECORD:
        return None
    i0, i1 = (int(np.searchsorted(cmp.time, z)) for z in zoom)
    half = max((i1 - i0) // 2, 200)
    mid = (i0 + i1) // 2
    return slice(max(mid - half, 0), min(mid + half, n))


def plot_comparison(cmp: Any, ax: Any = None, bands: Any = None, zoom: tuple[float, float] | None = None) -> Any:
    """Measured against predicted output (top) and the error of each model (bottom).

    Parameters
    ----------
    cmp : Comparison
    ax : sequence of Axes, optional
        Where to draw (output, error, and the zoom when there is one); default a new figure.
    bands : sequence of ResponseBand or None, optional
        Confidence band of each model's prediction (same order as ``cmp.names``), shaded.
    zoom : (float, float), optional
        A time window in seconds (e.g. where the model fails worst), drawn at full resolution in a
        third panel when the record is longer than :data:`LONG_RECORD` samples; the long panels
        are min/max envelopes then.

    Returns
    -------
    matplotlib.figure.Figure
    """
    zs = _zoom_slice(cmp, zoom)
    fig, axes = _axes(ax, 2 if zs is None else 3, height=2.4)
    top, bottom = axes[0, 0], axes[1, 0]
    bottom.sharex(top)
    limit = metrics.divergence_limit(cmp.y)
    bands = list(bands) if bands else [None] * len(cmp.names)
    _envelope(top, cmp.time, cmp.y, "k", "measured")
    for i, (name, pred, fit, div, band) in enumerate(
        zip(cmp.names, cmp.predictions, cmp.fit_percent, cmp.diverged, bands)
    ):
        shown = np.where(np.abs(pred) <= limit, pred, np.nan)
        label = f"{name}: " + ("diverged" if div else f"fit {fit:.1f} %")
        _band(top, cmp.time, band, f"C{i}")
        _envelope(top, cmp.time, shown, f"C{i}", label)
        _envelope(bottom, cmp.time, cmp.y - shown, f"C{i}", name, lw=0.8)
    unit = f" [{cmp.output_unit}]" if getattr(cmp, "output_unit", "") else ""
    shaded = " (shaded: 99 % band from the parameter covariance)" if any(b is not None for b in bands) else ""
    top.set_ylabel(cmp.output_name + unit)
    top.set_title(f"measured output and {horizon_text(cmp.horizon)}{shaded}", fontsize=9)
    bottom.axhline(0, color="k", lw=0.5)
    bottom.set_ylabel("measured − model" + unit)
    bottom.set_xlabel("time [s]")
    if zs is not None:
        _zoom(axes[2, 0], cmp, bands, zs, unit)
        top.axvspan(cmp.time[zs.start], cmp.time[zs.stop - 1], color="C3", alpha=0.12, lw=0)
    for a in axes[:, 0]:
        a.grid(alpha=0.3)
        a.legend(fontsize=7, loc="upper right")
    return fig


def _zoom(ax: Any, cmp: Any, bands: list, zs: slice, unit: str) -> None:
    t = cmp.time[zs]
    ax.plot(t, cmp.y[zs], color="k", lw=1.0, label="measured")
    for i, (name, pred, band) in enumerate(zip(cmp.names, cmp.predictions, bands)):
        _band(ax, cmp.time, band, f"C{i}", zs)
        ax.plot(t, pred[zs], color=f"C{i}", lw=0.9, label=name)
    ax.set_title(f"zoom: {t[0]:.4g}–{t[-1]:.4g} s, where the first model fails worst (shaded above)", fontsize=9)
    ax.set_ylabel(cmp.output_name + unit)
    ax.set_xlabel("time [s]")


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
    # reversed: the last step (the final model, green) is the lowest bar
    a.barh(range(len(vals)), np.nan_to_num(vals), color=["C2"] + ["C0"] * (len(vals) - 1))
    n = len(ladder.steps)
    kinds = [ladder.step_kind(n - 1 - i) for i in range(n)]
    labels = [s.structure if k == "start" else f"+ {s.added} ({k})" for s, k in zip(steps, kinds)]
    a.set_yticks(range(len(vals)), labels, fontsize=8)
    for i, v in enumerate(vals):
        a.text(v if np.isfinite(v) else 0, i, f" {v:.4g}", va="center", fontsize=8)
    a.set_xlabel(f"validation RMS error ({horizon_text(ladder.horizon)})")
    a.set_title("the error as effects and structure changes are added (top: first model; green: final)", fontsize=9)
    a.grid(alpha=0.3, axis="x")
    if np.isfinite(vals).any():
        a.set_xlim(0, np.nanmax(vals) * 1.2)
    return fig
