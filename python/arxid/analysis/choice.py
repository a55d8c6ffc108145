"""Which structure an analysis chose and why: :func:`choose` on a sweep, :class:`Choice` to say
it, and the order grid of an analysis (:func:`grid_of`)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, TypedDict, cast

from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from ..models.arguments import check_model
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel
from ..selection.search import DEFAULT_GRID, SweepResult

__all__ = ["Choice", "OrderGrid", "choose", "grid_of", "grid_lists", "given_model"]


@record
class Choice:
    """Which structure was chosen and why.

    Attributes
    ----------
    structure : str
        The chosen structure, e.g. ``ARX(2,1,3)``.
    rank : int or None
        Its 0-based rank in the sweep (None when the orders or the model were given).
    reason : str
        One sentence: how it was chosen.
    skipped : tuple of (str, str)
        Better-ranked structures the step sanity check rejected, with the reason.
    grid_edge : str
        When the structure sits on an edge of the swept grid: which, and the ranges to try.
    """

    structure: str
    rank: int | None
    reason: str
    skipped: tuple[tuple[str, str], ...] = ()
    grid_edge: str = ""

    def to_dict(self) -> dict:
        """JSON-ready: structure, rank (1-based, or None), reason, skipped (structure, why).

        Returns
        -------
        dict
        """
        return {
            "structure": self.structure,
            "rank": None if self.rank is None else self.rank + 1,
            "reason": self.reason,
            "skipped": [{"structure": s, "why": w} for s, w in self.skipped],
            "grid_edge": self.grid_edge or None,
        }


class OrderGrid(TypedDict):
    """The order ranges of a sweep, every key present."""

    na: tuple[int, ...]
    nb: tuple[int, ...]
    nk: tuple[int, ...]


def grid_of(grid: Mapping[str, Any] | None = None) -> OrderGrid:
    """The order grid with every key present: ``grid`` completed from :data:`arxid.DEFAULT_GRID`.

    Parameters
    ----------
    grid : mapping with keys among na, nb, nk, optional
        Order ranges; missing keys take the default.

    Returns
    -------
    dict of str to tuple of int
    """
    g = dict(grid or {})
    unknown = set(g) - {"na", "nb", "nk"}
    if unknown:
        raise OrderError(f"grid keys must be na, nb, nk; got {sorted(unknown)}")
    na, nb, nk = (tuple(int(v) for v in _as_range(g.get(k, DEFAULT_GRID[k]))) for k in ("na", "nb", "nk"))
    return OrderGrid(na=na, nb=nb, nk=nk)


def grid_lists(g: OrderGrid) -> dict[str, list[int]]:
    return {"na": list(g["na"]), "nb": list(g["nb"]), "nk": list(g["nk"])}


def _as_range(v: Any) -> Sequence[int]:
    return [v] if isinstance(v, int) else list(v)


def choose(result: SweepResult, rule: str = "lowest") -> tuple[ArxModel, Choice]:
    """The best-ranked structure of a sweep that passes the step sanity check, and why.

    The step sanity check includes stability for a plant the sweep does not call integrating, so
    the choice never has a pole outside the unit circle there; every better-ranked structure it
    passed over is listed with its reasons, and a choice on an edge of the grid says so. When no
    structure passes, the best one by validation error is chosen and the reason says what it fails:
    valid data always get an answer.

    Parameters
    ----------
    result : SweepResult
    rule : {"lowest", "smallest-within-noise"}
        See :meth:`SweepResult.select`. ``"lowest"`` (MATLAB's pick) is the default.

    Returns
    -------
    model : ArxModel
        The structure refitted on the sweep's rows (its parameters equal the sweep's).
    choice : Choice
    """
    try:
        sel = result.select(sane=True, rule=rule)
        among = "among those whose step response passes the sanity check"
    except ArxidError:  # valid data deserve an answer: the best one, with what it fails
        sel = result.select(sane=False, rule=rule)
        failed = "; ".join(result.sanity(sel.rank).reasons) or "its free run diverged"
        among = (
            f"although no structure's step response passes the sanity check (this one's: {failed}); "
            f"check the data, or say what the plant does with expect='stable' or expect='integrating'"
        )
    model = result.model(sel.rank)
    reason = f"the lowest {result.ranking_text} of {len(result)} structures {among}"
    if sel.note:
        reason = f"{sel.note}, {among}"
    skipped = tuple((name, "; ".join(reasons)) for _, name, reasons in sel.skipped)
    return model, Choice(sel.structure, sel.rank, reason, skipped, sel.grid_edge)


def given_model(
    est: IOData, model: ArxModel | PolynomialModel | str, orders: Sequence | None, grid: Mapping | None
) -> tuple[ArxModel, Choice]:
    """The model the user gave (fitted, or a structure such as ``"oe:2,2,3"`` fitted here), and why."""
    if orders is not None or grid is not None:
        raise OrderError("give either model=... or orders/grid, not both: the model fixes the structure")
    if isinstance(model, str):
        from ..models.spec import parse_model_spec

        spec = parse_model_spec(model)
        fitted = spec.fit(est)
        how = spec.method
        return cast(ArxModel, fitted), Choice(
            fitted.structure_name(), None, f"the structure was given and fitted by {how} on the estimation data"
        )
    fitted = check_model(model)
    if fitted.measured_input_names != est.input_names:
        raise DataError(f"the model's inputs {list(fitted.input_names)} differ from the data's {list(est.input_names)}")
    return fitted, Choice(fitted.structure_name(), None, "the model was given and is used as fitted, not refitted")
