"""Is something nonlinear still missing that no candidate explains? :func:`nonlinear_dependence`.

The missing-effect diagnosis only finds effects in its catalogue. When none explains the error, the
residual may still depend on a signal in a way no candidate removes (backlash, hysteresis, a
nonlinearity of an unusual shape). This test says so, and where.

For each signal (the output and each input) and each lag near the model's own, a block of nonlinear
functions of the standardised signal s = (x − mean) / std at that lag — s², s³, |s| and sign(s) for
a signal that changes sign, and the sign of its first difference — is tested against the model's
regressors **plus** the signal's plain lags (so a missing linear lag is not mistaken for a
nonlinearity) by the added-variable F-test (:mod:`arxid.added_variable`). The p-values of all
blocks are Holm-corrected together; a signal is named when one of its lags passes ``alpha``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..data.iodata import IOData
from ..models.arx_model import ArxModel
from ..models.effects import compile_effects
from ..models.regressors import max_lag, regressor_matrix
from .added_variable import AddedVariableTest, holm
from .candidates import changes_sign

__all__ = ["NonlinearDependence", "nonlinear_dependence", "dependence_sentence"]

#: Largest number of lags tested per signal.
MAX_LAGS = 3


@dataclass(frozen=True)
class NonlinearDependence:
    """The residuals depend nonlinearly on ``signal`` at ``lags``.

    Attributes
    ----------
    signal : str
        Name of the signal (the output's or an input's).
    lags : tuple of int
        Lags (samples) where the dependence is significant, ascending.
    p_value : float
        Smallest Holm-corrected p-value over those lags.
    share : float
        Largest share of the residual energy the nonlinear functions at one lag remove (0..1).
    """

    signal: str
    lags: tuple[int, ...]
    p_value: float
    share: float

    def to_dict(self) -> dict:
        """``signal``, ``lags``, ``p_value``, ``share`` as plain JSON values.

        Returns
        -------
        dict
        """
        return {"signal": self.signal, "lags": list(self.lags), "p_value": self.p_value, "share": self.share}


def _plan(model: ArxModel, data: IOData) -> list[tuple[str, np.ndarray, tuple[int, ...]]]:
    """(signal name, samples, lags) to test: the output at lags 1.., each used input from its delay on."""
    plan = [(data.output_name, data.y, tuple(range(1, min(max(model.na_, 1), MAX_LAGS - 1) + 1)))]
    for i, name in enumerate(data.input_names):
        if model.nb_[i] > 0:
            k = model.nk_[i]
            plan.append((name, data.u[:, i], tuple(k + j for j in range(min(model.nb_[i] + 1, MAX_LAGS)))))
    return plan


def _features(x: np.ndarray, rows: np.ndarray, lag: int, signed: bool) -> np.ndarray:
    finite = x[np.isfinite(x)]
    s = (x - finite.mean()) / (finite.std() or 1.0)
    v, dv = s[rows - lag], s[rows - lag] - s[rows - lag - 1]
    cols = [v**2, v**3, np.sign(dv)] + ([np.abs(v), np.sign(v)] if signed else [])
    return np.column_stack(cols)


def nonlinear_dependence(model: ArxModel, data: IOData, alpha: float = 0.01) -> tuple[NonlinearDependence, ...]:
    """Signals and lags where the model's residual still depends nonlinearly on the data.

    Parameters
    ----------
    model : ArxModel
        A fitted model.
    data : IOData
        Data to test on (the estimation data: the F-test assumes the residual of a fit on them).
    alpha : float
        Level of the Holm-corrected F-tests.

    Returns
    -------
    tuple of NonlinearDependence
        One per signal with a significant lag, strongest first (empty: no nonlinear dependence found).

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(-1, 1, 3000)
    >>> y = np.zeros(3000)
    >>> for t in range(1, 3000):
    ...     y[t] = 0.8 * y[t - 1] + np.tanh(3 * u[t - 1]) + 0.01 * rng.standard_normal()
    >>> data = arxid.IOData(y, u, ts=0.01)
    >>> [(d.signal, d.lags) for d in nonlinear_dependence(arxid.arx(data, 1, 1, 1), data)]
    [('u1', (1,))]
    """
    layout = compile_effects(model.effects, data, model.nb_, model.nk_)
    plan = _plan(model, data)
    deepest = max((max(lags) for _, _, lags in plan if lags), default=0) + 1
    first = max(model.first_lag_, max_lag(model.na_, layout), deepest)
    phi, y, rows = regressor_matrix(data, model.na_, layout, first)
    linear = [x[rows - lag] for _, x, lags in plan for lag in lags]
    blocks = [(name, lag, _features(x, rows, lag, changes_sign(x))) for name, x, lags in plan for lag in lags]
    ok = np.isfinite(np.column_stack(linear + [b for _, _, b in blocks])).all(axis=1) if blocks else None
    if ok is None or ok.sum() <= phi.shape[1] + len(linear) + 10:
        return ()
    base = AddedVariableTest(np.column_stack([phi, *linear, np.ones(len(rows))])[ok], y[ok])
    tested = [(name, lag, res) for name, lag, b in blocks if (res := base.test(b[ok])[0]) is not None]
    if not tested:
        return ()
    adj = holm(np.array([res.p_value for _, _, res in tested]))
    found: dict[str, list[tuple[int, float, float]]] = {}
    for (name, lag, res), p in zip(tested, adj, strict=True):
        if p < alpha:
            found.setdefault(name, []).append((lag, float(p), res.score**2))
    out = [
        NonlinearDependence(
            name, tuple(sorted(lag for lag, _, _ in hits)), min(p for _, p, _ in hits), max(s for _, _, s in hits)
        )
        for name, hits in found.items()
    ]
    return tuple(sorted(out, key=lambda d: d.p_value))


def dependence_sentence(found: tuple[NonlinearDependence, ...]) -> str:
    """The plain sentence for a diagnosis in which no candidate is significant.

    Parameters
    ----------
    found : tuple of NonlinearDependence
        What :func:`nonlinear_dependence` returned.

    Returns
    -------
    str
        e.g. ``"the residuals still depend nonlinearly on u1 (lags 1, 2) but none of the
        candidates removes it"``; ``""`` when ``found`` is empty.
    """
    if not found:
        return ""
    where = " and ".join(
        f"{d.signal} (lag{'s' if len(d.lags) > 1 else ''} {', '.join(map(str, d.lags))})" for d in found
    )
    return f"the residuals still depend nonlinearly on {where} but none of the candidates removes it"
