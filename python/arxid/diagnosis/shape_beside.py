"""The encompassing test of a shape: the model refitted with the shaped input's lags (and an offset)
*beside* its own columns, for every shape of a diagnosis.

Each such refit is the model's regressor with a few more columns. So the model's columns are reduced
once to an orthonormal basis Q (on a long record, from the fit's own factor: no fresh QR), with the
output's residual y⊥ (the model's own), and a shape costs the projection of its few columns,
Z − Q(QᵀZ), and a small QR beside y⊥ (:func:`projected_r`): the refit's residual sum of squares to
rounding, without a pass of the core over all the rows (twenty of those were a third of a diagnosis
at 4M samples). A shape's columns are its series at the input's lags: row t of lag k reads sample
t − k.

Where the shape models are fitted from one factor of their envelope that also holds the model
(:class:`arxid.diagnosis.shapes.ShapeFits`, data without gaps), the model with a shape beside it
is one more sub-structure of that envelope (:func:`beside_from_factor`): a small QR of a few
columns of its R, and no basis at all (at 4M samples the basis and the shapes' projections were
two seconds of each diagnosis). The shape is then the one its effect writes (parameters to four
significant digits), as in the validation test and the judge's refit, where the basis reads a
scanned parameter to all its digits.

A shape the refit would refuse is refused alike (a shaped lag the model's columns already span is
rank deficient by the core's rule). Where the shortcut cannot stand for the refit (the basis does
not give the model's own loss, the model's columns are dependent, or a shaped lag is missing on a
row the refit keeps), the shape is refitted.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .._base import _core
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.effects import compile_effects
from ..models.envelope import EnvelopeFactor
from ..models.input_shapes import InputShape
from ..models.regressors import lagger, regressor_matrix
from .candidates import candidate_input_names
from .shape_cost import orthonormal_basis, projected_r

__all__ = ["BesideFit", "Beside", "beside_from_factor"]

#: The basis must give the model's own loss to this relative difference.
_AGREEMENT = 1e-9


class Beside(NamedTuple):
    """The loss of the model with a shape beside it, on its regression rows."""

    rss: float
    n_rows: int
    n_params: int


class BesideFit:
    """``fit(shape, const)``: the model with ``shape``'s lags (those of its input) and, with
    ``const``, an offset beside its own columns, fitted on ``data`` (raises as the refit raises).

    Parameters
    ----------
    model : ArxModel
        The fitted model.
    data : IOData
        Its estimation data.
    """

    def __init__(self, model: ArxModel, data: IOData):
        self.model, self.data = model, data
        self.names = candidate_input_names(data)
        self._basis: tuple[np.ndarray, np.ndarray] | None = None
        self._lags: dict[int, tuple[int, ...] | None] = {}
        self._rows = np.zeros(0, dtype=np.intp)
        self._factors: dict[str, tuple[np.ndarray, np.ndarray] | None] = {}
        self._built = False

    def __call__(self, shape: InputShape, const: bool) -> Beside:
        lags = self._input_lags(self.names.index(shape.signal))
        if lags is None or self._basis is None:
            return self.refit(shape, const)
        if shape.effect not in self._factors:
            self._factors[shape.effect] = self._factor(shape, lags)
        factor = self._factors[shape.effect]
        if factor is None:  # a row the refit leaves out, or a data error: the refit says
            return self.refit(shape, const)
        r, dependent = factor
        k, offset = len(lags), "const" not in self.model.effects
        if dependent[:k].any() or (const and (not offset or dependent[k])):
            raise ArxidError(f"the columns of {shape.effect} beside the model's are rank deficient")
        if offset and not const:  # the offset's column left out: R of the others (exact, by rotations)
            r = np.asarray(np.linalg.qr(np.delete(r, k, axis=1), mode="r"))
        n_rows, n_params = self._basis[0].shape
        return Beside(float(r[-1, -1] ** 2), n_rows, n_params + k + int(const))

    def _factor(self, shape: InputShape, lags: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray] | None:
        """R of the shape's lags (and, for a model without an offset, a column of ones) projected
        beside y⊥: one pass over the rows serves the shape with and without its offset."""
        other = self.data.signal(shape.other) if shape.other else None
        i = self.names.index(shape.signal)
        with np.errstate(over="ignore", invalid="ignore"):
            series = shape.evaluate(self.data.u[:, i], other)
        ones = "const" not in self.model.effects
        z = np.empty((self._rows.size, len(lags) + int(ones)), order="F")  # a column is one copy of a slice
        lagged = lagger(self._rows)
        for c, k in enumerate(lags):  # row t of a lag-k column reads sample t − k
            z[:, c] = lagged(series, k)
        del series
        if not np.isfinite(z[:, : len(lags)]).all():
            return None
        if ones:
            z[:, -1] = 1.0
        assert self._basis is not None
        return projected_r(*self._basis, z)

    def _input_lags(self, i: int) -> tuple[int, ...] | None:
        """The lags of input ``i``'s columns (None: refit every shape of it)."""
        if not self._built:
            self._built = True
            self._build()
        if self._basis is None:
            return None
        return self._lags.get(i)

    def _build(self) -> None:
        m, data = self.model, self.data
        layout = compile_effects(m.effects, data, m.nb_, m.nk_)
        phi, y, rows = regressor_matrix(data, m.na_, layout, m.first_lag_)
        if rows.size != m.n_rows_:
            return
        for i in range(data.n_inputs):  # an input the model feeds through a shape has no plain lags
            plain = m.nb_[i] > 0 and layout.effect_of_column[i] is None
            self._lags[i] = tuple(range(m.nk_[i], m.nk_[i] + m.nb_[i])) if plain else None
        # Q over phi (the rows held once), from the fit's own R where it has one
        basis = orthonormal_basis(phi, overwrite=True, r=_model_r(m, phi))
        del phi
        if basis is None:
            return
        y_perp = y - basis @ (basis.T @ y)
        if not abs(float(y_perp @ y_perp) - m.rss_) <= _AGREEMENT * m.rss_:
            return  # the basis does not stand for the model's fit
        self._basis, self._rows = (basis, y_perp), rows

    def refit(self, shape: InputShape, const: bool) -> Beside:
        """The refit itself: the shaped input as one more input with the input's own lags."""
        data, model = self.data, self.model
        i = self.names.index(shape.signal)
        other = data.signal(shape.other) if shape.other else None
        u = np.column_stack([data.u, shape.evaluate(data.u[:, i], other)])
        names, units = [*data.input_names, "shape_"], [*data.input_units, ""]
        extended = data.with_signals(u=u, input_names=names, input_units=units)
        nb, nk = (*model.nb_, model.nb_[i]), (*model.nk_, model.nk_[i])
        effects = [*model.effects] + (["const"] if const else [])
        fitted = ArxModel(na=model.na_, nb=nb, nk=nk, effects=effects).fit(extended, first_lag=model.first_lag_)
        return Beside(fitted.rss_, fitted.n_rows_, fitted.n_params)


