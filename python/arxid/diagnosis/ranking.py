"""The last step of a diagnosis, wherever its suspects come from (one record, a fleet, the outputs of
a state-space model): the candidates that could not be scored added with their reason, the physics
of each suspect, and the ranking."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from ..data.iodata import IOData
from .candidates import physics
from .extension import Candidate
from .result import Suspect

__all__ = ["finish_suspects"]


def _unscored(notes: dict[str, str], cands: list[Candidate], suspects: list[Suspect]) -> list[Suspect]:
    """Candidates that could not be scored, with the reason, so the table says why they are absent."""
    have = {s.effect for s in suspects}
    by_label = {c.label: c for c in cands}
    nan = math.nan
    return [
        Suspect(lab, c.kind, c.effects, c.na, c.nb, c.nk, nan, nan, nan, nan, 0, nan, nan, False, why, None)
        for lab, why in notes.items()
        if lab not in have and (c := by_label.get(lab)) is not None
    ]


def _rank_key(s: Suspect) -> tuple:
    """Significant first (lowest validation error first), then refitted by error, then by p-value."""
    after = s.rms_sim_val_after
    refitted = not math.isnan(after)
    p = s.p_value if math.isfinite(s.p_value) else 2.0
    return (not s.significant, not refitted, after if refitted else 0.0, p, -np.nan_to_num(s.score))


def finish_suspects(
    notes: dict[str, str], cands: list[Candidate], suspects: list[Suspect], data: IOData
) -> list[Suspect]:
    """The last step of :func:`diagnose`, shared with the diagnosis of a fleet: the candidates that
    could not be scored added with their reason, the physics of each suspect, and the ranking.

    Parameters
    ----------
    notes : dict of str to str
        Why a candidate was not scored, by label.
    cands : list of Candidate
    suspects : list of Suspect
        The judged suspects.
    data : IOData
        The estimation data (their signal names tell inputs from logged signals).

    Returns
    -------
    list of Suspect
        Ranked: significant first, then refitted by validation error, then by p-value.
    """
    suspects = suspects + _unscored(notes, cands, suspects)
    return sorted((replace(s, physics=s.physics or physics(s.effect, data)) for s in suspects), key=_rank_key)
