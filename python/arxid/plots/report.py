"""Figures of the HTML report (:mod:`arxid.report`), drawn from numbers, never shown on screen.

Every function returns a :class:`matplotlib.figure.Figure` built without pyplot, so the report
works with any backend, in threads and on machines without a display. :func:`figure_to_data_uri`
turns a figure into an embedded PNG.
"""

from __future__ import annotations

import base64
import io
import math
from typing import Mapping, Sequence

import numpy as np

__all__ = [
    "figure_to_data_uri", "data_overview", "sweep_heatmap", "step_checks", "measured_vs_simulated",
    "residual_correlations", "error_in_time", "error_by_signal", "error_ladder", "correlation",
]

_WIDTH = 9.0  # inches; at 100 dpi a 900 px wide image, readable on a laptop and on A4


def _figure(n_rows: int = 1, n_cols: int = 1, height: float = 2.2, sharex: bool = False, width: float = _WIDTH):
    try:
        from matplotlib.figure import Figure
    except ImportError:  # pragma: no cover
        raise ImportError("the report's plots need matplotlib: pip install 'arxid[plot]'") from None
    fig = Figure(figsize=(width, max(height * n_rows, 2.0)), layout="constrained")
    axes = fig.subplots(n_rows, n_cols, sharex=sharex, squeeze=False)
    return fig, axes


