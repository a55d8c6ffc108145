"""Discrete state-space models in innovation form: :class:`StateSpaceModel`.

The model is ``x(t+1) = A x(t) + B u(t) + K e(t)``, ``y(t) = C x(t) + D u(t) + e(t)`` with e the
innovation (white). :func:`arxid.ssest` estimates one; this module simulates it, predicts with it,
scores it and converts it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import field
from typing import Any

import numpy as np

from .._base import _core
from .._base.metrics import fit_percent
from .._base.optional import require
from .._base.records import record
from ..exceptions import DataError
from .mimo_data import Signals, gather

__all__ = ["StateSpaceModel", "Refinement"]


def _response(a, b, c, d, x0, u) -> tuple[np.ndarray, np.ndarray]:
    """Outputs and states of (a, b, c, d) from x0 driven by u, computed in the Rust core."""
    as_c = np.ascontiguousarray
    return _core.state_space_response(as_c(a), as_c(b), as_c(c), as_c(d), as_c(x0, dtype=float), as_c(u, dtype=float))


@record
class Refinement:
    """How the prediction-error refinement of a subspace estimate went.

    Attributes
    ----------
    start_loss, loss : float
        Mean squared one-step prediction error (over samples and outputs, in the outputs' units
        squared) of the subspace estimate and of the refined model, on the estimation data.
    iterations : int
        Accepted Levenberg–Marquardt steps.
    converged : bool
        Whether the search stopped at a minimum (otherwise at the iteration limit, or stalled).
    termination : str
        Why the search stopped, in words.
    """

    start_loss: float
    loss: float
    iterations: int
    converged: bool
    termination: str

    def __str__(self) -> str:
        drop = 100.0 * (1.0 - self.loss / self.start_loss) if self.start_loss > 0 else 0.0
        return (
            f"prediction-error refinement: mean squared one-step error {self.start_loss:.4g} -> {self.loss:.4g} "
            f"({drop:.1f} % lower) in {self.iterations} step(s); {self.termination}"
        )


@record
class StateSpaceModel:
    """A discrete-time state-space model of several inputs and outputs, in innovation form.

    Attributes
    ----------
    a, b, c, d : ndarray of shapes (n, n), (n, n_inputs), (n_outputs, n), (n_outputs, n_inputs)
        The model matrices.
    k : ndarray of shape (n, n_outputs)
        Kalman gain of the innovation form (the one-step predictor's gain).
    initial_states : ndarray of shape (n_segments, n)
        The initial state estimated for each stretch of the estimation data (one per experiment,
        more when missing samples split one).
    ts : float
        Sampling time in seconds.
    input_names, output_names : tuple of str
    method : str
        ``"n4sid"``, ``"moesp"`` or ``"cva"``.
    singular_values : ndarray
        Singular values of the method's weighted projection, largest first (what the order sees).
    canonical_correlations : ndarray
        Canonical correlations between future outputs and past data (between 0 and 1), on which
        the order is chosen.
    order_criterion : ndarray
        The singular value criterion for orders 0, 1, ...; the chosen order is its minimum when
        the order was not fixed.
    horizon : (int, int)
        Past and future horizons (samples) of the block-Hankel data.
    order_fixed : bool
        Whether the caller fixed the order.
    refinement : Refinement or None
        How the prediction-error refinement went (``ssest(..., refine=True)``); None when the
        model is the subspace estimate itself.

    Notes
    -----
    ``x(t+1) = A x(t) + B u(t) + K e(t)``, ``y(t) = C x(t) + D u(t) + e(t)``.
    """

    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    d: np.ndarray
    k: np.ndarray
    initial_states: np.ndarray
    ts: float
    input_names: tuple[str, ...]
    output_names: tuple[str, ...]
    method: str = "n4sid"
    singular_values: np.ndarray = field(default_factory=lambda: np.zeros(0))
    canonical_correlations: np.ndarray = field(default_factory=lambda: np.zeros(0))
    order_criterion: np.ndarray = field(default_factory=lambda: np.zeros(0))
    horizon: tuple[int, int] = (0, 0)
    order_fixed: bool = False
    refinement: Refinement | None = None

    # ------------------------------------------------------------------ shape
    @property
    def order(self) -> int:
        """Number of states n."""
        return int(self.a.shape[0])

    @property
    def n_inputs(self) -> int:
        """Number of inputs."""
        return int(self.b.shape[1])

    @property
    def n_outputs(self) -> int:
        """Number of outputs."""
        return int(self.c.shape[0])

    @property
    def x0(self) -> np.ndarray:
        """The initial state of the first stretch of the estimation data, shape (n,)."""
        return self.initial_states[0] if len(self.initial_states) else np.zeros(self.order)

    @property
    def poles(self) -> np.ndarray:
        """Eigenvalues of A (discrete-time poles)."""
        return np.linalg.eigvals(self.a)

    @property
    def is_stable(self) -> bool:
        """Whether every pole lies strictly inside the unit circle."""
        return bool(np.all(np.abs(self.poles) < 1.0))

    # ------------------------------------------------------------------ time responses
    def _inputs(self, u: Any) -> np.ndarray:
        arr = np.array(u, dtype=float, ndmin=1)  # a copy: the caller's array is never touched
        if arr.ndim == 1:
            arr = arr[:, None]
        if arr.ndim != 2 or arr.shape[1] != self.n_inputs:
            raise DataError(f"u must have shape (n_samples, {self.n_inputs}), got {np.shape(u)}")
        return arr

    def simulate(self, u: Any, x0: Any = None) -> np.ndarray:
        """Free-run simulation (no measured output used).

        Parameters
        ----------
        u : array_like of shape (n_samples, n_inputs)
            Inputs.
        x0 : array_like of shape (n,), optional
            Initial state; default zero.

        Returns
        -------
        ndarray of shape (n_samples, n_outputs)
            Simulated outputs; NaN from where the simulation diverged.
        """
        u = self._inputs(u)
        x0 = np.zeros(self.order) if x0 is None else np.asarray(x0, dtype=float).reshape(-1)
        if x0.shape != (self.order,):
            raise DataError(f"x0 must have {self.order} entries, got {x0.size}")
        return _response(self.a, self.b, self.c, self.d, x0, u)[0]

    def _predictor(self, u: np.ndarray, y: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One-step predictions ŷ(t|t−1) and predictor states x̂(t|t−1) of one stretch."""
        a = self.a - self.k @ self.c
        b = np.hstack([self.b - self.k @ self.d, self.k])
        d = np.hstack([self.d, np.zeros((self.n_outputs, self.n_outputs))])
        return _response(a, b, self.c, d, x0, np.hstack([u, y]))

    def _stretch_prediction(self, u: np.ndarray, y: np.ndarray, x0: np.ndarray, k: float) -> np.ndarray:
        if np.isinf(k):
            return _response(self.a, self.b, self.c, self.d, x0, u)[0]
        one_step, x_pred = self._predictor(u, y, x0)
        steps = int(k)
        if steps == 1:
            return one_step
        # x̂(t|t−k) = A^{k−1} (x̂(t−k+1|t−k) − s(t−k+1)) + s(t), s the simulated state from x0.
        sim, s = _response(self.a, self.b, self.c, self.d, x0, u)
        power = np.linalg.matrix_power(self.a, steps - 1)
        x = s.copy()
        x[steps - 1 :] += (x_pred[: len(u) - steps + 1] - s[: len(u) - steps + 1]) @ power.T
        out = x @ self.c.T + u @ self.d.T
        out[: steps - 1] = sim[: steps - 1]
        return out

    def predict(self, data: Any, k: float = 1, initial: str = "estimate") -> np.ndarray:
        """k-step-ahead prediction ŷ(t | t−k) on measured data (``k=inf``: free-run simulation).

        Parameters
        ----------
        data : IOData or sequence of IOData
            Data with this model's inputs and outputs (one IOData per output, as for
            :func:`arxid.ssest`).
        k : int or inf
            Prediction horizon in samples, >= 1.
        initial : {"estimate", "zero"}
            Initial state of each stretch: estimated by least squares on these data, or zero.

        Returns
        -------
        ndarray of shape (n_samples, n_outputs)
            Predictions; NaN where a sample is missing.
        """
        if not (np.isinf(k) or (float(k) == int(k) and k >= 1)):
            raise DataError(f"the prediction horizon k must be a whole number of samples >= 1 or inf, got {k!r}")
        signals = gather(data)
        self._check_signals(signals.u.shape[1], signals.y.shape[1])
        if signals.output_names != self.output_names and set(signals.output_names) == set(self.output_names):
            raise DataError(  # the columns are read in order: the same names shuffled would be misread
                f"the data's outputs {list(signals.output_names)} are in another order than the model's "
                f"{list(self.output_names)}; pass them in the model's order (arxid.compare matches them by name)"
            )
        if initial not in ("estimate", "zero"):
            raise DataError(f'initial must be "estimate" or "zero", got {initial!r}')
        x0s = self._initial_states(signals) if initial == "estimate" else np.zeros((len(signals.segments), self.order))
        out = np.full(signals.y.shape, np.nan)
        for (lo, hi), x0 in zip(signals.segments, x0s, strict=True):
            out[lo:hi] = self._stretch_prediction(signals.u[lo:hi], signals.y[lo:hi], x0, k)
        return out

    def _initial_states(self, signals: Signals) -> np.ndarray:
        """Least-squares initial state of each stretch of ``signals``, A, B, C and D held fixed.

        The first samples decide it (``C Aᵗ`` decays); at most 5,000 per stretch are used.
        """
        n = self.order
        out = np.zeros((len(signals.segments), n))
        zero = np.zeros(n)
        for i, (lo, hi) in enumerate(signals.segments):
            hi = min(hi, lo + 5000)
            forced = self.simulate(signals.u[lo:hi], zero)
            regressor = np.empty((hi - lo, self.n_outputs, n))
            power = np.eye(n)
            for t in range(hi - lo):
                regressor[t] = self.c @ power
                power = self.a @ power
                if t > 4 * n and not np.abs(power).max() > 1e-14:
                    regressor[t + 1 :] = 0.0
                    break
            target = signals.y[lo:hi] - forced
            out[i] = np.linalg.lstsq(regressor.reshape(-1, n), target.reshape(-1), rcond=None)[0]
        return out

    def _check_signals(self, n_inputs: int, n_outputs: int) -> None:
        if (n_inputs, n_outputs) != (self.n_inputs, self.n_outputs):
            raise DataError(
                f"the data have {n_inputs} input(s) and {n_outputs} output(s); this model has "
                f"{self.n_inputs} and {self.n_outputs}"
            )

    def fit_percent(self, data: Any, k: float = np.inf, initial: str = "estimate") -> np.ndarray:
        """Fit in percent of each output (NRMSE, 100 is perfect), free run by default.

        Parameters
        ----------
        data : IOData or sequence of IOData
            Validation data.
        k : int or inf
            Prediction horizon (inf: simulation, as MATLAB ``compare``).
        initial : {"estimate", "zero"}
            Initial state of each stretch.

        Returns
        -------
        ndarray of shape (n_outputs,)
        """
        y = gather(data).y_with_gaps
        pred = self.predict(data, k=k, initial=initial)
        return np.array([fit_percent(y[:, i], pred[:, i]) for i in range(self.n_outputs)])

    # ------------------------------------------------------------------ conversion
    def to_control(self) -> Any:
        """The model as a python-control discrete ``StateSpace`` (deterministic part A, B, C, D).

        Returns
        -------
        control.StateSpace
            With ``dt = ts`` and the signal names.
        """
        control = require("control", "to_control")
        return control.ss(
            self.a, self.b, self.c, self.d, dt=self.ts, inputs=list(self.input_names), outputs=list(self.output_names)
        )

    def to_scipy(self) -> Any:
        """The model as a scipy discrete state-space system.

        Returns
        -------
        scipy.signal.StateSpace
            A, B, C, D with ``dt = ts``.
        """
        from scipy import signal

        return signal.StateSpace(self.a, self.b, self.c, self.d, dt=self.ts)

    def frequency_response(self, frequencies: Sequence[float] | np.ndarray) -> np.ndarray:
        """The frequency response G(e^{jωTs}) of the inputs to the outputs.

        Parameters
        ----------
        frequencies : array_like of shape (n_frequencies,)
            Frequencies in Hz (0 gives the steady-state gain).

        Returns
        -------
        ndarray of shape (n_frequencies, n_outputs, n_inputs)
            Complex gains.
        """
        z = np.exp(2j * np.pi * np.asarray(frequencies, dtype=float) * self.ts)
        eye = np.eye(self.order)
        return np.array([self.c @ np.linalg.solve(zi * eye - self.a, self.b) + self.d for zi in z])

    def __str__(self) -> str:
        chosen = "fixed by the caller" if self.order_fixed else "chosen by the singular value criterion"
        radius = float(np.max(np.abs(self.poles))) if self.order else 0.0
        lines = [
            f"State-space model ({self.method.upper()}): {self.order} states ({chosen}), "
            f"{self.n_inputs} input(s) -> {self.n_outputs} output(s), Ts = {self.ts:g} s",
            f"  inputs:  {', '.join(self.input_names)}",
            f"  outputs: {', '.join(self.output_names)}",
            f"  largest pole magnitude {radius:.4f} ({'stable' if radius < 1 else 'UNSTABLE'})",
        ]
        if self.canonical_correlations.size:
            shown = ", ".join(f"{v:.3f}" for v in self.canonical_correlations[: self.order + 3])
            lines.append(
                f"  canonical correlations (first {min(self.order + 3, self.canonical_correlations.size)}): {shown}"
            )
        if self.refinement is not None:
            lines.append(f"  {self.refinement}")
        return "\n".join(lines)
