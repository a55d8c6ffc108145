"""Figures of the data and of step responses, drawn without pyplot (any backend, no display).

:func:`figure_to_data_uri` turns any arxid figure into an embedded PNG for the HTML report.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from .._base.optional import require

__all__ = ["figure_to_data_uri", "data_overview", "step_checks", "thin", "new_figure"]

_WIDTH = 9.0  # inches; at 100 dpi a 900 px wide image, readable on a laptop and on A4


def new_figure(
    n_rows: int = 1, n_cols: int = 1, height: float = 2.2, sharex: bool = False, width: float = _WIDTH
) -> tuple[Any, np.ndarray]:
    """A constrained-layout Figure (no pyplot) and its axes as a 2-D array.

    Parameters
    ----------
    n_rows, n_cols : int
        Grid of axes.
    height : float
        Height of one row in inches.
    sharex : bool
        Share the x axis between rows.
    width : float
        Width in inches.

    Returns
    -------
    fig : matplotlib.figure.Figure
    axes : ndarray of Axes, shape (n_rows, n_cols)
    """
    Figure = require("matplotlib.figure", "plotting").Figure
    fig = Figure(figsize=(width, max(height * n_rows, 2.0)), layout="constrained")
    axes = fig.subplots(n_rows, n_cols, sharex=sharex, squeeze=False)
    return fig, axes


def figure_to_data_uri(fig: Any, dpi: int = 100) -> str:
    """PNG of ``fig`` as a ``data:image/png;base64,...`` URI (self-contained, no file, no network).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    dpi : int

    Returns
    -------
    str
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _label(name: str, unit: str = "") -> str:
    return f"{name} [{unit}]" if unit else name


def thin(t: np.ndarray, *ys: np.ndarray, max_points: int = 4000) -> tuple[np.ndarray, ...]:
    """Min/max envelope decimation, so a long record stays readable: every bucket of samples keeps
    its smallest and largest value (a 40,000-sample overlay is not a solid block).

    Parameters
    ----------
    t : ndarray of shape (n,)
    *ys : ndarray of shape (n,)
    max_points : int
        Largest number of points kept per curve.

    Returns
    -------
    tuple of ndarray
        ``t`` and each of ``ys`` thinned the same way.
    """
    n = len(t)
    k = max(1, -(-n // max(max_points // 2, 1)))  # samples per bucket, so at most max_points kept
    if k == 1:
        return (t,) + tuple(ys)
    m = -(-n // k)  # the last bucket may be partial (padded with NaN): its peaks are kept too
    out_t = np.repeat(np.asarray(t)[::k], 2)
    out = []
    for y in ys:
        flat = np.full(m * k, np.nan)
        flat[:n] = np.asarray(y, dtype=float)
        block = flat.reshape(m, k)
        empty = np.isnan(block).all(axis=1)
        lo = np.where(empty, np.nan, np.where(np.isnan(block), np.inf, block).min(axis=1))
        hi = np.where(empty, np.nan, np.where(np.isnan(block), -np.inf, block).max(axis=1))
        out.append(np.column_stack([lo, hi]).ravel())
    return (out_t,) + tuple(out)


def data_overview(data: Any, max_extra: int = 4, validation_start: int | None = None) -> Any:
    """Output, inputs and up to ``max_extra`` extra signals against time, one panel each.

    Parameters
    ----------
    data : IOData
    max_extra : int
        Extra signals shown at most.
    validation_start : int, optional
        First sample of the validation data: a divider labelled "estimation | validation" is drawn
        there (other experiment starts are thin dashed lines).

    Returns
    -------
    matplotlib.figure.Figure
    """
    names = [data.output_name, *data.input_names, *list(data.extra)[:max_extra]]
    fig, axes = new_figure(len(names), 1, height=1.4, sharex=True)
    t = np.arange(data.n_samples) * data.ts
    for ax, name in zip(axes[:, 0], names):
        tt, x = thin(t, data.signal(name))
        ax.plot(tt, x, lw=0.8, color="C0" if name == data.output_name else ("C1" if name in data.input_names else "C2"))
        ax.set_ylabel(_label(name, data.unit(name)), fontsize=8)
        ax.grid(alpha=0.3)
    for s in data.experiment_starts[1:]:
        if s == validation_start:
            continue
        for ax in axes[:, 0]:
            ax.axvline(s * data.ts, color="0.4", lw=0.6, ls=":")
    if validation_start is not None:
        tv = validation_start * data.ts
        for ax in axes[:, 0]:
            ax.axvline(tv, color="k", lw=1.0, ls="--")
        top = axes[0, 0]
        top.annotate(
            "estimation | validation",
            xy=(tv, 1.0),
            xycoords=("data", "axes fraction"),
            xytext=(0, 3),
            textcoords="offset points",
            ha="center",
            va="bottom",
            fontsize=8,
            fontweight="bold",
        )
    axes[-1, 0].set_xlabel("time [s] (experiments laid end to end)")
    return fig


def step_checks(
    responses: Sequence[tuple[str, np.ndarray]],
    ts: float,
    flags: Mapping[str, str] | None = None,
    ylabel: str = "output",
    bands: Mapping[str, Any] | None = None,
    negatives: Mapping[str, np.ndarray] | None = None,
) -> Any:
    """Responses to a positive and a negative step of several structures (the step sanity check a
    published quadrotor study, Sarıoğlu & Kural, used to reject its best-ranked structure).

    Parameters
    ----------
    responses : sequence of (label, ndarray of shape (n_samples,))
        Response to a positive step of typical amplitude, as a deviation from the response to no
        step (what an offset does is not part of it); the negative step is drawn as its mirror
        (``-response``, exact for a model linear in its inputs) unless ``negatives`` gives it.
    ts : float
        Sampling time [s].
    flags : mapping of label to str, optional
        Why a structure was rejected; drawn dashed with the reason in the legend.
    ylabel : str
        Output name with its unit.
    bands : mapping of label to ResponseBand, optional
        Confidence band of a response, shaded around both steps.
    negatives : mapping of label to ndarray of shape (n_samples,), optional
        Response to the negative step, where it is not the mirror of the positive one (input
        nonlinearities such as ``u1^2``); default: the mirror for every label.

    Returns
    -------
    matplotlib.figure.Figure
    """
    flags = dict(flags or {})
    bands = dict(bands or {})
    negatives = dict(negatives or {})
    fig, axes = new_figure(1, 1, height=3.0)
    ax = axes[0, 0]
    for i, (label, r) in enumerate(responses):
        t = np.arange(len(r)) * ts
        style = "--" if label in flags else "-"
        text = f"{label} (rejected: {flags[label]})" if label in flags else f"{label}"
        neg = np.asarray(negatives[label], dtype=float) if label in negatives else -np.asarray(r, dtype=float)
        if label in bands:
            b = bands[label]
            ax.fill_between(
                t, b.lower, b.upper, color=f"C{i % 10}", alpha=0.25, lw=0, label=f"{label}: {b.description}"
            )
            # the band's half-widths around the negative step (its mirror when neg = -r)
            ax.fill_between(t, neg - (b.upper - r), neg + (r - b.lower), color=f"C{i % 10}", alpha=0.15, lw=0)
        ax.plot(t, r, style, color=f"C{i % 10}", lw=1.2, label=text)
        ax.plot(t, neg, style, color=f"C{i % 10}", lw=0.6, alpha=0.6)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_xlabel("time after the step [s]")
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    title = "step responses, positive (thick) and negative (thin) step"
    if flags:
        title += "; dashed: rejected by the sanity check"
    ax.set_title(title, fontsize=9)
    return fig