def figure_to_data_uri(fig, dpi: int = 100) -> str:
    """PNG of ``fig`` as a ``data:image/png;base64,...`` URI (self-contained, no file, no network)."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _label(name: str, unit: str = "") -> str:
    return f"{name} [{unit}]" if unit else name


def _thin(t: np.ndarray, *ys: np.ndarray, max_points: int = 4000):
    """Every k-th sample so a plot stays light; long logs are not drawn point by point."""
    step = max(1, len(t) // max_points)
    return (t[::step],) + tuple(y[::step] for y in ys)


def data_overview(data, max_extra: int = 4):
    """Output, inputs and up to ``max_extra`` extra signals against time, one panel each.

    Parameters
    ----------
    data : IOData
    max_extra : int
    """
    names = [data.output_name, *data.input_names, *list(data.extra)[:max_extra]]
    fig, axes = _figure(len(names), 1, height=1.4, sharex=True)
    t = np.arange(data.n_samples) * data.ts
    for ax, name in zip(axes[:, 0], names):
        tt, x = _thin(t, data.signal(name))
        ax.plot(tt, x, lw=0.8, color="C0" if name == data.output_name else ("C1" if name in data.input_names else "C2"))
        ax.set_ylabel(_label(name, data.unit(name)), fontsize=8)
        ax.grid(alpha=0.3)
    for s in data.experiment_starts[1:]:
        for ax in axes[:, 0]:
            ax.axvline(s * data.ts, color="k", lw=0.6, ls="--")
    axes[-1, 0].set_xlabel("time [s] (experiments laid end to end)")
    return fig


def sweep_heatmap(table, value: str, nb_value=None, title: str | None = None):
    """Validation error over (na, nk) for one nb, as a colour map with the best cell marked.

    Parameters
    ----------
    table : pandas.DataFrame
        One row per structure with columns ``na``, ``nb``, ``nk`` (ints) and ``value``.
    value : str
        Column to show (lower is better); NaN cells (diverged) are grey.
    nb_value : int, optional
        Which nb to show; default: the nb of the best row.
    title : str, optional
        Figure title.
    """
    df = table[np.isfinite(table[value].astype(float))]
    if nb_value is None:
        nb_value = df.loc[df[value].astype(float).idxmin(), "nb"] if len(df) else table["nb"].iloc[0]
    sub = table[table["nb"] == nb_value]
    nas = sorted(set(int(x) for x in sub["na"]))
    nks = sorted(set(int(x) for x in sub["nk"]))
    grid = np.full((len(nas), len(nks)), np.nan)
    for _, row in sub.iterrows():
        grid[nas.index(int(row["na"])), nks.index(int(row["nk"]))] = float(row[value])
    fig, axes = _figure(1, 1, height=min(0.45 * len(nas) + 1.6, 5.0), width=min(_WIDTH, 2.5 + 0.55 * len(nks)))
    ax = axes[0, 0]
    finite = grid[np.isfinite(grid)]
    if finite.size and finite.min() > 0:
        from matplotlib.colors import LogNorm
        norm = LogNorm(vmin=finite.min(), vmax=max(finite.max(), finite.min() * 1.0001))
    else:
        norm = None
    cmap = _cmap()
    im = ax.imshow(np.ma.masked_invalid(grid), cmap=cmap, norm=norm, aspect="auto", origin="lower")
    ax.set_xticks(range(len(nks)), [str(k) for k in nks])
    ax.set_yticks(range(len(nas)), [str(a) for a in nas])
    ax.set_xlabel("nk (delay, samples)")
    ax.set_ylabel("na")
    if finite.size:
        i, j = np.unravel_index(np.nanargmin(grid), grid.shape)
        ax.plot(j, i, marker="o", mfc="none", mec="k", ms=14, mew=1.5)
    fig.colorbar(im, ax=ax, label=value)
    ax.set_title(title or f"{value} for nb = {nb_value} (circle: lowest; grey: diverged)", fontsize=9)
    return fig


def _cmap():
    from matplotlib import colormaps
    cmap = colormaps["viridis"].copy()
    cmap.set_bad("0.8")
    return cmap


def step_checks(responses: Sequence[tuple[str, np.ndarray]], ts: float, flags: Mapping[str, str] | None = None):
    """Responses to a positive and a negative step of several structures (seed 004's sanity check).

    Parameters
    ----------
    responses : sequence of (label, ndarray of shape (n_samples,))
        Response to a positive step of typical amplitude; the negative step is drawn as its mirror
        computed by the caller (or, for a linear model, ``-response``).
    ts : float
    ts : float
        Sampling time [s].
    flags : mapping of label to str, optional
        Why a structure was rejected; drawn dashed with the reason in the legend.
    """
    flags = dict(flags or {})
    fig, axes = _figure(1, 1, height=3.0)
    ax = axes[0, 0]
    for i, (label, r) in enumerate(responses):
        t = np.arange(len(r)) * ts
        style = "--" if label in flags else "-"
        text = f"{label}: {flags[label]}" if label in flags else f"{label}"
        ax.plot(t, r, style, color=f"C{i % 10}", lw=1.2, label=text)
        ax.plot(t, -r, style, color=f"C{i % 10}", lw=0.6, alpha=0.6)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("time after the step [s]")
    ax.set_ylabel("output")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    ax.set_title("step responses, positive (thick) and negative (thin) step; dashed: rejected", fontsize=9)
    return fig


def measured_vs_simulated(data, predictions: Sequence[tuple[str, np.ndarray]], title: str = ""):
    """Measured output with model outputs over it, and each model's error underneath.

    Parameters
    ----------
    data : IOData
        Validation data.
    predictions : sequence of (label, ndarray of shape (n_samples,))
        Simulated (or k-step predicted) output, NaN where there is none.
    title : str
        Figure title.
    """
    fig, axes = _figure(2, 1, height=2.4, sharex=True)
    t = np.arange(data.n_samples) * data.ts
    tt, y = _thin(t, data.y)
    axes[0, 0].plot(tt, y, color="k", lw=1.0, label="measured")
    for i, (label, p) in enumerate(predictions):
        _, pp, e = _thin(t, p, data.y - p)
        axes[0, 0].plot(tt, pp, color=f"C{i}", lw=0.9, label=label)
        axes[1, 0].plot(tt, e, color=f"C{i}", lw=0.8, label=label)
    axes[0, 0].set_ylabel(_label(data.output_name, data.output_unit))
    axes[1, 0].set_ylabel("measured − model")
    axes[1, 0].axhline(0, color="k", lw=0.5)
    axes[1, 0].set_xlabel("time [s]")
    for ax in axes[:, 0]:
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="upper right")
    if title:
        axes[0, 0].set_title(title, fontsize=9)
    return fig


def correlation(a: np.ndarray, b: np.ndarray, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised cross-correlation r(τ) = Σ a(t) b(t−τ) / (N σ_a σ_b) for τ = −L..L, NaN-safe.

    Returns
    -------
    lags : ndarray of shape (2L+1,)
    r : ndarray of shape (2L+1,)
    """
    ok = np.isfinite(a) & np.isfinite(b)
    a = np.where(ok, a - np.mean(a[ok]), 0.0) if ok.any() else np.zeros_like(a)
    b = np.where(ok, b - np.mean(b[ok]), 0.0) if ok.any() else np.zeros_like(b)
    n = int(ok.sum())
    den = math.sqrt(float(np.dot(a, a)) * float(np.dot(b, b)))
    lags = np.arange(-max_lag, max_lag + 1)
    r = np.zeros(len(lags))
    if den == 0 or n == 0:
        return lags, r
    for i, tau in enumerate(lags):
        if tau >= 0:
            r[i] = np.dot(a[tau:], b[:len(b) - tau]) if tau < len(a) else 0.0
        else:
            r[i] = np.dot(a[:tau], b[-tau:])
    return lags, r / den


def residual_correlations(residual: np.ndarray, signals: Mapping[str, np.ndarray], max_lag: int = 25):
    """Autocorrelation of the residual and its cross-correlation with each signal, with 99 % bounds
    ±2.58/√N (in the style of MATLAB ``resid``).

    Parameters
    ----------
    residual : ndarray of shape (n_samples,)
        One-step prediction error (NaN where none).
    signals : mapping of str to ndarray of shape (n_samples,)
        Inputs and extra signals to correlate with.
    max_lag : int
        Largest lag shown.
    """
    n = int(np.isfinite(residual).sum())
    bound = 2.58 / math.sqrt(max(n, 1))
    panels = [("residual autocorrelation", residual)] + [(f"residual × {k}", v) for k, v in signals.items()]
    cols = 2
    rows = int(math.ceil(len(panels) / cols))
    fig, axes = _figure(rows, cols, height=1.9)
    for ax in axes.ravel()[len(panels):]:
        ax.set_visible(False)
    for ax, (title, sig) in zip(axes.ravel(), panels):
        lags, r = correlation(residual, sig, max_lag)
        if title == "residual autocorrelation":
            keep = lags >= 0
            lags, r = lags[keep], r[keep]
        out = np.abs(r) > bound
        if title == "residual autocorrelation":
            out[lags == 0] = False
        ax.vlines(lags, 0, r, color="C0", lw=1.2)
        ax.plot(lags[out], r[out], "o", color="C3", ms=3)
        ax.axhspan(-bound, bound, color="C0", alpha=0.12, lw=0)
        ax.axhline(0, color="k", lw=0.5)
        ax.set_title(title, fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    fig.suptitle(f"correlations of the one-step residual; shaded: 99 % bound ±{bound:.3g}; red: outside", fontsize=9)
    return fig


def rolling_rms(e: np.ndarray, window: int) -> np.ndarray:
    """Centred rolling RMS of ``e`` over ``window`` samples, ignoring NaN."""
    ok = np.isfinite(e)
    sq = np.where(ok, e * e, 0.0)
    k = np.ones(max(int(window), 1))
    num = np.convolve(sq, k, mode="same")
    cnt = np.convolve(ok.astype(float), k, mode="same")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt(num / cnt)


def error_in_time(data, errors: Sequence[tuple[str, np.ndarray]], window_s: float | None = None):
    """Rolling RMS of each model's error against time: where in the log the model fails.

    Parameters
    ----------
    data : IOData
    errors : sequence of (label, ndarray of shape (n_samples,))
    window_s : float, optional
        Window in seconds (default 1/50 of the log, at least 10 samples).
    """
    n = data.n_samples
    w = max(10, int(round(window_s / data.ts)) if window_s else n // 50)
    fig, axes = _figure(1, 1, height=2.4)
    ax = axes[0, 0]
    t = np.arange(n) * data.ts
    for i, (label, e) in enumerate(errors):
        tt, r = _thin(t, rolling_rms(e, w))
        ax.plot(tt, r, color=f"C{i}", lw=1.0, label=label)
    ax.set_xlabel("time [s]")
    ax.set_ylabel("rolling RMS error")
    ax.set_title(f"where in time the error sits (window {w * data.ts:g} s)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def binned_rms(x: np.ndarray, e: np.ndarray, n_bins: int = 10) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """RMS of ``e`` in quantile bins of ``x``: (bin centres, RMS, samples per bin)."""
    ok = np.isfinite(x) & np.isfinite(e)
    x, e = x[ok], e[ok]
    if x.size < n_bins or np.ptp(x) == 0:
        return np.array([]), np.array([]), np.array([])
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n_bins + 1)))
    idx = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    centres, rms, count = [], [], []
    for b in range(len(edges) - 1):
        sel = idx == b
        if sel.any():
            centres.append(float(np.mean(x[sel])))
            rms.append(float(np.sqrt(np.mean(e[sel] ** 2))))
            count.append(int(sel.sum()))
    return np.array(centres), np.array(rms), np.array(count)


def error_by_signal(data, error: np.ndarray, names: Sequence[str], n_bins: int = 10,
                    other: np.ndarray | None = None, labels: tuple[str, str] = ("before", "after")):
    """RMS of the error binned by each signal's value: at which operating point the model fails.

    Parameters
    ----------
    data : IOData
    error : ndarray of shape (n_samples,)
    names : sequence of str
        Signals to bin by (output, inputs, extra signals; ``"d<output>"`` is the output's rate).
    n_bins : int
        Number of equal-count bins.
    other : ndarray of shape (n_samples,), optional
        A second model's error, drawn for comparison.
    labels : (str, str)
        Legend labels of ``error`` and ``other``.
    """
    cols = 3
    rows = int(math.ceil(len(names) / cols)) or 1
    fig, axes = _figure(rows, cols, height=1.9)
    for ax in axes.ravel()[len(names):]:
        ax.set_visible(False)
    for ax, name in zip(axes.ravel(), names):
        if name == "d" + data.output_name:
            x = np.gradient(data.y) / data.ts
        else:
            x = data.signal(name)
        for k, (e, lab) in enumerate([(error, labels[0]), (other, labels[1])]):
            if e is None:
                continue
            c, r, _ = binned_rms(x, e, n_bins)
            ax.plot(c, r, "o-", color=f"C{3 if k == 0 else 2}", ms=3, lw=1.0, label=lab)
        ax.set_title(f"RMS error by {name}", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    if other is not None and len(names):
        axes.ravel()[0].legend(fontsize=7)
    fig.suptitle("where the error sits by operating point (equal-count bins)", fontsize=9)
    return fig


def error_ladder(steps: Sequence[tuple[str, float]], metric: str = "validation RMS error"):
    """Bars of the validation error as effects are added, one bar per ladder step.

    Parameters
    ----------
    steps : sequence of (label, value)
    metric : str
        Axis label: what the value measures.
    """
    fig, axes = _figure(1, 1, height=max(1.2 + 0.45 * len(steps), 2.2))
    ax = axes[0, 0]
    labels = [s[0] for s in steps][::-1]
    vals = np.array([s[1] if s[1] is not None else np.nan for s in steps][::-1], dtype=float)
    ax.barh(range(len(vals)), np.nan_to_num(vals), color=["C2" if i == 0 else "C0" for i in range(len(vals))])
    ax.set_yticks(range(len(vals)), labels, fontsize=8)
    for i, v in enumerate(vals):
        ax.text(v if np.isfinite(v) else 0, i, f" {v:.4g}", va="center", fontsize=8)
    ax.set_xlabel(metric)
    ax.set_title("the error falls as the missing effects are added (top: first model)", fontsize=9)
    ax.grid(alpha=0.3, axis="x")
    if np.isfinite(vals).any():
        ax.set_xlim(0, np.nanmax(vals) * 1.2)
    return fig
