"""Bode figure of a measured frequency response (:func:`arxid.frf`) against a model: gain with the
estimate's band, phase, coherence shading, and the frequencies where the model leaves the band."""

from __future__ import annotations

from typing import Any

import numpy as np

from .data import new_figure

__all__ = ["plot_bode", "misses", "miss_bands"]

#: Coherence below which the estimate is shaded as unreliable.
_LOW_COHERENCE = 0.5


def misses(fr: Any, model: np.ndarray | None, input: int = 0) -> np.ndarray:
    """Where the model's response lies outside the estimate's confidence disc, |G − Ĥ| > r.

    Parameters
    ----------
    fr : FrequencyResponse
    model : ndarray of complex, shape (n_f,), or None
        The model's response at ``fr.frequency``.
    input : int

    Returns
    -------
    ndarray of bool, shape (n_f,)
        All False without a model.
    """
    if model is None:
        return np.zeros(fr.frequency.size, dtype=bool)
    return np.abs(np.asarray(model) - fr.response[:, input]) > fr.band_radius[:, input]


def miss_bands(fr: Any, model: np.ndarray | None, input: int = 0) -> tuple[tuple[float, float], ...]:
    """The runs of frequencies [Hz] where the model leaves the band (:func:`misses`) while the
    coherence is at least 0.5, as (first, last) pairs.

    Parameters
    ----------
    fr : FrequencyResponse
    model : ndarray of complex, shape (n_f,), or None
    input : int

    Returns
    -------
    tuple of (float, float)
    """
    missed = misses(fr, model, input) & (fr.coherence >= _LOW_COHERENCE)
    edges = np.flatnonzero(np.diff(np.concatenate([[0], missed.astype(np.int8), [0]])))
    f = fr.frequency
    return tuple((float(f[a]), float(f[b - 1])) for a, b in zip(edges[::2], edges[1::2], strict=True))


def _spans(mask: np.ndarray, f: np.ndarray) -> list[tuple[float, float]]:
    """Runs of ``mask`` as frequency intervals, each widened by half a bin on a log axis."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    ratio = np.sqrt(f[1] / f[0]) if f.size > 1 else 1.1
    return [(f[a] / ratio, f[b - 1] * ratio) for a, b in zip(edges[::2], edges[1::2])]


def _shade(axes: Any, fr: Any, missed: np.ndarray) -> None:
    for ax in axes:
        for lo, hi in _spans(fr.coherence < _LOW_COHERENCE, fr.frequency):
            ax.axvspan(lo, hi, color="0.85", lw=0)
        for lo, hi in _spans(missed & (fr.coherence >= _LOW_COHERENCE), fr.frequency):
            ax.axvspan(lo, hi, color="C3", alpha=0.15, lw=0)


def _gain(ax: Any, fr: Any, model: np.ndarray | None, i: int, name: str) -> None:
    f = fr.frequency
    lo, hi = fr.magnitude_band_db
    mag = fr.magnitude_db[:, i]
    floor = np.nanmin(mag) - 20.0
    ax.fill_between(f, np.maximum(lo[:, i], floor), hi[:, i], color="0.6", alpha=0.4, lw=0)
    ax.plot(f, mag, color="k", lw=0.9, label=f"from the data ({fr.method})")
    if model is not None:
        ax.plot(f, 20 * np.log10(np.abs(model)), color="C0", lw=1.3, label=name)
    ax.set_ylim(floor + 10.0, np.nanmax(hi[:, i]) + 5.0)
    out, inp = fr.output_unit, fr.input_units[i]
    unit = f" [{out}/{inp}]" if out and inp else f" [{out} per unit]" if out else ""
    ax.set_ylabel("gain [dB]" + unit, fontsize=8)


def _phase(ax: Any, fr: Any, model: np.ndarray | None, i: int) -> None:
    f = fr.frequency
    ax.plot(f, fr.phase_deg[:, i], ".", color="k", ms=2)
    if model is not None:
        # the model's phase relative to the data's wrap, so both lie on the same branch
        ax.plot(f, fr.phase_deg[:, i] + np.degrees(np.angle(model / fr.response[:, i])), ".", color="C0", ms=2)
    ax.set_ylim(-190, 190)
    ax.set_yticks([-180, -90, 0, 90, 180])
    ax.set_ylabel("phase [deg]", fontsize=8)


def plot_bode(fr: Any, model: np.ndarray | None = None, *, input: int = 0, model_name: str = "model") -> Any:
    """Bode figure: the measured frequency response with its band, a model's on top, the coherence.

    Parameters
    ----------
    fr : FrequencyResponse
        From :func:`arxid.frf`.
    model : ndarray of complex, shape (n_f,), optional
        A model's response at ``fr.frequency`` (:meth:`FrequencyResponse.plot` computes it from a
        fitted model).
    input : int
        Which input.
    model_name : str
        Legend of the model's curve.

    Returns
    -------
    matplotlib.figure.Figure
        Gain [dB] with the band at ``fr.confidence`` (grey), phase (wrapped), coherence. Grey
        shading: coherence below 0.5 (the estimate says little there); red shading: the model
        leaves the band where the coherence is at least 0.5 (it misses the data beyond the
        estimate's uncertainty).
    """
    fig, axes = new_figure(3, 1, height=1.8, sharex=True)
    ax = axes[:, 0]
    ax[0].set_xscale("log")
    missed = misses(fr, model, input)
    _shade(ax, fr, missed)
    _gain(ax[0], fr, model, input, model_name)
    _phase(ax[1], fr, model, input)
    ax[2].plot(fr.frequency, fr.coherence, color="C2", lw=0.9)
    ax[2].set_ylim(0, 1.05)
    ax[2].set_ylabel("coherence", fontsize=8)
    ax[-1].set_xlabel("frequency [Hz]")
    for a in ax:
        a.grid(alpha=0.3, which="both")
        a.tick_params(labelsize=7)
    if missed.any():
        ax[0].axvspan(np.nan, np.nan, color="C3", alpha=0.15, lw=0, label="model outside the band")
    ax[0].legend(fontsize=7, loc="lower left")
    ax[0].set_title(
        f"{fr.output_name} from {fr.input_names[input]}: {fr.summary} (band {100 * fr.confidence:g} %)", fontsize=9
    )
    return fig
