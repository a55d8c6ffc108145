"""Figure of a :class:`~arxid.frequency.FrequencyCheck`: the data's frequency response beside the
model's, both with their bands, the disagreeing bands shaded, the coherence and the error spectrum."""

from __future__ import annotations

from typing import Any

import numpy as np

from .._base.metrics import normal_quantile
from .data import new_figure

__all__ = ["plot_frequency_check"]


def _unit_ratio(out_unit: str, in_unit: str) -> str:
    if out_unit and in_unit:
        return f" [{out_unit}/{in_unit}]"
    return f" [{out_unit} per input unit]" if out_unit else ""


def _shade(axes: Any, fc: Any, name: str) -> None:
    half_bin = 0.5 * (fc.frequency[1] - fc.frequency[0]) if len(fc.frequency) > 1 else 0.0
    for ax in axes:
        for b in fc.bands:
            if b.input == name:
                ax.axvspan(max(b.low - half_bin, 0.5 * b.low), b.high + half_bin, color="C3", alpha=0.15, lw=0)


def _log_band(mag: np.ndarray, sd: np.ndarray, z: float) -> tuple[np.ndarray, np.ndarray]:
    """The band |G| ± z·sd drawn on a log axis: the lower edge stops at |G|/100 where sd ≥ |G|."""
    return np.maximum(mag - z * sd, mag / 100), mag + z * sd


def _magnitude(ax: Any, fc: Any, i: int, z: float) -> None:
    f = fc.frequency
    h, g = np.abs(fc.data_response[:, i]), np.abs(fc.model_response[:, i])
    sd_h, sd_g = fc.data_sd[:, i], fc.model_sd[:, i]
    ax.fill_between(f, *_log_band(h, sd_h, z), color="0.6", alpha=0.35, lw=0)
    ax.plot(f, h, color="k", lw=0.9, label="from the data (H1 estimate)")
    ax.fill_between(f, *_log_band(g, sd_g, z), color="C0", alpha=0.3, lw=0)
    ax.plot(f, g, color="C0", lw=1.2, label=f"model {fc.model_name}")
    ax.set_yscale("log")
    curves = np.concatenate([h[h > 0], g[g > 0]])
    if curves.size:
        ax.set_ylim(curves.min() / 5, curves.max() * 5)
    ax.set_ylabel("gain" + _unit_ratio(fc.output_unit, fc.input_units[i]))


def _phase(ax: Any, fc: Any, i: int) -> None:
    f = fc.frequency
    # wrapped to ±180°: unwrapping a noisy estimate adds spurious turns
    ax.plot(f, np.degrees(np.angle(fc.data_response[:, i])), ".", color="k", ms=2)
    ax.plot(f, np.degrees(np.angle(fc.model_response[:, i])), ".", color="C0", ms=2)
    ax.set_ylim(-190, 190)
    ax.set_yticks([-180, -90, 0, 90, 180])
    ax.set_ylabel("phase [deg]")


def _coherence(ax: Any, fc: Any) -> None:
    ax.plot(fc.frequency, fc.coherence, color="C2", lw=0.9)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("coherence")


def _spectra(ax: Any, fc: Any) -> None:
    unit = f" [({fc.output_unit})²/Hz]" if fc.output_unit else " [unit²/Hz]"
    ax.plot(fc.frequency, fc.residual_spectrum, color="C3", lw=0.9, label="error of the model")
    ax.plot(fc.frequency, fc.noise_spectrum, color="0.4", lw=0.9, ls="--", label="not explained by any linear model")
    ax.set_yscale("log")
    ax.set_ylabel("error spectrum" + unit, fontsize=8)


def plot_frequency_check(fc: Any, input: int = 0) -> Any:
    """Frequency response from the data against the model's, coherence and error spectrum.

    Parameters
    ----------
    fc : FrequencyCheck
    input : int
        Which input's transfer function.

    Returns
    -------
    matplotlib.figure.Figure
        Four panels sharing the frequency axis (Hz, logarithmic): gain with the bands at the
        check's level (grey: data, blue: model), phase, coherence, and the power spectra of the
        model's error and of the part no linear model can explain. Red shading: where the model
        misses the data beyond both uncertainties.
    """

    name = fc.input_names[input]
    fig, axes = new_figure(4, 1, height=1.7, sharex=True)
    ax = axes[:, 0]
    ax[0].set_xscale("log")
    _magnitude(ax[0], fc, input, normal_quantile(fc.level))
    _phase(ax[1], fc, input)
    _coherence(ax[2], fc)
    _spectra(ax[3], fc)
    _shade(ax, fc, name)
    for a in ax:
        a.grid(alpha=0.3, which="both")
        a.tick_params(labelsize=7)
    if any(b.input == name for b in fc.bands):
        ax[0].axvspan(np.nan, np.nan, color="C3", alpha=0.15, lw=0, label="misses the data")
    ax[0].legend(fontsize=7, loc="lower left")
    ax[3].legend(fontsize=7, loc="lower left")
    ax[-1].set_xlabel("frequency [Hz]")
    ax[0].set_title(
        f"{fc.output_name} from {name}: {fc.summary} (bands: {100 * fc.level:g} %)",
        fontsize=9,
    )
    return fig
