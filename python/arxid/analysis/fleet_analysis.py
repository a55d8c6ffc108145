"""The analysis of a fleet of logs on a Dask cluster: ``arxid.analyse(logs, client=...)``.

The logs are read by the workers and stay there (:class:`arxid.fleet.cluster.WorkerLogs`); the last
``1 - split`` of each log validates. The structure comes from the given orders (fitted from the
shares' factors) or from the fleet sweep (``arxid.sweep(logs, client=...)``) and the in-process
choice (:func:`arxid.analysis.pipeline.choose`; its step sanity check and refit read the chosen
structure's data on the client, as a fleet sweep's result does). Then the diagnosis and the ladder
run on sufficient statistics where the logs are (:func:`arxid.diagnosis.cluster_records.diagnose_fleet`):
the same suspects, statistics and ladder errors as :func:`arxid.analyse` on the logs merged as
experiments of one IOData (``arxid.data.logs.merged_parts``) with the same orders, to rounding; and
which logs the missing effect shows in.

Differences from the in-process analysis, said in :attr:`FleetAnalysis.notes`: no comparison plots,
where-it-fails, frequency checks, bands, feedback test or residual tests (they need the whole
residual sequence on the client); the ladder keeps the chosen orders (in process a swept structure is
re-chosen as effects are added) and does not take out earlier effects a later one makes unnecessary.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from functools import partial
from typing import Any, cast

from .._base.formatting import text_table
from .._base.records import record
from ..diagnosis.cluster_records import ClusterRecords, FleetDiagnosis
from ..diagnosis.ladder import Ladder
from ..diagnosis.pooled_refits import PooledRefits
from ..exceptions import ArxidError
from ..fleet.cluster import WorkerLogs
from ..models.arx_model import ArxModel
from ..models.polynomial import check_initial
from ..selection.search import SweepResult, sweep
from .conclusion import Conclusion, concluded
from .pipeline import FLEET_ANALYSIS, Choice, OrderGrid, chosen_structure, measure_notes

__all__ = ["FleetAnalysis", "analyse_fleet", "FLEET_ANALYSIS_NOTE"]

#: What the analysis of a fleet does not do (see the module's docstring).
FLEET_ANALYSIS_NOTE = (
    "Fleet analysis on a Dask cluster: no comparison plots, where-it-fails, frequency checks, bands, feedback or "
    "residual tests; the ladder keeps the chosen orders and does not take out earlier effects."
)


@record(eq=False, kw_only=True)
class FleetAnalysis(Conclusion):
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
    fleet: FleetDiagnosis

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
        out = super().to_dict()
        out.update({"logs": list(self.logs), "fleet": self.fleet.to_dict(), "timings": dict(self.timings)})
        return out

    def _head_lines(self) -> list[str]:
        return [
            f"fleet of {len(self.logs)} logs analysed on the Dask cluster",
            f"model: {self.model.structure_name()} ({self.choice.reason})",
            self._validation_line(),
        ]

    def _evidence_lines(self) -> list[str]:
        """Which logs the missing effect shows in, and its test on each log."""
        lines = [self.fleet.sentence()]
        if self.fleet.evidence:
            rows = [[e.log, e.rows, e.score, e.f_statistic, e.p_adjusted, e.significant] for e in self.fleet.evidence]
            head = ["log", "rows", "partial corr.", "F", "p (Holm)", "shows it"]
            lines += ["", text_table(head, rows, title=f"{self.missing_effect} in each log:")]
        return lines

    def _tail_lines(self) -> list[str]:
        return ["", *self.notes]


def _structure(
    logs: WorkerLogs,
    sources: Sequence[Any],
    refits: PooledRefits,
    orders: Sequence | None,
    grid: Mapping | None,
    options: dict,
) -> tuple[SweepResult | None, ArxModel, Choice, OrderGrid | None]:
    """The chosen structure (:func:`~arxid.analysis.pipeline.chosen_structure`): the given orders
    fitted where the logs are, or the fleet sweep's choice."""
    m = len(logs.signals.input_names)

    def fit(na: Any, nb: Any, nk: Any) -> ArxModel:
        nbs = tuple(nb) if isinstance(nb, (list, tuple)) else (int(nb),) * m
        nks = tuple(nk) if isinstance(nk, (list, tuple)) else (int(nk),) * m
        return refits.fit(int(na), nbs, nks, ())

    swept = partial(sweep, cast(Any, list(sources)), client=logs.client, validation=logs.validation)
    return chosen_structure(orders, grid, fit, swept, options)


def fleet_ladder(
    model: ArxModel, logs: WorkerLogs, max_steps: int, horizon: int | None, initial: str, diagnose_kwargs: dict
) -> tuple[Ladder, FleetDiagnosis]:
    """:meth:`Ladder.run` (orders kept) on the fleet's records, and its first diagnosis with the logs
    the missing effect shows in.

    Parameters
    ----------
    model : ArxModel
    logs : WorkerLogs
    max_steps : int
    horizon : int or None
    initial : {"zero", "estimate"}
    diagnose_kwargs : dict
        Passed to :func:`arxid.diagnose`.

    Returns
    -------
    tuple of (Ladder, FleetDiagnosis)
    """
    records = ClusterRecords(logs)
    ladder = Ladder.run(model, records, max_steps=max_steps, horizon=horizon, initial=initial, **diagnose_kwargs)
    return ladder, records.evidence(ladder.diagnoses[0], 0)


def analyse_fleet(
    logs: Sequence[Any],
    client: Any,
    *,
    split: float,
    read: Any,
    orders: Sequence | None,
    grid: Mapping[str, Any] | None,
    horizon: int | None,
    expect: str | None,
    max_steps: int,
    initial: str,
    grow: bool | None,
    max_seconds: float | None,
    **diagnose_kwargs: Any,
) -> FleetAnalysis:
    """:func:`arxid.analyse` of a fleet of logs where they are, on a Dask cluster (``client=``).

    Parameters
    ----------
    logs, client, split, read, orders, grid, horizon, expect, max_steps, initial, grow, max_seconds
        As in :func:`arxid.analyse` (``logs`` its ``data``).
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
    refits = PooledRefits(on_workers)
    options = {"horizon": horizon, "expect": expect, "read": read, "auto_extend": grow, "growth_seconds": max_seconds}
    res, model, choice, g = _structure(on_workers, logs, refits, orders, grid, options)
    timings["sweep"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    measure = res.horizon if res is not None else horizon
    ladder, first = fleet_ladder(model, on_workers, max_steps, measure, initial, diagnose_kwargs)
    timings["diagnose"] = time.perf_counter() - t0
    notes = (FLEET_ANALYSIS_NOTE, *measure_notes(res, ladder.horizon, horizon))
    if not math.isfinite(first.diagnosis.rms_sim_val):
        notes += ("The chosen model's validation error is not finite.",)
    return FleetAnalysis(
        **concluded(g, res, choice, model, ladder, timings), logs=tuple(on_workers.names), fleet=first, notes=notes
    )


FLEET_ANALYSIS["analyse"] = analyse_fleet
