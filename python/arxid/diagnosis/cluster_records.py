"""The records of a diagnosis kept on a Dask cluster (a fleet's logs): :class:`ClusterRecords`
runs each stage of the one diagnosis (:func:`arxid.diagnose`, given these records) where the
logs are, and :func:`diagnose_fleet` adds which logs the missing effect shows in.

* Candidate scoring (step 2) from the shares' triangular factors (:mod:`~.statistics`).
* Refits (steps 3 to 5) from the shares' factors of each refit's regressors, and validation errors
  (free run or k steps ahead) simulated on each share's own logs, pooled from their sums
  (:mod:`~.pooled_refits`; a free run is not a statistic of the regressors).
* Everything else is the procedure's own: the baseline's rule, :class:`~.judge.Judge` (its refits
  done on the fleet, :class:`ClusterRefits`), :func:`~.judge.demote_pairs`, Holm's correction and the
  ranking.

The result equals :func:`arxid.diagnose` on the logs merged as experiments of one IOData (each log's
last share validating) to rounding, with these stages left out on a fleet, said in
:attr:`FleetDiagnosis.notes`: the residual tests and the slow-disturbance share of the baseline (they
need the whole residual sequence), the nonlinear-dependence table, threshold scans, shapes and the
search for two effects that hide each other. ``candidates="auto"`` is the union of the candidates
each share's logs suggest.

Which logs the missing effect shows in: the added-variable test of the top suspect on each log's own
rows (its partial correlation, F and p-value, Holm-corrected over the logs): :class:`LogEvidence`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._base.formatting import finite_or_none
from ..exceptions import ArxidError
from ..fleet.cluster import WorkerLogs
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel
from .added_variable import holm
from .candidates import auto_candidates
from .extension import Candidate, candidate_list
from .judge import Judge
from .pooled_refits import PooledRefits
from .result import Diagnosis
from .statistics import RegressorStatistics, combine_statistics, share_statistics
from .suspects import INTEGRATING_HORIZON, Baseline, baseline_errors, diagnose

__all__ = [
    "ClusterRecords",
    "FleetDiagnosis",
    "ClusterRefits",
    "LogEvidence",
    "diagnose_fleet",
    "diagnose_logs",
    "FLEET_NOTES",
]

#: What the diagnosis of a fleet leaves out (see the module's docstring).
FLEET_NOTES = (
    "On a fleet the residual tests, the slow-disturbance share, the nonlinear-dependence table and threshold "
    "scans are not computed (they need the whole residual sequence or the fleet's quantiles).",
)


class ClusterRefits:
    """:class:`~arxid.diagnosis.judge.CandidateRefits` on a fleet's logs: each refit fitted from the
    shares' factors and validated on the shares' own logs (:class:`PooledRefits`), the refits
    :meth:`~arxid.diagnosis.judge.Judge.suspects` makes done together (two round trips for all of
    them instead of two for each).

    Parameters
    ----------
    refits : PooledRefits
    model : ArxModel
    horizon : int or None
    """

    def __init__(self, refits: PooledRefits, model: ArxModel, horizon: int | None):
        self.refits, self.model, self.horizon = refits, model, horizon
        self._done: dict[tuple, Any] = {}

    def _key(self, model: ArxModel, c: Any, initial: str) -> tuple:
        effects = tuple(model.effects) + tuple(e for e in c.effects if e not in model.effects)
        return (id(model), c.na, tuple(c.nb), tuple(c.nk), effects, model.first_lag_, initial)

    def prepare(self, cands: Sequence[Candidate], simple: Sequence[Candidate], initial: str) -> None:
        """Every candidate refitted and validated in one batch (each simple explanation when it is compared)."""
        keys = [self._key(self.model, c, initial) for c in cands]
        structures = [(c.na, c.nb, c.nk, k[4], self.model.first_lag_) for c, k in zip(cands, keys)]
        self._done.update(zip(keys, self.refits.fit_many(structures, [("val", self.horizon, initial)])))

    def hold(self, cands: Sequence[Candidate]) -> None:
        """Nothing ahead: each pair is refitted when asked."""

    def validated(self, model: ArxModel, c: Any, initial: str) -> tuple[ArxModel, float]:
        """``model`` refitted with ``c`` on every log, and its pooled validation error.

        Parameters
        ----------
        model : ArxModel
        c : Candidate or Suspect
        initial : {"zero", "estimate"}

        Returns
        -------
        tuple of (ArxModel, float)
        """
        key = self._key(model, c, initial)
        out = self._done.pop(key, None)
        if out is None:
            out = self.refits.fit_many(
                [(c.na, c.nb, c.nk, key[4], model.first_lag_)], [("val", self.horizon, initial)]
            )[0]
        if isinstance(out, ArxidError):
            raise out
        fitted, (score,) = out
        return fitted, score.rms


@dataclass(frozen=True)
class LogEvidence:
    """The top suspect tested on one log's own rows.

    Attributes
    ----------
    log : str
    rows : int
        The model's regression rows in the log.
    score : float
        Partial correlation of the suspect's columns with the model's residual in this log (its
        square: the share of this log's residual energy it removes).
    f_statistic, p_value : float
        Its added-variable F-test on this log alone (NaN when the log cannot test it).
    p_adjusted : float
        Holm-corrected over the logs.
    significant : bool
        ``p_adjusted < alpha``.
    """

    log: str
    rows: int
    score: float
    f_statistic: float
    p_value: float
    p_adjusted: float
    significant: bool

    def to_dict(self) -> dict:
        """JSON-ready.

        Returns
        -------
        dict
        """
        return {
            "log": self.log,
            "rows": self.rows,
            "score": finite_or_none(self.score),
            "f_statistic": finite_or_none(self.f_statistic),
            "p_value": finite_or_none(self.p_value),
            "p_adjusted": finite_or_none(self.p_adjusted),
            "significant": self.significant,
        }


@dataclass(frozen=True, eq=False)
class FleetDiagnosis:
    """The diagnosis of a fleet: the :class:`~arxid.Diagnosis` of the merged logs, and the logs the
    top suspect shows in.

    Attributes
    ----------
    diagnosis : Diagnosis
        As :func:`arxid.diagnose` on the merged logs gives it (without residual tests).
    evidence : tuple of LogEvidence
        The top suspect tested on each log (empty when nothing is significant).
    notes : tuple of str
        What the fleet's diagnosis left out.
    """

    diagnosis: Diagnosis
    evidence: tuple[LogEvidence, ...] = ()
    notes: tuple[str, ...] = FLEET_NOTES

    @property
    def logs_with_effect(self) -> tuple[str, ...]:
        """The logs where the top suspect is significant on their own."""
        return tuple(e.log for e in self.evidence if e.significant)

    def sentence(self) -> str:
        """Which logs the missing effect shows in, as one plain sentence.

        Returns
        -------
        str
        """
        top = self.diagnosis.top
        if top is None:
            return "No missing effect is significant on the fleet, so no log is singled out."
        n, shown = len(self.evidence), self.logs_with_effect
        alpha = self.diagnosis.alpha
        how = f"its added-variable F-test on each log's own data, p < {alpha:g} after Holm's correction over the logs"
        if not shown:
            alone = f"none of the {n} logs alone ({how}): only the fleet reveals it"
            return f"The missing effect {top.effect} shows in {alone}."
        listed = ", ".join(shown)
        return f"The missing effect {top.effect} shows in {len(shown)} of the {n} logs ({how}): {listed}."

    def to_dict(self) -> dict:
        """JSON-ready: the logs' evidence, the sentence and the notes.

        Returns
        -------
        dict
        """
        top = self.diagnosis.top
        return {
            "effect": None if top is None else top.effect,
            "logs": [e.to_dict() for e in self.evidence],
            "logs_with_effect": list(self.logs_with_effect),
            "sentence": self.sentence(),
            "notes": list(self.notes),
        }


class _Done:
    """A result already made (the pooled baseline), read as the in-process one is awaited."""

    def __init__(self, value: Any):
        self.value = value

    def result(self) -> Any:
        return self.value


def _auto_labels(share: tuple, model: ArxModel, loop_signals: tuple[str, ...]) -> list[str]:
    return list(auto_candidates(model, share[0], loop_signals))


class ClusterRecords:
    """A fleet's logs read by the workers of a Dask cluster, each stage of the diagnosis run there.

    Parameters
    ----------
    logs : WorkerLogs
        Read with a validation share (``validation=`` fraction).

    Attributes
    ----------
    statistics : list of RegressorStatistics
        Each scoring's statistics, in order (each log's factor: which logs the missing effect shows in).
    """

    here = False  # the samples stay on the workers
    same = False

    def __init__(self, logs: WorkerLogs):
        self.logs = logs
        self.refits = PooledRefits(logs)
        self.estimation, validation = logs.on_demand()
        self.head = logs.head
        self.validation: Any = validation
        self.statistics: list[RegressorStatistics] = []

    def check(self, model: ArxModel) -> None:
        """ARX models only, on logs read with a validation share."""
        if isinstance(model, PolynomialModel):
            raise ArxidError("the diagnosis of a fleet refits ARX models only; give an ARX model (or orders)")
        if self.logs.validation is None:
            raise ArxidError(
                "the diagnosis of a fleet needs each log's validation share: read the logs with validation=0.3"
            )

    def baseline(self, model: ArxModel, horizon: int | None, initial: str, max_lag: int) -> _Done:
        """The baseline from pooled scores (one round trip for every error its rule may ask)."""
        asked = [(None, "zero"), (horizon, initial), (1, "zero"), (INTEGRATING_HORIZON, initial)]
        got = dict(zip(asked, self.refits.scores(model, [("val", k, i) for k, i in asked])))
        too_short = (
            f"the validation parts of the logs are too short for a prediction by {model.structure_name()}; "
            "hold out a larger share of each log"
        )
        rms = lambda k, i: (got[k, i].rms, got[k, i].diverged)  # noqa: E731
        at, base_rms = baseline_errors(model, horizon, initial, rms, lambda k, i: got[k, i].fit, too_short)
        return _Done(Baseline(at, base_rms, got[1, "zero"].rms, got[at, initial].fit))

    def candidates(
        self, candidates: str | Sequence[str], model: ArxModel, loop_signals: tuple[str, ...]
    ) -> tuple[list[Candidate], bool]:
        """The candidates, parsed against the logs' signals; ``"auto"``: those any share's logs suggest."""
        auto = isinstance(candidates, str)
        if auto:
            if candidates != "auto":
                raise ArxidError(f"candidates must be 'auto' or a list of effect strings, got {candidates!r}")
            labels: list[str] = []
            for share in self.logs.client.gather(self.logs.each(_auto_labels, model, loop_signals)):
                labels += [lab for lab in share if lab not in labels]
            candidates = labels
        cands, _ = candidate_list(candidates, model, self.logs.head)
        return cands, auto

    def scoring(self, model: ArxModel, cands: list[Candidate]) -> RegressorStatistics:
        """The factors of the model's regressors and its candidates' columns, per log, from the workers."""
        logs = self.logs
        outs = logs.client.gather(logs.each(share_statistics, model, cands, "const" not in model.effects))
        order = [j for group in logs.groups for j in group]
        self.statistics.append(combine_statistics(model, cands, outs, order, logs.signals))
        return self.statistics[-1]

    def evidence(self, d: Diagnosis, i: int = -1) -> FleetDiagnosis:
        """``d`` (the ``i``-th diagnosis of these records) with the logs its top suspect shows in.

        Parameters
        ----------
        d : Diagnosis
        i : int

        Returns
        -------
        FleetDiagnosis
        """
        return FleetDiagnosis(d, _evidence(self.statistics[i], d, self.logs.names, d.alpha))

    def measure(self, model: ArxModel, horizon: int | None, initial: str) -> tuple[float, float]:
        """As :meth:`arxid.diagnosis.suspects.Records.measure`, pooled over the logs (one round trip)."""
        score = self.refits.scores(model, [("val", horizon, initial)])[0]
        return score.rms, score.fit

    def judge(
        self, model: ArxModel, horizon: int | None, base_rms: float, min_improvement: float, initial: str
    ) -> Judge:
        """The judge refitting on the workers."""
        where = ClusterRefits(self.refits, model, horizon)
        return Judge(model, self.estimation, self.validation, horizon, base_rms, min_improvement, initial, where)


def diagnose_fleet(model: ArxModel, logs: WorkerLogs, **options: Any) -> FleetDiagnosis:
    """:func:`arxid.diagnose` of a fleet of logs kept on a Dask cluster (the same procedure,
    :func:`arxid.diagnose` given :class:`ClusterRecords`), with the logs the top suspect shows in.

    Parameters
    ----------
    model : ArxModel
        A fitted ARX model (its rows start ``model.first_lag_`` into each log).
    logs : WorkerLogs
        The fleet, read by the workers with a validation share (``validation=`` fraction).
    **options
        As in :func:`arxid.diagnose` (``candidates``, ``horizon``, ``alpha`` ...).

    Returns
    -------
    FleetDiagnosis

    Raises
    ------
    ArxidError
        For a polynomial model, or logs read without a validation share.
    """
    records = ClusterRecords(logs)
    return records.evidence(diagnose(model, records, **options))


def diagnose_logs(
    model: ArxModel, logs: Sequence[Any], client: Any, *, split: float = 0.7, read: Any = None, **options: Any
) -> FleetDiagnosis:
    """:func:`diagnose_fleet` of a list of logs: the workers of ``client`` read them (``read`` as in
    :func:`arxid.data.logs.load_experiment`) and hold out the last ``1 - split`` of each for validation.

    Parameters
    ----------
    model : ArxModel
        A fitted ARX model (for example ``arxid.arx(logs, 2, 2, 1, client=client)``).
    logs : sequence of IOData or file paths
    client : dask.distributed.Client
    split : float
        Estimation share of each log.
    read : dict or callable, optional
    **options
        As in :func:`arxid.diagnose`.

    Returns
    -------
    FleetDiagnosis
    """
    if isinstance(split, bool) or not isinstance(split, (int, float)) or not 0 < split < 1:
        raise ArxidError(f"split must be the estimation fraction of each log between 0 and 1, got {split!r}")
    if options.pop("validation", None) is not None:
        raise ArxidError("on a fleet each log's last share validates: give no validation= with client=")
    return diagnose_fleet(model, WorkerLogs(client, logs, read, 1.0 - float(split)), **options)


def _evidence(stats: RegressorStatistics, d: Diagnosis, names: Sequence[str], alpha: float) -> tuple[LogEvidence, ...]:
    """The top suspect's added-variable test on each log alone, Holm-corrected over the logs."""
    top = d.top
    if top is None:
        return ()
    if top.effect in stats.own:
        return _logs_of(stats.per_log_own(top.effect), stats.own[top.effect][1], names, alpha)
    parts = [p for p in top.effect.split("+") if p]
    labels = (
        [top.effect]
        if top.effect in stats.columns
        else [p if p != "const" or p in stats.columns else "" for p in parts]
    )
    if not all(lab in stats.columns for lab in labels):
        return ()
    idx = np.concatenate([stats.index(lab) for lab in labels])
    return _logs_of(stats.per_log(idx), stats.rows, names, alpha)


def _logs_of(tests: list, rows: Sequence[int], names: Sequence[str], alpha: float) -> tuple[LogEvidence, ...]:
    """Each log's test as evidence, Holm-corrected over the logs."""
    p = np.array([t.p_value if t is not None else 1.0 for t in tests])
    adj = holm(p)
    nan = math.nan
    return tuple(
        LogEvidence(
            name,
            n,
            t.score if t else nan,
            t.f_statistic if t else nan,
            t.p_value if t else nan,
            float(pa) if t else nan,
            bool(t is not None and pa < alpha),
        )
        for name, n, t, pa in zip(names, rows, tests, adj)
    )
