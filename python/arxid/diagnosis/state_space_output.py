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

The refit that the judge validates holds A, C and K too, and re-estimates B, D and the initial
states of all outputs with the term as one more input (the least squares of :func:`arxid.ssest`,
in the Rust core). It nests the model (a subspace estimate, whose B, D and x0 are that least
squares): with the term's B column and D entry at zero it is the model, so a term that does not
act moves the validation error only by what fitting one more input costs. Estimating the model
again with the term (``ssest`` at the same order) does not nest it, and on closed-loop data a new
subspace estimate is a lottery: on the quadrotor's body rates (simulated flight, order 11, 10-step
error) a white-noise signal as the extra input raised q's validation error by 231 % and lowered
p's by 13 % with ``ssest`` again, and moved each by less than 1 % with A and C held. The price:
when the missing effect has biased the A and C the model was estimated with, the held modes
recover only part of what the term buys (a battery gain on one output of a 2×2 plant, inputs
about an operating point: that output's error falls from 0.117 to 0.059, where ``ssest`` again,
or a prediction-error refinement of the held refit judged against the model refined alike, reach
the noise level 0.020, at a refinement per candidate). The term is still named.
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
        """The diagnosed model refitted on ``data`` with this view's effects and ``effects`` as extra
        inputs: A, C and K held, B, D and the initial states re-estimated by least squares.

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
        signals = gather(view.inputs(data))
        segments = [(lo, hi) for lo, hi in signals.segments if hi - lo > 2 * base.order + 2]
        if not segments:
            raise DataError("no stretch of the data without missing samples is long enough to refit the model")
        as_c = np.ascontiguousarray
        b, d, x0 = _core.subspace_input_matrices(
            as_c(base.a), as_c(base.c), as_c(signals.u), as_c(signals.y), segments, feedthrough=True, initial_state=True
        )
        fitted = replace(base, b=b, d=d, initial_states=x0, input_names=signals.input_names, refinement=None)
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
    before its dynamics). Where the measured signals exist but the effect has no value yet (a first
    difference, or the term of the output, at the start of a record) it is zero, as if from rest:
    a missing sample there would start the record one sample later, from another state.

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
    if not cols:
        return np.zeros((data.n_samples, 0))
    z = np.column_stack(cols)
    measured = np.isfinite(np.column_stack([data.outputs, data.u, *data.extra.values()])).all(axis=1)
    z[measured[:, None] & ~np.isfinite(z)] = 0.0
    return z


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
