"""Grid edges: is a chosen structure on the border of the orders swept, and which ranges to try next.

A structure sits on an edge when its na or an nb is the largest of its range, or an nk is the
largest of its range, or the smallest where the range does not start at 0 (a range of one value
was fixed by the user and is no edge). The best structure of a grid could then lie outside it;
the suggestion grows each edge range by ``max(2, ⌈len/2⌉)`` values, the step
:meth:`arxid.SweepResult.extend` takes.

Poles and zeros grow together (:func:`grown_grid` with ``together``): an edge on na or on an nb
grows na and every nb range that is not fixed, each by its own step. A plant of order n needs about
n poles and n zeros; growing only the range on the edge walks one order at a time and stops at a
structure such as ARX(13,4,0) that is inside its grid but far from a plant that needs ARX(11,12,0)
(a flexible arm, ``tests/test_robust_grid.py``). The delay nk grows only on its own edge.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from .._base.records import record

__all__ = ["Edge", "grid_edges", "grown_grid", "edge_text"]


@record
class Edge:
    """One order of a structure on the border of its range.

    Attributes
    ----------
    order : str
        ``"na"``, ``"nb"`` or ``"nk"``.
    input : int or None
        Input index for nb and nk (None for na).
    value : int
        The structure's order.
    side : str
        ``"largest"`` or ``"smallest"``.
    suggestion : tuple of int
        The range to try instead.
    """

    order: str
    input: int | None
    value: int
    side: str
    suggestion: tuple[int, ...]

    def __str__(self) -> str:
        label = self.order if self.input is None else f"{self.order}[{self.input}]"
        lo, hi = self.suggestion[0], self.suggestion[-1]
        return f"{label} = {self.value} is the {self.side} tried; try {label} {lo}:{hi}"


def _step(values: Sequence[int]) -> int:
    return max(2, math.ceil(len(values) / 2))


def grid_edges(
    grid: dict, na: int, nb: Sequence[int], nk: Sequence[int], multi_input: bool = False
) -> tuple[Edge, ...]:
    """The edges structure (na, nb, nk) touches in ``grid``.

    Parameters
    ----------
    grid : dict
        ``{"na": tuple, "nb": [tuple per input], "nk": [tuple per input]}`` as swept.
    na : int
    nb, nk : sequence of int
        Per input.
    multi_input : bool
        Name the input in the text (several inputs).

    Returns
    -------
    tuple of Edge
    """
    out = []
    nas = tuple(grid["na"])
    if len(nas) > 1 and na == max(nas):
        out.append(Edge("na", None, na, "largest", tuple(range(min(nas), max(nas) + _step(nas) + 1))))
    for j, (b, k) in enumerate(zip(nb, nk)):
        nbs, nks = tuple(grid["nb"][j]), tuple(grid["nk"][j])
        idx = j if multi_input else None
        if len(nbs) > 1 and b == max(nbs):
            out.append(Edge("nb", idx, b, "largest", tuple(range(min(nbs), max(nbs) + _step(nbs) + 1))))
        if len(nks) > 1 and k == max(nks):
            out.append(Edge("nk", idx, k, "largest", tuple(range(min(nks), max(nks) + _step(nks) + 1))))
        if len(nks) > 1 and k == min(nks) and k > 0:
            out.append(Edge("nk", idx, k, "smallest", tuple(range(max(0, min(nks) - _step(nks)), max(nks) + 1))))
    return tuple(out)


def grown_grid(grid: dict, edges: Sequence[Edge], limit: int, together: bool = False) -> dict | None:
    """``grid`` with every edge range replaced by its suggestion (capped at ``limit``); None when
    nothing could grow.

    Parameters
    ----------
    grid : dict
        As in :func:`grid_edges`.
    edges : sequence of Edge
    limit : int
        Largest order allowed.
    together : bool
        Grow poles and zeros together: an edge on na or on any nb also grows na and every nb range
        of more than one value (each by ``max(2, ⌈len/2⌉)``), as :meth:`arxid.SweepResult.extend`
        does.

    Returns
    -------
    dict or None
    """
    na: tuple[int, ...] = tuple(grid["na"])
    per_input: dict[str, list[tuple[int, ...]]] = {k: [tuple(r) for r in grid[k]] for k in ("nb", "nk")}
    edges = list(edges)
    if together and any(e.order in ("na", "nb") for e in edges):
        edges = [e for e in edges if e.order == "nk"] + _size_edges(na, per_input["nb"])
    grew = False
    for e in edges:
        sug = tuple(v for v in e.suggestion if v <= limit)
        if e.order == "na":
            grew |= sug != na
            na = sug
        else:
            ranges = per_input[e.order]
            for j in range(len(ranges)) if e.input is None else [e.input]:
                grew |= sug != ranges[j]
                ranges[j] = sug
    return {"na": na, **per_input} if grew else None


def _size_edges(na: tuple[int, ...], nbs: list[tuple[int, ...]]) -> list[Edge]:
    """Largest-side edges on na and on every nb range of more than one value (poles and zeros grown
    together)."""
    out = []
    if len(na) > 1:
        out.append(Edge("na", None, max(na), "largest", tuple(range(min(na), max(na) + _step(na) + 1))))
    for j, nbs_j in enumerate(nbs):
        if len(nbs_j) > 1:
            grown = tuple(range(min(nbs_j), max(nbs_j) + _step(nbs_j) + 1))
            out.append(Edge("nb", j, max(nbs_j), "largest", grown))
    return out


def edge_text(structure: str, edges: Sequence[Edge]) -> str:
    """One sentence for tables and reports ("" when the structure is inside the grid).

    Parameters
    ----------
    structure : str
    edges : sequence of Edge

    Returns
    -------
    str
    """
    if not edges:
        return ""
    return (
        f"{structure} sits on the edge of the grid ({'; '.join(str(e) for e in edges)}): a better structure may "
        f"lie outside it"
    )