def beside_from_factor(envelope: EnvelopeFactor, model: ArxModel, own: int, shaped: int) -> Beside | None:
    """The model (structure ``own`` of ``envelope``) with the columns of a shape model (structure
    ``shaped``: the shape at its input's lags, and an offset) beside its own, from the envelope's
    factor; None where the factor does not stand for the model's own fit (other rows, another loss).
    Raises as the refit raises on columns the model's already span.

    Parameters
    ----------
    envelope : EnvelopeFactor
    model : ArxModel
        The fitted model, structure ``own`` of the envelope.
    own, shaped : int
        Indices of the model and of the shape model among the envelope's structures.

    Returns
    -------
    Beside or None
    """
    if not (envelope.has(own) and envelope.has(shaped)) or envelope.n_rows != model.n_rows_:
        return None
    na = envelope.structures[own][0]
    (nb, nk), (nb_shape, nk_shape) = envelope.columns[own], envelope.columns[shaped]
    if not _stands_for(envelope, na, nb, nk, model):
        return None
    # the model's columns, and the shape model's where the model has none (the shape, the offset)
    both = [(b, k) if b > 0 else (b2, k2) for b, k, b2, k2 in zip(nb, nk, nb_shape, nk_shape, strict=True)]
    orders = (na, [b for b, _ in both], [k for _, k in both])
    out = _core.fit_from_factor(envelope.r, envelope.n_rows, envelope.envelope, orders, [])
    return Beside(float(out.rss), int(out.n_rows), int(np.asarray(out.theta).size))


def _stands_for(envelope: EnvelopeFactor, na: int, nb: list[int], nk: list[int], model: ArxModel) -> bool:
    """Whether the model's fit from the factor gives its own loss (to :data:`_AGREEMENT`)."""
    try:
        rss = float(_core.fit_from_factor(envelope.r, envelope.n_rows, envelope.envelope, (na, nb, nk), []).rss)
    except ArxidError:
        return False
    return abs(rss - model.rss_) <= _AGREEMENT * model.rss_


def _model_r(model: ArxModel, phi: np.ndarray) -> np.ndarray | None:
    """R with RᵀR = ΦᵀΦ from the model's own fit (its covariance over the noise variance is
    (ΦᵀΦ)⁻¹), None where that cannot serve: :func:`orthonormal_basis` then needs no fresh QR of
    Φ, and its second pass restores Q to the last bits (three passes over the rows, not four)."""
    n, p = phi.shape
    if not (model.rss_ > 0 and np.isfinite(model.covariance_).all()):
        return None
    try:
        return np.linalg.cholesky(np.linalg.inv(model.covariance_ * ((n - p) / model.rss_))).T
    except np.linalg.LinAlgError:
        return None
