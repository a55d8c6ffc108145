"""The analysis of a fleet of logs on a Dask cluster: ``arxid.analyse(logs, client=...)``.

The logs are read by the workers and stay there (:class:`arxid.fleet.cluster.WorkerLogs`); the last
``1 - split`` of each log validates. The structure comes from the given orders (fitted from the
shares' factors) or from the fleet sweep (``arxid.sweep(logs, client=...)``) and the in-process
choice (:func:`arxid.analysis.pipeline.choose`; its step sanity check and refit read the chosen
structure's data on the client, as a fleet sweep's result does). Then the diagnosis and the ladder
run on sufficient statistics where the logs are (:func:`arxid.diagnosis.fleet_diagnose.diagnose_fleet`):
the same suspects, statistics and ladder errors as :func:`arxid.analyse` on the logs merged as
experiments of one IOData (``arxid.data.logs.merged_parts``) with the same orders, to rounding; and
which logs the missing effect shows in.

Differences from the in-process analysis, said in :attr:`FleetAnalysis.notes`: no comparison plots,
where-it-fails, frequency checks, bands, feedback test or residual tests (they need the whole
residual sequence on the client); the ladder keeps the chosen orders (in process a swept structure is
re-chosen as effects are added) and does not take out earlier effects a later one makes unnecessary.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, cast

from .._base.formatting import format_value, horizon_label, json_safe, text_table
from ..diagnosis.candidates import physics
from ..diagnosis.fleet_diagnose import FleetDiagnosis, diagnose_fleet
from ..diagnosis.fleet_refit import FleetRefits
from ..diagnosis.ladder import Ladder, LadderStep, next_rung
from ..diagnosis.result import Diagnosis
from ..exceptions import ArxidError, OrderError
from ..fleet.cluster import WorkerLogs
from ..models.arx_model import ArxModel
from ..models.polynomial import check_initial
from ..selection.growth import DEFAULT_GROWTH_SECONDS
from ..selection.search import SweepResult, sweep
from .pipeline import DEFAULT_SPLIT, FLEET_ANALYSIS, Choice, OrderGrid, choose, grid_lists, grid_of
from .verdicts import ladder_headline

__all__ = ["FleetAnalysis", "analyse_fleet", "FLEET_ANALYSIS_NOTE"]

#: What the analysis of a fleet does not do (see the module's docstring).
FLEET_ANALYSIS_NOTE = (
    "Fleet analysis on a Dask cluster: no comparison plots, where-it-fails, frequency checks, bands, feedback or "
    "residual tests; the ladder keeps the chosen orders and does not take out earlier effects."
)


@dataclass(frozen=True, eq=False)
class FleetAnalysis:
    """What arxid concludes about a fleet of logs analysed where they are.

    Attributes
    ----------
    logs : tuple of str
        The logs' names, in the order given.
    grid : dict or None
        The order grid swept (None when the orders were given).
    sweep : SweepResult or None
    choice : Choice
    model : ArxModel
        The chosen structure, fitted on every log's estimation part.
    horizon : int or None
        The validation error measure (None: free run; k: k steps ahead).
    diagnosis : Diagnosis
        Suspects for the chosen model's error over the fleet (without residual tests).
    ladder : Ladder
        The models as the significant suspects are added, with their validation errors.
    fleet : FleetDiagnosis
        The first diagnosis with the logs the missing effect shows in.
    timings : dict of str to float
    notes : tuple of str
    """

    logs: tuple[str, ...]
    grid: OrderGrid | None
    sweep: SweepResult | None
    choice: Choice
    model: ArxModel
    horizon: int | None
    diagnosis: Diagnosis
    ladder: Ladder
    fleet: FleetDiagnosis
    timings: dict
    notes: tuple[str, ...] = ()

    @property
    def final_model(self) -> ArxModel:
        """The model of the ladder's last step."""
        return self.ladder.final_model

    @property
    def missing_effect(self) -> str | None:
        """The best significant suspect, or None."""
        top = self.diagnosis.top
        return None if top is None else top.effect

    @property
    def logs_with_effect(self) -> tuple[str, ...]:
        """The logs where the missing effect is significant on their own."""
        return self.fleet.logs_with_effect

    def to_dict(self) -> dict:
        """The machine-readable result: the keys of :meth:`Analysis.to_dict` that a fleet has
        (``model``, ``baseline``, ``suspects``, ``ladder``, ``choice``, ``grid``, ``notes``,
        ``error_fall``), plus ``logs`` and ``fleet`` (:meth:`FleetDiagnosis.to_dict`: each log's test
        of the missing effect and the sentence naming the logs it shows in).

        Returns
        -------
        dict
        """
        out = self.diagnosis.to_dict(self.ladder)
        g = self.grid
        out.update(
            {
                "choice": self.choice.to_dict(),
                "grid": None if g is None else {"na": list(g["na"]), "nb": list(g["nb"]), "nk": list(g["nk"])},
                "logs": list(self.logs),
                "fleet": self.fleet.to_dict(),
                "notes": list(self.notes),
                "error_fall": self.ladder.error_fall(),
                "timings": dict(self.timings),
            }
        )
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
        return json.dumps(json_safe(self.to_dict()), indent=indent, allow_nan=False)

    def summary_lines(self, n_suspects: int = 12) -> list[str]:
        """The text report of ``arxid diagnose`` on a fleet.

        Parameters
        ----------
        n_suspects : int
            Rows of the suspect table.

        Returns
        -------
        list of str
        """
        d = self.diagnosis
        lines = [f"fleet of {len(self.logs)} logs analysed on the Dask cluster"]
        lines.append(f"model: {self.model.structure_name()} ({self.choice.reason})")
        lines.append(
            f"validation ({horizon_label(self.horizon)}): RMS {format_value(d.rms_sim_val)}, one-step RMS "
            f"{format_value(d.rms_pred_val)}, fit {format_value(d.fit_val)} %"
        )
        rows = [
            [str(i), s.effect, s.score, s.p_value, s.significant, s.rms_sim_val_after, s.explained_by or "-", d.why(s)]
            for i, s in enumerate(d.suspects[:n_suspects], start=1)
        ]
        if rows:
            head = ["rank", "effect", "score", "p-value", "significant", "val. RMS after", "explained by", "why"]
            lines += ["", text_table(head, rows, title="suspects (missing effects, ranked):")]
        lines += [
            "",
            f"missing effect: {self.missing_effect}" if self.missing_effect else "no significant missing effect",
        ]
        lines.append(self.fleet.sentence())
        if self.fleet.evidence:
            rows = [[e.log, e.rows, e.score, e.f_statistic, e.p_adjusted, e.significant] for e in self.fleet.evidence]
            head = ["log", "rows", "partial corr.", "F", "p (Holm)", "shows it"]
            lines += ["", text_table(head, rows, title=f"{self.missing_effect} in each log:")]
        if len(self.ladder):
            lines += ["", str(self.ladder)]
            headline = ladder_headline(self.ladder)
            lines += [headline] if headline else []
        return lines + ["", *self.notes]

    def __str__(self) -> str:
        return "\n".join(self.summary_lines())


