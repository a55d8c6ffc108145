"""What the parameters of a fitted model multiply: :class:`FittedLayout`, the columns of its effect
layout without the data (what the converters, the printing and the model file read)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from .._base.records import record
from .effects import EffectLayout

__all__ = ["FittedLayout"]


@record
class FittedLayout:
    """What every parameter of a fitted model multiplies: the columns of its effect layout.

    Attributes
    ----------
    nb, nk : tuple of int
        Orders and delays per column (the inputs, then input-derived effect columns).
    output_terms : tuple of (kind, power, carrier)
        Output-derived effect terms, one parameter each.
    column_labels : tuple of str
        Name of each column (an input name or the effect that built it).
    effect_of_column : tuple of (str or None)
        The effect each column belongs to (None for the model's inputs).
    effect_of_term : tuple of str
        The effect each output term belongs to.
    """

    nb: tuple[int, ...]
    nk: tuple[int, ...]
    output_terms: tuple[tuple[str, int, int], ...]
    column_labels: tuple[str, ...]
    effect_of_column: tuple[str | None, ...]
    effect_of_term: tuple[str, ...]

    @classmethod
    def of(cls, layout: EffectLayout) -> FittedLayout:
        """The fitted part of an :class:`~arxid.effects.EffectLayout` (no data arrays).

        Parameters
        ----------
        layout : EffectLayout

        Returns
        -------
        FittedLayout
        """
        return cls(
            tuple(layout.nb),
            tuple(layout.nk),
            tuple(tuple(t) for t in layout.output_terms),  # type: ignore[misc]
            tuple(layout.column_labels),
            tuple(layout.effect_of_column),
            tuple(layout.effect_of_term),
        )

    def to_dict(self) -> dict:
        """JSON-ready.

        Returns
        -------
        dict
        """
        return {
            "nb": list(self.nb),
            "nk": list(self.nk),
            "output_terms": [list(t) for t in self.output_terms],
            "column_labels": list(self.column_labels),
            "effect_of_column": list(self.effect_of_column),
            "effect_of_term": list(self.effect_of_term),
        }

    @classmethod
    def from_dict(cls, d: Mapping[str, Any], input_names: Sequence[str], effects: Sequence[str]) -> FittedLayout:
        """Read :meth:`to_dict`; files written before the labels were stored get generic labels.

        Parameters
        ----------
        d : mapping
        input_names : sequence of str
        effects : sequence of str

        Returns
        -------
        FittedLayout
        """
        nb, terms = tuple(int(v) for v in d["nb"]), tuple((str(k), int(p), int(c)) for k, p, c in d["output_terms"])
        m = len(input_names)
        labels = d.get("column_labels") or list(input_names) + [f"effect{j}" for j in range(m, len(nb))]
        of_column = d.get("effect_of_column") or [None] * len(nb)
        of_term = d.get("effect_of_term") or [f"term{j}" for j in range(len(terms))]
        return cls(nb, tuple(int(v) for v in d["nk"]), terms, tuple(labels), tuple(of_column), tuple(of_term))
