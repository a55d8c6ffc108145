"""The one-step error of a model whose input acts through a shape, for many values of the shape's
parameters: what a scan of a dead zone's width or a saturation's levels minimises.

Each value is the residual sum of squares of the model refitted with the input replaced by f(u),
and only the input's own lag columns change between values. So the other columns (the output lags,
the other inputs, the effects, the offset) are reduced once to an orthonormal basis Q, and a value
costs the projection of the shaped lags, Z − Q(QᵀZ), and the R factor of them beside the projected
output (QR of a few columns; its last diagonal entry is the residual's norm): the refit's loss to
rounding, without a refit (a few hundred of those were most of a short diagnosis). The core gathers
the lags from the shaped series, and a scan's grid of values is one call (:meth:`ShapeCost.many`).

A value the refit would refuse is refused alike: a shaped lag that depends on the other columns
(a dead zone wider than the input, a saturation that leaves a constant) is rank deficient by the
core's own rule, and a shaped input that leaves the float range is a data error; both cost +inf.
Where the shortcut cannot stand for the refit (its first value disagrees with the refit, or the
other columns are themselves dependent), every value is refitted.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .._base.orthonormal import Projector, orthonormal_basis, projected_r
from ..data.iodata import IOData
from ..exceptions import ArxidError, OrderError
from ..models.arx_model import ArxModel
from ..models.arx_solver import checked_solution
from ..models.effects import EffectLayout, compile_effects, format_threshold
from ..models.input_shapes import InputShape, check_params, shape_values
from ..models.regressors import regressor_columns, regressor_matrix
from .candidates import candidate_input_names

__all__ = ["ShapeCost", "input_lags", "orthonormal_basis", "projected_r", "projected_rss"]

#: The shortcut's loss must match the refit's to this relative difference at the first value.
_AGREEMENT = 1e-9


class ShapeCost:
    """``cost(params)``: the one-step residual sum of squares of ``model`` refitted on ``data`` with
    the input ``signal`` replaced by the shape ``kind`` at ``params`` (+inf where the refit fails).

    Parameters
    ----------
    model : ArxModel
        The fitted model (its orders, effects and first lag).
    data : IOData
        Estimation data.
    kind, signal : str
        The shape family (one with parameters: a power, a saturation, a dead zone) and the input
        it replaces.
    const : bool
        Refit with an offset.
    shared : dict, optional
        The scans of one model on one record, each family in turn, share their projection here: the
        other columns, their basis and the projected output do not depend on the family (only the
        shaped input's lags do).
    """

    def __init__(self, model: ArxModel, data: IOData, kind: str, signal: str, const: bool, shared: dict | None = None):
        self.model, self.data, self.kind, self.signal, self.const = model, data, kind, signal, const
        self.shared = shared
        self.column = candidate_input_names(data).index(signal)
        self._fast: _Projection | None = None
        self._checked = False

    def __call__(self, params: tuple[float, ...]) -> float:
        values = tuple(float(v) for v in params)
        if self._fast is not None:  # a scan's every value but the first: no shape built unless new
            return self._fast.rss(values)
        shape = InputShape(self.kind, self.signal, values)
        if not self._checked:  # the first value: refitted, and the shortcut set up against it
            self._checked = True
            exact = self.refit(shape)
            if math.isfinite(exact):
                fast = _Projection.build(self, shape)
                if fast is not None and abs(fast.rss(values) - exact) <= _AGREEMENT * exact:
                    self._fast = fast
            return exact
        return self.refit(shape)

    def many(self, values: Sequence[tuple[float, ...]]) -> list[float]:
        """``[cost(v) for v in values]``, the values after the first projected in one call of the core."""
        values = [tuple(float(v) for v in params) for params in values]
        head = [self(values[0])] if values and not self._checked else []
        if self._fast is None:
            return head + [self(v) for v in values[len(head) :]]
        return head + self._fast.rss_many(values[len(head) :])

    def effects(self, shape: InputShape) -> list[str]:
        return [*self.model.effects, shape.effect] + (["const"] if self.const else [])

    def refit(self, shape: InputShape) -> float:
        """The loss of the refit itself."""
        m, data = self.model, self.data
        try:  # ArxModel.fit's checks and solve, without the fitted model's state (only its loss is read)
            fitted = ArxModel(na=m.na_, nb=m.nb_, nk=m.nk_, effects=self.effects(shape))
            return float(checked_solution(fitted, data, m.first_lag_, 0)[3].rss)
        except ArxidError:
            return math.inf


class _Projection:
    """The other columns' basis and the projected output, fixed across the shape's values; the
    shaped lags are read from the shaped series at fixed sample indices."""

    def __init__(self, cost: ShapeCost, index: np.ndarray, q: np.ndarray, y_perp: np.ndarray):
        self.cost, self.projector = cost, Projector(q, y_perp)
        self.index = np.ascontiguousarray(index, dtype=np.int64)
        x = np.asarray(cost.data.signal(cost.signal), dtype=float)
        self.signal = x
        # a power of a negative input raises, as the refit's evaluation raises (one check, not one a value)
        self.checked = cost.kind != "power" or not np.nanmin(x, initial=0.0) < 0
        odd = cost.kind in ("signed power", "dead zone")  # |x| and sign(x), the same at every value
        self.magnitude: np.ndarray | None = np.abs(x) if odd else None
        self.sign: np.ndarray | None = np.sign(x) if odd else None
        self._known: dict[tuple[str, ...], float] = {}

    @classmethod
    def build(cls, cost: ShapeCost, shape: InputShape) -> _Projection | None:
        """The projection of ``cost``'s first value ``shape``, whose refit succeeded (the effects
        compile); another family's of the same model, record, input and offset when shared."""
        key = (cost.signal, cost.const)
        if cost.shared is not None and key in cost.shared:
            return cls(cost, *cost.shared[key])
        m, data = cost.model, cost.data
        try:
            layout = compile_effects(cost.effects(shape), data, m.nb_, m.nk_)
        except ArxidError:
            return None
        phi, y, rows = regressor_matrix(data, m.na_, layout, m.first_lag_)
        which, index, plain = input_lags(data, m.na_, layout, cost.column, phi, rows)
        if which.size == 0 or not plain.all():
            return None  # a column not a plain lag of the shaped series: the refit decides
        basis = orthonormal_basis(np.delete(phi, which, axis=1))
        if basis is None:
            return None  # dependent columns besides the shape: the refit decides
        y_perp = y - basis @ (basis.T @ y)
        if cost.shared is not None:
            cost.shared[key] = (index, basis, y_perp)
        return cls(cost, index, basis, y_perp)

    def rss(self, values: tuple[float, ...]) -> float:
        return self.rss_many([values])[0]

    def rss_many(self, values: Sequence[tuple[float, ...]]) -> list[float]:
        """The loss at each of ``values``; the shaped series of the new ones projected in one call of
        the core (each value's numbers as alone)."""
        # The refit reads the effect's text, four digits a value: values with the same digits are
        # the same shape (a local search's late steps), and a new text is read once.
        digits = [tuple(map(format_threshold, params)) for params in values]
        new = {d: params for d, params in zip(digits, values) if d not in self._known}
        if new:
            self._shaped(new)
        return [self._known[d] for d in digits]

    def _shaped(self, new: dict[tuple[str, ...], tuple[float, ...]]) -> None:
        """The losses of new values (by their digits), the shaped series written side by side."""
        series = np.empty((len(new), self.signal.size))
        shaped = []
        with np.errstate(over="ignore", invalid="ignore"):
            for d in new:
                read = self._read(d)
                if read is None:
                    self._known[d] = math.inf
                    continue
                shaped.append(d)
                shape_values(self.cost.kind, read, self.signal, series[len(shaped) - 1], self.magnitude, self.sign)
        series = series[: len(shaped)]
        infinite = np.isinf(series)  # beyond the float range: a data error to the refit
        if infinite.any():
            beyond = np.asarray(infinite.any(axis=1))
            self._known.update((d, math.inf) for d, out in zip(shaped, beyond.tolist()) if out)
            shaped, series = [d for d, out in zip(shaped, beyond.tolist()) if not out], series[~beyond]
        if not shaped:
            return
        losses = self.projector.shaped_rss(series, self.index)
        for d, loss in zip(shaped, losses):  # None: a lag the shape leaves undefined, refitted
            self._known[d] = (
                self.cost.refit(InputShape(self.cost.kind, self.cost.signal, new[d])) if loss is None else loss
            )

    def _read(self, digits: tuple[str, ...]) -> tuple[float, ...] | None:
        """The parameters the refit reads from the effect's text (its digits), None where it refuses
        them (a number the grammar cannot write, a parameter out of range)."""
        read = tuple(map(float, digits))
        if not all(math.isfinite(v) for v in read):  # "inf", "nan": not a number of the grammar
            return None
        try:
            check_params(self.cost.kind, read, "")
        except OrderError:
            return None
        if not self.checked:  # raises as the refit's evaluation raises
            InputShape(self.cost.kind, self.cost.signal, read).evaluate(self.signal)
        return read