def _structure(
    logs: WorkerLogs,
    sources: Sequence[Any],
    refits: FleetRefits,
    orders: Sequence | None,
    grid: Mapping | None,
    options: dict,
) -> tuple[SweepResult | None, ArxModel, Choice, OrderGrid | None]:
    """The chosen structure: the given orders fitted where the logs are, or the fleet sweep's choice."""
    if orders is not None:
        if grid is not None:
            raise OrderError("give either orders or grid, not both")
        try:
            na, nb, nk = orders
        except (TypeError, ValueError):
            raise OrderError(f"orders must be (na, nb, nk), got {orders!r}") from None
        m = len(logs.signals.input_names)
        nbs = tuple(nb) if isinstance(nb, (list, tuple)) else (int(nb),) * m
        nks = tuple(nk) if isinstance(nk, (list, tuple)) else (int(nk),) * m
        model = refits.fit(int(na), nbs, nks, ())
        return None, model, Choice(model.structure_name(), None, "the orders were given"), None
    g = grid_of(grid)  # the grid of the in-process analysis, grown by the same rule (arxid.sweep's)
    options.update(grid_lists(g) if grid is not None else {})
    res = sweep(cast(Any, list(sources)), client=logs.client, validation=logs.validation, **options)
    res = res if res.growth is not None else res.extend(max_rounds=0, max_seconds=options["growth_seconds"])
    model, choice = choose(res)
    return res, model, choice, g


