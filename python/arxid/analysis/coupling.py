"""How strongly each input drives each output of a model of several inputs and outputs:
:func:`coupling` → :class:`Coupling`.

The steady-state gain G(1) and the peak gain max_ω |G_ij(e^{jωTs})| in the signals' units, and,
on measured data, the share of each output's motion that each input's path carries: the RMS of
output i simulated from input j alone (the other inputs held at zero) over the RMS of output i
about its mean. The shares are dimensionless and comparable: a plant without cross-coupling has
them on its diagonal.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from .._base.formatting import finite_or_none, text_table
from ..data.iodata import IOData
from ..models.mimo_data import gather
from ..models.state_space import StateSpaceModel

__all__ = ["Coupling", "coupling", "N_FREQUENCIES"]

#: Frequencies (log-spaced from 1/1000 of Nyquist to Nyquist, and 0) on which the peak gain is read.
N_FREQUENCIES = 400


@dataclass(frozen=True, eq=False)
class Coupling:
    """Gains of every input → output path of a model.

    Attributes
    ----------
    input_names, output_names : tuple of str
    input_units, output_units : tuple of str
    steady_state : ndarray of shape (n_outputs, n_inputs)
        G(1) (output unit per input unit); inf for a path with an integrator.
    peak : ndarray of shape (n_outputs, n_inputs)
        Largest |G_ij| over the frequency grid.
    peak_frequency : ndarray of shape (n_outputs, n_inputs)
        Where it is reached, Hz.
    share : ndarray of shape (n_outputs, n_inputs)
        RMS of output i simulated from input j alone over the RMS of measured output i about its
        mean (dimensionless); NaN without data.
    """

    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    input_units: tuple[str, ...]
    output_units: tuple[str, ...]
    steady_state: np.ndarray
    peak: np.ndarray
    peak_frequency: np.ndarray
    share: np.ndarray

    def strongest_input(self, output: str) -> str:
        """The input whose path carries the largest share of ``output`` (the largest peak gain without data).

        Parameters
        ----------
        output : str
            One of ``output_names``.

        Returns
        -------
        str
        """
        row = self.share[self.output_names.index(output)]
        row = self.peak[self.output_names.index(output)] if not np.isfinite(row).any() else row
        return self.input_names[int(np.nanargmax(row))]

    def to_dict(self) -> dict:
        """JSON-ready gains by output and input.

        Returns
        -------
        dict
            ``{"steady_state" | "peak" | "peak_frequency_hz" | "share": {output: {input: value}}}``;
            non-finite numbers are None.
        """

        def table(values: np.ndarray) -> dict:
            return {
                out: {inp: finite_or_none(float(values[i, j])) for j, inp in enumerate(self.input_names)}
                for i, out in enumerate(self.output_names)
            }

        return {
            "steady_state": table(self.steady_state),
            "peak": table(self.peak),
            "peak_frequency_hz": table(self.peak_frequency),
            "share": table(self.share),
        }

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None

        Returns
        -------
        str
        """
        return json.dumps(self.to_dict(), indent=indent)

    def __str__(self) -> str:
        rows = [
            [out, *[f"{self.share[i, j]:.3g}" for j in range(len(self.input_names))]]
            for i, out in enumerate(self.output_names)
        ]
        head = ["output \\ input", *self.input_names]
        return (
            "coupling: share of each output's motion carried by each input's path (RMS of the output "
            "simulated from that input alone / RMS of the output)\n" + text_table(head, rows)
        )


def coupling(model: StateSpaceModel, data: IOData | None = None) -> Coupling:
    """The gains of every input → output path of ``model``, scaled on ``data``.

    Parameters
    ----------
    model : StateSpaceModel
    data : IOData, optional
        Data with the model's inputs and outputs, on which the shares are measured.

    Returns
    -------
    Coupling
    """
    nyquist = 0.5 / model.ts
    frequencies = np.concatenate([[0.0], np.geomspace(nyquist / 1000, nyquist, N_FREQUENCIES)])
    shape = (model.n_outputs, model.n_inputs)
    if np.any(np.abs(model.poles - 1) < 1e-9):  # an integrator: no steady state, an unbounded peak
        steady, response = np.full(shape, np.inf), np.full((len(frequencies), *shape), np.inf)
    else:
        with np.errstate(all="ignore"):
            response = np.abs(model.frequency_response(frequencies))  # (frequency, output, input)
        steady = model.frequency_response([0.0])[0].real
    peak_at = np.argmax(np.nan_to_num(response, nan=-1.0), axis=0)
    peak = np.take_along_axis(response, peak_at[None], axis=0)[0]
    share = np.full(shape, np.nan)
    units_in, units_out = ("",) * model.n_inputs, ("",) * model.n_outputs
    if data is not None and set(model.output_names) <= set(data.output_names):
        share = _shares(model, data)
        units_in = tuple(data.input_units)
        units_out = tuple(data.output_units[data.output_names.index(n)] for n in model.output_names)
    return Coupling(
        model.input_names, model.output_names, units_in, units_out, steady, peak, frequencies[peak_at], share
    )


def _shares(model: StateSpaceModel, data: IOData) -> np.ndarray:
    """RMS of each output simulated from each input alone over the RMS of the output about its mean,
    over the stretches of ``data`` without missing samples (from rest at the start of each)."""
    signals = gather(data)
    columns = [signals.output_names.index(n) for n in model.output_names]
    own = np.zeros((model.n_outputs, model.n_inputs))
    total = np.zeros(model.n_outputs)
    for lo, hi in signals.segments:
        y = signals.y[lo:hi, columns]
        total += ((y - y.mean(axis=0)) ** 2).sum(axis=0)
        for j in range(model.n_inputs):
            alone = np.zeros((hi - lo, model.n_inputs))
            alone[:, j] = signals.u[lo:hi, j]
            with np.errstate(all="ignore"):
                own[:, j] += (model.simulate(alone) ** 2).sum(axis=0)
    with np.errstate(all="ignore"):
        return np.sqrt(own / total[:, None])