def input_lags(
    data: IOData, na: int, layout: EffectLayout, column: int, phi: np.ndarray, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The columns of ``phi`` that move with input ``column``, per row and column the sample each
    reads, and whether each is a plain lag of the input (not a product or power of it).

    The input's columns are those that move when its series does: found by writing the sample
    numbers in as the series."""
    half = 0.5 * data.n_samples
    numbered = layout.u.copy()
    numbered[:, column] = np.arange(data.n_samples) + half  # distinct from every value
    moved = regressor_columns(data, na, replace(layout, u=numbered), rows, range(phi.shape[1]))
    which = np.array([j for j in range(phi.shape[1]) if (moved[:, j] != phi[:, j]).any()], dtype=np.intp)
    index = np.zeros((rows.size, which.size), dtype=np.intp)
    plain = np.zeros(which.size, dtype=bool)
    for c, j in enumerate(which):  # a column at a time: a few row-long temporaries, not a matrix of them
        read = moved[:, j] - half
        if ((read >= 0) & (read < data.n_samples) & (read == np.round(read))).all():
            index[:, c] = read
            plain[c] = np.array_equal(layout.u[index[:, c], column], phi[:, j])
    return which, index, plain


def projected_rss(basis: np.ndarray, y_perp: np.ndarray, z: np.ndarray) -> float:
    """The residual sum of squares of ``y`` on the basis's columns and ``z`` (``y_perp`` is y less
    its projection on the basis); +inf when a column of ``z`` depends on the basis or on those
    before it."""
    return Projector(basis, y_perp).rss(z)
