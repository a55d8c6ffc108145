"""What an analysis concludes, whether its records were one in this process or a fleet's logs on a
cluster: the parts of :class:`~arxid.analysis.pipeline.Analysis` and
:class:`~arxid.analysis.fleet_analysis.FleetAnalysis` that are the same (their JSON, the suspect
table, the missing effect, the ladder's lines), written once."""

from __future__ import annotations

from .._base.formatting import format_value, horizon_label, json_safe, text_table
from .._base.records import record
from ..diagnosis.ladder import Ladder
from ..diagnosis.result import Diagnosis
from ..models.arx_model import ArxModel
from ..selection.search import SweepResult
from .choice import Choice, OrderGrid, grid_lists
from .verdicts import ladder_headline

__all__ = ["Conclusion", "concluded"]


@record(eq=False, kw_only=True)  # every field by name: the subclasses add theirs
class Conclusion:
    """The shared face of an analysis' result: what one record and a fleet both conclude.

    Attributes
    ----------
    grid : dict of str to tuple of int, or None
        The order grid asked for (None when the orders or the model were given).
    sweep : SweepResult or None
        Every structure of the last grid swept, ranked (None when the orders or the model were given).
    choice : Choice
        Which structure was chosen and why.
    model : ArxModel
        The chosen structure, without added effects.
    horizon : int or None
        The validation error measure: None = free run, k = k-step-ahead prediction.
    diagnosis : Diagnosis
        Suspects for the chosen model's error.
    ladder : Ladder
        The models as the significant suspects are added, with their validation errors.
    timings : dict of str to float
        Seconds spent in each stage.
    notes : tuple of str
        What the reader should know.
    """

    grid: OrderGrid | None
    sweep: SweepResult | None
    choice: Choice
    model: ArxModel
    horizon: int | None
    diagnosis: Diagnosis
    ladder: Ladder
    timings: dict
    notes: tuple[str, ...] = ()

    @property
    def final_model(self) -> ArxModel:
        """The model of the ladder's last step (the chosen model when nothing was added)."""
        return self.ladder.final_model

    @property
    def missing_effect(self) -> str | None:
        """The best significant suspect, or None when nothing significant is missing."""
        top = self.diagnosis.top
        return None if top is None else top.effect

    def to_dict(self) -> dict:
        """The keys every analysis has: those of :meth:`Diagnosis.to_dict` with the ladder, ``choice``,
        ``grid`` (the order grid asked for, None when the orders were given), ``notes`` and
        ``error_fall`` (see :meth:`Ladder.error_fall`).

        Returns
        -------
        dict
        """
        out = self.diagnosis.to_dict(self.ladder)
        out.update({"choice": self.choice.to_dict(), "grid": None if self.grid is None else grid_lists(self.grid)})
        out.update({"notes": list(self.notes), "error_fall": self.ladder.error_fall()})
        return out

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict` (NaN and inf become null).

        Parameters
        ----------
        indent : int or None

        Returns
        -------
        str
        """
        import json

        return json.dumps(json_safe(self.to_dict()), indent=indent, allow_nan=False)

    def summary_lines(self, n_suspects: int = 12) -> list[str]:
        """The text report of ``arxid diagnose`` (``arxid fleet``): the model and its validation,
        the suspect table, the missing effect and the ladder.

        Parameters
        ----------
        n_suspects : int
            Rows of the suspect table.

        Returns
        -------
        list of str
        """
        return self._head_lines() + self._suspect_lines(n_suspects) + self._verdict_lines() + self._tail_lines()

    def _head_lines(self) -> list[str]:
        """What comes before the suspects: the model, the choice, its validation."""
        raise NotImplementedError

    def _evidence_lines(self) -> list[str]:
        """What comes after the missing effect's name (where it shows)."""
        return []

    def _tail_lines(self) -> list[str]:
        return []

    def __str__(self) -> str:
        return "\n".join(self.summary_lines())

    def _validation_line(self) -> str:
        d = self.diagnosis
        return (
            f"validation ({horizon_label(self.horizon)}): RMS {format_value(d.rms_sim_val)}, one-step RMS "
            f"{format_value(d.rms_pred_val)}, fit {format_value(d.fit_val)} %"
        )

    def _suspect_lines(self, n: int) -> list[str]:
        """The suspect table's best ``n`` rows (nothing without a suspect)."""
        d = self.diagnosis
        rows = [
            [str(i), s.effect, s.score, s.p_value, s.significant, s.rms_sim_val_after, s.explained_by or "-", d.why(s)]
            for i, s in enumerate(d.suspects[:n], start=1)
        ]
        if not rows:
            return []
        head = ["rank", "effect", "score", "p-value", "significant", "val. RMS after", "explained by", "why"]
        return ["", text_table(head, rows, title="suspects (missing effects, ranked):")]

    def _verdict_lines(self) -> list[str]:
        """The missing effect, where it shows, and the ladder with its headline."""
        missing = self.missing_effect
        lines = ["", f"missing effect: {missing}" if missing else "no significant missing effect"]
        lines += self._evidence_lines()
        if len(self.ladder):
            lines += ["", str(self.ladder)]
            headline = ladder_headline(self.ladder)
            lines += [headline] if headline else []
        return lines


def concluded(
    grid: OrderGrid | None, sweep: SweepResult | None, choice: Choice, model: ArxModel, ladder: Ladder, timings: dict
) -> dict:
    """The fields of a :class:`Conclusion` from its stages: the measure and first diagnosis are the
    ladder's.

    Parameters
    ----------
    grid : OrderGrid or None
    sweep : SweepResult or None
    choice : Choice
    model : ArxModel
    ladder : Ladder
    timings : dict of str to float

    Returns
    -------
    dict
    """
    return dict(
        grid=grid,
        sweep=sweep,
        choice=choice,
        model=model,
        horizon=ladder.horizon,
        diagnosis=ladder.diagnoses[0],
        ladder=ladder,
        timings=timings,
    )
