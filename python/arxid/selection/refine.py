"""Output-error refinement of a sweep (:func:`refine`, behind ``arxid.sweep(..., refine="oe")``): the best
ARX structures of a :class:`~arxid.SweepResult` and a small grid refitted as output-error models
(:func:`arxid.oe`) and every model ranked by its free-run error on the validation data
(:class:`RefinedSweep`)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._base import metrics
from .._base.formatting import text_table
from ..checks import prediction
from ..exceptions import ArxidError, OrderError
from ..models.pem import oe
from ..models.polynomial import check_initial
from .table import SweepTable

__all__ = ["refine", "RefinedSweep", "RefinedRow"]


@dataclass(frozen=True)
class RefinedRow:
    """One structure of a refined sweep.

    Attributes
    ----------
    model_class : str
        ``"ARX"`` or ``"OE"``.
    structure : str
        ``ARX(na,nb,nk)`` or ``OE(nb,nf,nk)``.
    n_params : int
    rms_val : float
        Free-run RMS error on the validation data (the estimation data without them), on the
        samples every row predicts, from the initial conditions the refinement was asked for.
    fit_val : float
        Free-run NRMSE fit in percent on the same samples.
    score : float
        The ranking measure: Akaike's FPE of the validation free-run error, V (N + p) / (N − p),
        which breaks statistically meaningless differences in favour of fewer parameters.
    converged : bool
        The OE iterations stopped at a minimum (always True for ARX).
    model : ArxModel or PolynomialModel
    """

    model_class: str
    structure: str
    n_params: int
    rms_val: float
    fit_val: float
    score: float
    converged: bool
    model: Any = field(repr=False, compare=False)


@dataclass(frozen=True)
class RefinedSweep:
    """ARX structures of a sweep and their output-error refinements, ranked by validation free-run error.

    Attributes
    ----------
    rows : tuple of RefinedRow
        Best first.
    sweep : SweepResult
        The ARX sweep that was refined.
    """

    rows: tuple[RefinedRow, ...]
    sweep: Any = field(repr=False)

    def __len__(self) -> int:
        return len(self.rows)

    def best(self) -> Any:
        """The first-ranked model.

        Returns
        -------
        ArxModel or PolynomialModel
        """
        return self.rows[0].model

    def structure_name(self, i: int) -> str:
        """Name of the ``i``-th ranked structure.

        Parameters
        ----------
        i : int

        Returns
        -------
        str
        """
        return self.rows[i].structure

    def table(self, n: int = 12) -> str:
        """The ranking as text: model class, structure, parameters, validation free-run error.

        Parameters
        ----------
        n : int
            Rows shown.

        Returns
        -------
        str
        """
        body = [
            [
                i + 1,
                r.model_class,
                r.structure,
                r.n_params,
                r.rms_val,
                r.fit_val,
                r.score,
                "yes" if r.converged else "no",
            ]
            for i, r in enumerate(self.rows[:n])
        ]
        head = ["rank", "class", "structure", "params", "RMS (val, free run)", "fit % (val)", "FPE (val)", "converged"]
        return text_table(head, body, title="ARX sweep refined to output-error models")

    def __str__(self) -> str:
        return self.table()


def _candidates(
    result: SweepTable, top: int, grid: dict[str, Any] | None, initial: str = "zero"
) -> list[tuple[str, Any]]:
    """The top ARX models of the sweep, their OE counterparts (nf = na) and an OE grid."""
    est = result.estimation
    out: list[tuple[str, Any]] = []
    seen = set()
    for i in range(min(top, len(result))):
        arx = result.model(i)
        out.append(("ARX", arx))
        if arx.na_:
            seen.add((tuple(arx.nb_), (arx.na_,) * est.n_inputs, tuple(arx.nk_)))
    g = grid or {}
    nks = _as_list(g.get("nk", sorted({int(v) for row in result.nk for v in np.atleast_1d(row)})))
    for nb in _as_list(g.get("nb", (1, 2, 3))):
        for nf in _as_list(g.get("nf", (1, 2, 3))):
            for nk in nks:
                seen.add(((int(nb),) * est.n_inputs, (int(nf),) * est.n_inputs, (int(nk),) * est.n_inputs))
    for nb_, nf_, nk_ in sorted(seen):
        try:
            out.append(("OE", oe(est, list(nb_), list(nf_), list(nk_), initial=initial, warn=False)))
        except ArxidError:
            continue
    return out


def refine(
    result: SweepTable,
    structure: str = "oe",
    top: int = 5,
    grid: dict[str, Any] | None = None,
    initial: str = "zero",
) -> RefinedSweep:
    """Refit the best ARX structures of a sweep (and a small grid) as output-error models and rank
    every model by its free-run error on the validation data (penalised for parameters as FPE).

    Parameters
    ----------
    result : SweepResult
    structure : {"oe"}
        The model class the ARX structures are refined to.
    top : int
        Number of best ARX structures kept and refitted as OE(nb, nf = na, nk).
    grid : dict, optional
        ``{"nb": ..., "nf": ..., "nk": ...}`` ranges of the OE grid fitted as well (default nb and
        nf in 1..3, nk over the sweep's delays). Orders are shared by all inputs.
    initial : {"zero", "estimate"}
        Initial conditions of the OE fits (see :meth:`PolynomialModel.fit`) and of every row's free
        run on the validation data (see :func:`arxid.compare`): ``"zero"`` (default) runs OE models
        from rest and ARX models from the measured outputs; ``"estimate"`` fits each row's initial
        conditions first, so a validation record that starts mid-transient is not held against
        the OE rows. ARX and OE rows are scored alike either way.

    Returns
    -------
    RefinedSweep

    Notes
    -----
    ARX with output noise compensates bias with many parameters and loses the delay; OE structures
    of low order describe the same response with the right delay. All rows are scored on the
    samples every model predicts and ranked by Akaike's FPE of that error (the mean square error
    times (N + p) / (N − p)): a high-order ARX structure that matches a 4-parameter OE model's
    error to 0.1 % does not outrank it.
    """
    if structure != "oe":
        raise ArxidError(f"refine supports structure='oe' only, got {structure!r}")
    top = _int("top", top, 1)
    val = result.validation if result.validation is not None else result.estimation
    initial = check_initial(initial)
    cands = _candidates(result, top, grid, initial)
    preds = [prediction(m, val, None, initial)[0] for _, m in cands]
    ok = np.isfinite(val.y)
    for p in preds:
        ok &= np.isfinite(p) | ~np.isfinite(p).any()
    rows, n = [], int(ok.sum())
    for (kind, m), p in zip(cands, preds):
        e = np.where(ok, val.y - p, np.nan)
        rms = math.inf if metrics.diverged(val.y, p) else metrics.rms(e)
        fit = metrics.fit_percent(np.where(ok, val.y, np.nan), p)
        score = float(metrics.fpe(n * rms**2, n, m.n_params)) if math.isfinite(rms) else math.inf
        converged = bool(getattr(m, "converged_", True))
        rows.append(RefinedRow(kind, m.structure_name(), m.n_params, rms, fit, score, converged, m))
    rows.sort(key=lambda r: (r.score, r.n_params))
    return RefinedSweep(tuple(rows), result)


def _as_list(v: Any) -> Sequence[Any]:
    return list(v) if isinstance(v, (list, tuple, range, np.ndarray)) else [v]


def _int(name: str, value: Any, low: int = 0) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or int(value) < low:
        raise OrderError(f"{name} must be an integer >= {low}, got {value!r}")
    return int(value)