def fleet_ladder(
    model: ArxModel, logs: WorkerLogs, max_steps: int, horizon: int | None, initial: str, diagnose_kwargs: dict
) -> tuple[Ladder, FleetDiagnosis]:
    """The greedy ladder of :meth:`Ladder.run` (orders kept) with every diagnosis made on the fleet.

    Parameters
    ----------
    model : ArxModel
    logs : WorkerLogs
    max_steps : int
    horizon : int or None
    initial : {"zero", "estimate"}
    diagnose_kwargs : dict
        Passed to :func:`diagnose_fleet`.

    Returns
    -------
    tuple of (Ladder, FleetDiagnosis)
        The ladder and its first diagnosis.
    """
    refits = FleetRefits(logs)
    first = diagnose_fleet(model, logs, horizon=horizon, initial=initial, **diagnose_kwargs)
    d = first.diagnosis
    ladder = Ladder(d.validation, d.horizon, initial)

    def measured(m: ArxModel, added: str, base: Diagnosis) -> LadderStep:
        # A diagnosis of ``m`` at the ladder's measure has measured it already (one round trip less).
        if base.model is m and base.horizon == ladder.horizon:
            rms, fit = base.rms_sim_val, base.fit_val
        else:
            score = refits.scores(m, [("val", ladder.horizon, initial)])[0]
            rms, fit = score.rms, score.fit
        text = physics(added, logs.head) if added else ""
        return LadderStep(added, m, tuple(m.effects), m.structure_name(), rms, fit, ladder.horizon, text)

    ladder.steps.append(measured(model, "", d))
    ladder.diagnoses.append(d)
    for _ in range(int(max_steps)):
        rung = next_rung(d)
        if rung is None or rung.model is None:
            break
        model = rung.model
        d = diagnose_fleet(model, logs, horizon=d.horizon, initial=initial, **diagnose_kwargs).diagnosis
        ladder.steps.append(measured(model, rung.effect, d))
        ladder.diagnoses.append(d)
    return ladder, first


def analyse_fleet(
    logs: Sequence[Any],
    client: Any,
    *,
    split: float = DEFAULT_SPLIT,
    read: Any = None,
    orders: Sequence | None = None,
    grid: Mapping[str, Any] | None = None,
    horizon: int | None = None,
    expect: str | None = None,
    max_steps: int = 3,
    initial: str = "zero",
    grow: bool | None = None,
    max_seconds: float | None = DEFAULT_GROWTH_SECONDS,
    **diagnose_kwargs: Any,
) -> FleetAnalysis:
    """Analyse a fleet of logs where they are, on a Dask cluster.

    Parameters
    ----------
    logs : sequence of IOData or file paths
        The logs (files are read by the workers, with ``read``).
    client : dask.distributed.Client
    split : float
        Estimation share of each log (its last ``1 - split`` validates; default 0.7).
    read : dict or callable, optional
        How to read file paths (see :func:`arxid.data.logs.load_experiment`).
    orders : (na, nb, nk), optional
        A fixed structure; else the fleet sweep over ``grid`` chooses it.
    grid : mapping with keys na, nb, nk, optional
        Sweep grid (missing keys take :data:`arxid.DEFAULT_GRID`), swept as given unless ``grow``.
    grow : bool or None
        Grow the grid while the choice sits on its edge and growing improves it, each larger grid
        swept where the logs are. None (default): the default grid grows, a given one does not
        (as :func:`arxid.analyse` in process).
    max_seconds : float or None
        Time budget of the grid search in seconds (default 30).
    horizon : int, optional
        Validation error measure: None = free run; k = k-step-ahead prediction.
    expect : {None, "stable", "integrating", "double-integrating"}
        What the physics says (the sweep's step sanity check).
    max_steps : int
        Largest number of effects the ladder adds.
    initial : {"zero", "estimate"}
        Initial conditions of every validation error (see :func:`arxid.compare`).
    **diagnose_kwargs
        Passed to the diagnosis (``candidates``, ``alpha``, ``min_improvement`` ...).

    Returns
    -------
    FleetAnalysis

    Raises
    ------
    ArxidError
        For a split outside (0, 1), or logs that cannot be read or differ in their signals.
    """
    if isinstance(split, bool) or not isinstance(split, (int, float)) or not 0 < split < 1:
        raise ArxidError(f"split must be the estimation fraction of each log between 0 and 1, got {split!r}")
    initial = check_initial(initial)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    on_workers = WorkerLogs(client, logs, read, 1.0 - float(split))
    timings["read"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    refits = FleetRefits(on_workers)
    options = {"horizon": horizon, "expect": expect, "read": read, "auto_extend": grow, "growth_seconds": max_seconds}
    res, model, choice, g = _structure(on_workers, logs, refits, orders, grid, options)
    timings["sweep"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    measure = res.horizon if res is not None else horizon
    ladder, first = fleet_ladder(model, on_workers, max_steps, measure, initial, diagnose_kwargs)
    timings["diagnose"] = time.perf_counter() - t0
    notes: tuple[str, ...] = (FLEET_ANALYSIS_NOTE,)
    if res is not None and res.integrating:
        notes += (f"The sweep found an integrating plant ({res.integrating_reason}).",)
    if not math.isfinite(first.diagnosis.rms_sim_val):
        notes += ("The chosen model's validation error is not finite.",)
    return FleetAnalysis(
        tuple(on_workers.names), g, res, choice, model, ladder.horizon, first.diagnosis, ladder, first, timings, notes
    )


FLEET_ANALYSIS["analyse"] = analyse_fleet
