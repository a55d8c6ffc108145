"""Instrumental variables for a structure with effects: the refits of a closed-loop diagnosis.

:func:`iv_with_effects` fits ``A(q) y = B(q) u + Σ effect terms`` from the normal equations of the
instruments, ``Σ z(t) φ(t)ᵀ θ = Σ z(t) y(t)``. ``φ(t)`` is the regressor on the measured data;
``z(t)`` is the same regressor built on the noise-free signals of :func:`arxid.iv`'s closed-loop
instruments (the output and inputs projected on the references), so an effect of an input, of the
output or a product is instrumented by the same effect of their projections, and a logged signal
that is not in the loop (a battery voltage) instruments itself. The reference does not carry the
noise, so the refit stays consistent in closed loop, as the model it extends.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._base import metrics
from ..data.iodata import IOData
from ..exceptions import DataError, IdentifiabilityError
from .arx_solver import per_input
from .effects import compile_effects, effect_names
from .iv import IvModel, instrument_names, instrument_signals
from .regressors import regressor_matrix, regressor_names

__all__ = ["iv_with_effects"]


class _Solution:
    """What :meth:`ArxModel._store` reads of a solve."""

    def __init__(self, theta: np.ndarray, rss: float, n_rows: int, n_skipped: int, inv_gram: np.ndarray):
        self.theta, self.rss, self.n_rows, self.n_skipped, self.inv_gram = theta, rss, n_rows, n_skipped, inv_gram


def iv_with_effects(
    data: IOData,
    na: int,
    nb: Sequence[int],
    nk: Sequence[int],
    effects: Sequence[str],
    references: Sequence[str],
    first_lag: int = 0,
) -> IvModel:
    """Fit an ARX structure with effects by instrumental variables built from the references.

    Parameters
    ----------
    data : IOData
        Estimation data, the references among its extra signals.
    na : int
    nb, nk : sequence of int
        One per input.
    effects : sequence of str
        Effect terms (grammar of :mod:`arxid.effects`, thresholds written out).
    references : sequence of str
        The logged references (at least one).
    first_lag : int
        Start the rows this far into each experiment.

    Returns
    -------
    IvModel
        Fitted, with its effects; its covariance is the IV one, ``σ² (ZᵀΦ)⁻¹ ZᵀZ (ΦᵀZ)⁻¹``.

    Raises
    ------
    DataError
        When a reference is not logged, or no row is usable.
    IdentifiabilityError
        When the instruments do not determine every parameter.

    Examples
    --------
    >>> import arxid
    >>> from arxid.datasets import pid_rate_loop
    >>> from arxid.models.iv_effects import iv_with_effects
    >>> d = pid_rate_loop(seed=0, n_samples=6000)
    >>> m = iv_with_effects(d, 2, [1], [3], ["const"], ["rate_sp"])
    >>> m.structure_name(), m.effects
    ('IV(2,1,3) + const', ('const',))
    """
    names = instrument_names(data, list(references))
    if not names:
        raise DataError("iv_with_effects needs at least one reference among the extra signals")
    nb_, nk_ = per_input("nb", nb, data.n_inputs), per_input("nk", nk, data.n_inputs)
    xy, xu = instrument_signals(data, names)
    clean = IOData(
        xy,
        xu,
        data.ts,
        output_name=data.output_name,
        input_names=data.input_names,
        extra=dict(data.extra),
        experiment_starts=data.experiment_starts,
    )
    layout = compile_effects(tuple(effects), data, nb_, nk_)
    phi, y, rows = regressor_matrix(data, na, layout, first_lag)
    z, _, z_rows = regressor_matrix(clean, na, compile_effects(tuple(effects), clean, nb_, nk_), first_lag)
    keep = np.isin(z_rows, rows)
    z = z[keep]
    if not np.array_equal(z_rows[keep], rows) or phi.shape[0] <= phi.shape[1]:
        raise DataError("too few rows where the data and their instruments are both present for this structure")
    theta, inv_gram = _solve(z, phi, y)
    model = IvModel(na=na, nb=list(nb_), nk=list(nk_), instruments=list(names), iterations=0)
    model.effects = effect_names(effects)
    residual = y - phi @ theta
    usable = sum(max(0, b - a - max(first_lag, 0)) for a, b in data.segments)
    rss = metrics.mean_square(residual) * residual.size
    res = _Solution(theta, rss, phi.shape[0], max(0, usable - phi.shape[0]), inv_gram)
    names_ = regressor_names(data.output_name, na, layout)
    model._store(data, (na, nb_, nk_), layout, names_, first_lag, res)
    return model


def _solve(z: np.ndarray, phi: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """θ from ``ZᵀΦ θ = Zᵀy`` (QR of the small matrix), and the IV "inverse Gram" of the covariance."""
    m = z.T @ phi
    q, r = np.linalg.qr(m)
    d = np.abs(np.diag(r))
    if d.size and d.min() <= 1e-10 * d.max():
        raise IdentifiabilityError(
            "the instruments do not determine every parameter of this structure with its effects; lower the orders "
            "or use a reference that moves more"
        )
    theta = np.linalg.solve(r, q.T @ (z.T @ y))
    m_inv = np.linalg.inv(m)
    return theta, m_inv @ (z.T @ z) @ m_inv.T
