"""One output of a state-space model as the missing-effect diagnosis sees it: the model with a
candidate term as one more input, its score test and its refit.

With A, C (and K) of the fitted model held, the simulated outputs are linear in B, D and the
initial states: output p is ``ŷ_p(t) = Σ_j (c_p (qI − A)⁻¹ b_j) u_j(t) + d_p u(t) + c_p Aᵗ x0``.
A candidate term z(t) (``u1*vbat``, ``u1^2``, ``const``, ``y^3`` on the simulated output) entering as
one more input adds the columns ``c_p (qI − A)⁻¹ e_i z`` (one per state i: its own B column) and z
itself (its D entry). The columns of u_j are the states of the transposed system
``w(t+1) = Aᵀ w(t) + c_pᵀ u_j(t)`` from rest, so every regressor is one state-space response in the
Rust core. The score test regresses output p's simulation error on the candidate's columns beside
the model's own (B, D, x0 for that output), both whitened by an AR model of the error
(:func:`~arxid.diagnosis.polynomial.whitened_test`, the polynomial diagnosis's test).

The refit that the judge validates is :func:`arxid.ssest` again, at the model's order, method and
horizons, with the term as one more input. Holding A and C there (only B, D and x0 re-estimated)
would be exact and cheaper, but a missing effect biases the A and C it was estimated with (the
subspace sees the effect as a disturbance), and the held modes then hide part of what the term
buys: on a 2×2 plant whose battery voltage scales one input's gain into one output (inputs about an
operating point), that output's validation error fell from 0.117 to 0.059 with A and C held, and to
0.020, the noise level, with ``ssest`` again. The score test keeps A and C (a Lagrange-multiplier
test at the fitted model), and the validated error on separate data decides, as for every model.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import ClassVar

import numpy as np

from .._base import _core, metrics
from ..checks.state_space import state_space_label
from ..data.iodata import IOData
from ..exceptions import DataError
from ..models.derived_inputs import uses_output
from ..models.effects import effect_series
from ..models.mimo_data import gather
from ..models.state_space import StateSpaceModel
from ..models.subspace import ssest
from .added_variable import AddedVariableResult
from .polynomial import WhitenedTest, appended_inputs

__all__ = ["StateSpaceOutput", "OutputRegressors"]


@dataclass(frozen=True, eq=False)
class StateSpaceOutput:
    """One output of a state-space model, with the effects it was refitted with.

    A diagnosis of a :class:`~arxid.StateSpaceModel` judges each output through this view, and
    ``diagnosis.apply(k)`` returns one: ``model`` is the state-space model refitted with the
    suspect's effects as its last inputs, and :meth:`predict` computes them from measured data.

    Attributes
    ----------
    model : StateSpaceModel
        The model; its last ``len(effects)`` inputs are the effects.
    output : str
        The output judged.
    effects : tuple of str
        Effect terms appended as inputs (``u1*vbat``, ``y^3``); empty for the diagnosed model.
    source : StateSpaceModel or None
        The diagnosed model, whose simulated output stands for the output in terms of the output
        (``y^3``); None for the diagnosed model itself.
    """

    model: StateSpaceModel
    output: str
    effects: tuple[str, ...] = ()
    source: StateSpaceModel | None = None
    # The orders a diagnosis reads of an ARX model: a state-space model's structure is its order.
    na_: ClassVar[int] = 0
    nb_: ClassVar[tuple[int, ...]] = ()
    nk_: ClassVar[tuple[int, ...]] = ()

    @property
    def diagnosed(self) -> StateSpaceModel:
        """The model the diagnosis started from (without the effects)."""
        return self.source if self.source is not None else self.model

    @property
    def index(self) -> int:
        """Column of :attr:`output` among the model's outputs."""
        return self.model.output_names.index(self.output)

    @property
    def n_params(self) -> int:
        """Entries of B and D (what a refit estimates besides the initial states)."""
        return int(self.model.b.size + self.model.d.size)

    @property
    def is_stable(self) -> bool:
        """Whether every pole lies strictly inside the unit circle."""
        return self.model.is_stable

    def discrete_poles(self) -> np.ndarray:
        """The eigenvalues of A."""
        return self.model.poles

    def structure_name(self) -> str:
        """e.g. ``state-space model (N4SID, 4 states), output q + u1*vbat``."""
        added = "".join(f" + {e}" for e in self.effects)
        return f"state-space model ({state_space_label(self.model)}), output {self.output}{added}"

    def inputs(self, data: IOData) -> IOData:
        """``data`` (all of the model's outputs) with the effects appended as inputs.

        Parameters
        ----------
        data : IOData
            The measured inputs and every output of the model, in its order.

        Returns
        -------
        IOData
        """
        if not self.effects:
            return data
        return appended_inputs(data, self.effects, effect_columns(self.diagnosed, data, self.output, self.effects))

    def predict(self, data: IOData, horizon: int | None = None, initial: str = "zero") -> np.ndarray:
        """The output predicted on measured data (its effects computed from them).

        Parameters
        ----------
        data : IOData
            The measured inputs and every output of the model, in its order.
        horizon : int or None
            None: free run; k: k-step-ahead prediction.
        initial : {"zero", "estimate"}
            Initial state of each stretch.

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        with np.errstate(all="ignore"):
            pred = self.model.predict(self.inputs(data), k=np.inf if horizon is None else horizon, initial=initial)
        return pred[:, self.index]

    def extended(self, data: IOData, effects: Sequence[str]) -> StateSpaceOutput:
        """The diagnosed model estimated again on ``data`` with this view's effects and ``effects``
        as extra inputs: :func:`arxid.ssest` at its order, method and horizons (refined when it was,
        stable when it is).

        Parameters
        ----------
        data : IOData
            Estimation data: the measured inputs and every output, in the model's order.
        effects : sequence of str

        Returns
        -------
        StateSpaceOutput
        """
        base = self.diagnosed
        view = StateSpaceOutput(base, self.output, tuple(dict.fromkeys((*self.effects, *effects))), base)
        fitted = ssest(
            view.inputs(data),
            base.order,
            method=base.method,
            horizon=base.horizon,
            stable=base.is_stable,  # a stable model stays stable with the term (as ssest(stable=True) made it)
            refine=base.refinement is not None,
            n_threads=1,  # the judge refits two candidates at a time
        )
        return replace(view, model=fitted)

    def validation_rms(self, validation: IOData, horizon: int | None, initial: str) -> float:
        """RMS error of the output on ``validation`` at ``horizon`` (inf when the free run diverges).

        Parameters
        ----------
        validation : IOData
        horizon : int or None
        initial : {"zero", "estimate"}

        Returns
        -------
        float
        """
        return metrics.prediction_rms(validation.outputs[:, self.index], self.predict(validation, horizon, initial))


def effect_columns(model: StateSpaceModel, data: IOData, output: str, effects: Sequence[str]) -> np.ndarray:
    """The effects' signals on ``data``, shape (n_samples, len(effects)); a term of the output is
    computed on ``model``'s free-run simulation of it, one sample back (it acts inside the plant,
    before its dynamics).

    Parameters
    ----------
    model : StateSpaceModel
        The diagnosed model.
    data : IOData
        The measured inputs and every output of ``model``, in its order.
    output : str
    effects : sequence of str

    Returns
    -------
    ndarray
    """
    one = data.output(output)
    simulated: IOData | None = None
    cols = []
    for e in effects:
        if not uses_output(e, one):
            cols.append(effect_series(e, one))
            continue
        if simulated is None:
            with np.errstate(all="ignore"):
                y = model.predict(data, k=np.inf, initial="estimate")[:, model.output_names.index(output)]
            simulated = replace(one, y=y)
        z = effect_series(e, simulated)
        cols.append(np.concatenate([[np.nan], z[:-1]]))
    return np.column_stack(cols) if cols else np.zeros((data.n_samples, 0))


#: Largest state count of one batched response when the regressors of many columns are computed
#: at once (a block-diagonal system: the cost grows with its square).
BATCH_STATES = 64


class OutputRegressors:
    """The least-squares regressors of one output of a state-space model on estimation data, and
    the score test of effect terms beside them.

    Parameters
    ----------
    view : StateSpaceOutput
        The diagnosed model's output.
    data : IOData
        Estimation data: the measured inputs and every output, in the model's order.
    effects : sequence of str
        Every effect that will be tested: their columns are computed together.
    """

    def __init__(self, view: StateSpaceOutput, data: IOData, effects: Sequence[str] = ()):
        self.view, self.data = view, data
        model = view.model
        signals = gather(data)
        self.segments = [(lo, hi) for lo, hi in signals.segments if hi - lo > 2 * model.order + 2]
        if not self.segments:
            raise DataError("no stretch of the estimation data without missing samples is long enough to test")
        self.rows = np.concatenate([np.arange(lo, hi) for lo, hi in self.segments])
        with np.errstate(all="ignore"):
            predicted = model.predict(data, k=np.inf, initial="estimate")[:, view.index]
        error = (signals.y[:, view.index] - predicted)[self.rows]
        own = np.hstack([self.filtered(signals.u), signals.u[self.rows], self._initial_columns()])
        self.test_beside = WhitenedTest(own, error)
        self.n_own = own.shape[1]
        self.columns: dict[str, np.ndarray] = {}
        self._add(list(dict.fromkeys(effects)))

    def _add(self, effects: list[str]) -> None:
        """The columns of ``effects`` (B-columns, then the D-column), kept by effect. A sample where
        an effect has no value (its first difference, a term of the output) is set to zero."""
        if not effects:
            return
        z = effect_columns(self.view.model, self.data, self.view.output, effects)
        z = np.where(np.isfinite(z), z, 0.0)
        n = self.view.model.order
        step = max(1, BATCH_STATES // max(n, 1))
        for at in range(0, len(effects), step):
            part = z[:, at : at + step]
            b_columns = self.filtered(part)
            for j, e in enumerate(effects[at : at + step]):
                self.columns[e] = np.hstack([b_columns[:, j * n : (j + 1) * n], part[self.rows, j : j + 1]])

    def filtered(self, z: np.ndarray) -> np.ndarray:
        """The B-columns of inputs ``z`` (n_samples × m) on the tested rows: the states of
        ``w(t+1) = Aᵀ w(t) + c_pᵀ z(t)`` from rest in each stretch, shape (n_rows, n·m)."""
        model, n, m = self.view.model, self.view.model.order, z.shape[1]
        a = np.kron(np.eye(m), model.a.T)
        b = np.kron(np.eye(m), model.c[self.view.index][:, None])
        none_out, none_through = np.zeros((1, n * m)), np.zeros((1, m))
        parts = [
            _core.state_space_response(a, b, none_out, none_through, np.zeros(n * m), np.ascontiguousarray(z[lo:hi]))[1]
            for lo, hi in self.segments
        ]
        return np.vstack(parts)

    def _initial_columns(self) -> np.ndarray:
        """The x0-columns: c_p Aᵗ in its own stretch, zero elsewhere (one initial state per stretch)."""
        model, n = self.view.model, self.view.model.order
        at = np.ascontiguousarray(model.a.T)
        c_p = np.ascontiguousarray(model.c[self.view.index])
        out = np.zeros((len(self.rows), n * len(self.segments)))
        row = 0
        for i, (lo, hi) in enumerate(self.segments):
            still = np.zeros((hi - lo, 1))
            states = _core.state_space_response(at, np.zeros((n, 1)), np.zeros((1, n)), np.zeros((1, 1)), c_p, still)[1]
            out[row : row + hi - lo, i * n : (i + 1) * n] = states
            row += hi - lo
        return out

    def test(self, effects: Sequence[str]) -> tuple[AddedVariableResult | None, str]:
        """Score test of ``effects`` as extra inputs of this output (partial F-test, whitened).

        Parameters
        ----------
        effects : sequence of str

        Returns
        -------
        AddedVariableResult or None, str
            None and the reason when the candidate could not be tested.
        """
        self._add([e for e in dict.fromkeys(effects) if e not in self.columns])
        new = np.hstack([self.columns[e] for e in effects])
        if len(self.rows) <= self.n_own + new.shape[1] + 2:
            return None, "too few samples"
        return self.test_beside.test(new)
