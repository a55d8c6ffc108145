"""The error ladder: models as effects are added, with the validation error at each step.

:meth:`Ladder.run` adds the best significant physical effect that :func:`arxid.diagnose` finds,
re-diagnoses, and repeats until nothing significant is left, so the user watches the error fall
step by step. The rungs are physical effects: a structure change (``nb+1``) stands on its own only
when no effect is significant, and with ``restructure=True`` the orders are re-chosen around the
current ones each time an effect is added (:mod:`arxid.diagnosis.restructure`); the rung then says
how the structure changed.
"""

from __future__ import annotations

import math
from dataclasses import field, replace
from typing import Any

import numpy as np

from .._base.formatting import finite_or_none, horizon_label, require_pandas, text_table
from .._base.records import record
from ..checks import error_rms
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arguments import check_horizon, check_model
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel, check_initial
from ..models.wiener import WienerModel, added_effects
from .candidates import physics
from .restructure import linear_name, order_change, rechoose_structure
from .result import Diagnosis, Suspect
from .suspects import OneRecord, Records, diagnose

__all__ = ["Ladder", "LadderStep", "next_rung"]


@record(eq=False)
class LadderStep:
    """One rung: the model after adding ``added`` and its validation error.

    Attributes
    ----------
    added : str
        What this step added (``""`` for the starting model).
    model : ArxModel
    effects : tuple of str
        All effects of the model at this step.
    structure : str
        e.g. ``ARX(2,2,1) + y^3``.
    rms_sim_val : float
        Validation error at ``horizon`` (None = free run).
    fit_val : float
        Validation fit percent at ``horizon``.
    horizon : int or None
    physics : str
        What the added candidate stands for (``"Coulomb friction on a speed output"``).
    approximation_of : str
        Set when a later step found the better explanation: this step's effect only approximated
        it and was taken out of the model then (``"y^3"`` approximating ``"sign(y)"``).
    replaces : tuple of str
        Effects of earlier steps this step's effect made unnecessary (they approximated it).
    restructured : str
        Set when the structure was re-chosen once ``added`` was in the model: how the orders
        changed (``"nb+1"``; ``""`` when they did not).
    rms_before_restructure : float
        Validation error of the model with ``added`` at the structure before it was re-chosen
        (NaN when it was not).
    """

    added: str
    model: ArxModel = field(repr=False)
    effects: tuple[str, ...]
    structure: str
    rms_sim_val: float
    fit_val: float
    horizon: int | None
    physics: str = ""
    approximation_of: str = ""
    replaces: tuple[str, ...] = ()
    restructured: str = ""
    rms_before_restructure: float = math.nan

    def label(self) -> str:
        """What the step added, with the approximation, replacement or new structure said in words.

        Returns
        -------
        str
            e.g. ``"y^3 (approximated sign(y))"``, ``"sign(y) (replaces y^3)"``,
            ``"u1*vbat, and the structure became ARX(4,2,5)"``, ``"(start)"``.
        """
        text = self.added or "(start)"
        if self.approximation_of:
            text += f" (approximated {self.approximation_of})"
        if self.replaces:
            text += f" (replaces {', '.join(self.replaces)})"
        if self.restructured:
            text += f", and the structure became {linear_name(self.model)}"
        return text

    def to_dict(self) -> dict:
        """One step of :meth:`Ladder.to_list`.

        Returns
        -------
        dict
            ``added``, ``structure``, ``effects``, ``rms_sim_val``, ``fit_val``, ``physics``,
            ``approximation_of``, ``replaces``, ``restructured`` (the change of orders made when
            the structure was re-chosen, None when it was not) and ``rms_before_restructure``.
        """
        return {
            "added": self.added,
            "structure": self.structure,
            "effects": list(self.effects),
            "rms_sim_val": finite_or_none(float(self.rms_sim_val)),
            "fit_val": finite_or_none(float(self.fit_val)),
            "physics": self.physics,
            "approximation_of": self.approximation_of,
            "replaces": list(self.replaces),
            "restructured": self.restructured or None,
            "rms_before_restructure": finite_or_none(float(self.rms_before_restructure)),
        }


class Ladder:
    """The sequence of models as effects are added, with the validation error at each step.

    Build it by hand with :meth:`add`, or greedily with :meth:`run`, which adds the best significant
    suspect of :func:`diagnose` until nothing significant is left.

    Parameters
    ----------
    validation : IOData, optional
        Data every step is measured on; default: that of the first :meth:`add`, else the first
        model's estimation data.
    horizon : int, optional
        Validation error measure: None = free-run simulation; k = k-step-ahead prediction.
    initial : {"zero", "estimate"}
        Initial conditions of the validation error: ``"zero"`` (default) starts each free run from
        the measured outputs; ``"estimate"`` fits them first (see :func:`arxid.compare`).

    Attributes
    ----------
    steps : list of LadderStep
        The models in the order they were added.
    diagnoses : list of Diagnosis
        The diagnoses :meth:`run` made (empty for a ladder built by hand).

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(0.5, 1.5, 3000)
    >>> y = np.zeros(3000)
    >>> for t in range(1, 3000):
    ...     y[t] = 0.8 * y[t - 1] + 0.5 * u[t - 1] ** 2 + 0.01 * rng.standard_normal()
    >>> est, val = arxid.IOData(y, u, ts=0.01).split(0.6)
    >>> ladder = arxid.Ladder.run(arxid.arx(est, 1, 1, 1), est, val)
    >>> [s.added for s in ladder.steps][:2]
    ['', 'through(u1^2.005)']
    """

    def __init__(self, validation: IOData | None = None, horizon: int | None = None, initial: str = "zero"):
        self.validation = validation
        self.horizon = check_horizon(horizon)
        self.initial = check_initial(initial)
        self.steps: list[LadderStep] = []
        self.diagnoses: list[Diagnosis] = []
        #: The records :meth:`run` diagnoses, when given as such (a fleet's logs on a cluster): every
        #: step is measured where they are.
        self.records: Records | None = None

    def add(
        self,
        model: ArxModel,
        added: str = "",
        validation: IOData | None = None,
        *,
        settle: bool = False,
        min_improvement: float = 0.05,
        rechosen_from: ArxModel | None = None,
    ) -> LadderStep:
        """Record ``model`` as the next step, measured on ``validation`` (default: the ladder's).

        Parameters
        ----------
        model : ArxModel
            A fitted model.
        added : str
            What this step added (an effect or a structure change; ``""`` for the starting model).
        validation : IOData, optional
            Data to measure this step on; default the ladder's, else the model's estimation data
            (the first data given become the ladder's).
        settle : bool
            Check whether the effects earlier steps added are still needed beside ``added``: one
            whose removal raises the error by less than ``min_improvement`` only approximated the
            new effect; it is taken out of the model and its step labelled an approximation.
        min_improvement : float
            Relative fall of the validation error an earlier effect must still bring (0.05 = 5%).
        rechosen_from : ArxModel, optional
            The model with ``added`` at the structure before it was re-chosen: the step records
            how the orders changed and that model's validation error.

        Returns
        -------
        LadderStep
            The new step, with its validation RMS and fit percent at the ladder's ``horizon``.

        Raises
        ------
        ArxidError
            When there are no data to measure on.
        """
        model = check_model(model)
        val = validation if validation is not None else self.validation
        if val is None:
            val = model.data_
        if val is None:
            raise ArxidError("give validation data: Ladder(validation) or add(model, validation=...)")
        self.validation = self.validation if self.validation is not None else val
        replaces: tuple[str, ...] = ()
        if settle and added and self.steps:
            model, replaces = self._settle(model, added, val, min_improvement)
        step = self._step(model, added, val, replaces)
        if rechosen_from is not None and order_change(rechosen_from, model):
            before = error_rms(rechosen_from, val, self.horizon, self.initial)
            step = replace(step, restructured=order_change(rechosen_from, model), rms_before_restructure=before)
        self.steps.append(step)
        return step

    def _step(self, model: ArxModel, added: str, val: IOData, replaces: tuple[str, ...]) -> LadderStep:
        where = self.records if self.records is not None else OneRecord(val, val)  # measured where they are
        rms, fit = where.measure(model, self.horizon, self.initial)
        data = model.data_ if model.data_ is not None else where.head
        return LadderStep(
            added,
            model,
            added_effects(model),  # a sensor step's effects differ from the step before: its kind is "effect"
            model.structure_name(),
            rms,
            fit,
            self.horizon,
            model.sensor.physics() if isinstance(model, WienerModel) else physics(added, data) if added else "",
            replaces=replaces,
        )

    def _settle(
        self, model: ArxModel, added: str, val: IOData, min_improvement: float
    ) -> tuple[ArxModel, tuple[str, ...]]:
        """Take out the earlier effects that ``added`` makes unnecessary; label their steps (ARX
        models; a polynomial model's effects are inputs with their own dynamics and stay)."""
        if not isinstance(model, ArxModel):
            return model, ()
        new = set(added.split("+"))
        replaced = []
        for i, step in enumerate(self.steps):
            earlier = tuple(e for e in step.added.split("+") if e in model.effects and e not in new)
            if not step.added or step.approximation_of or not earlier:
                continue
            without = [e for e in model.effects if e not in earlier]
            if model.data_ is None:
                break
            try:
                reduced = ArxModel(na=model.na_, nb=model.nb_, nk=model.nk_, effects=without).fit(
                    model.data_, first_lag=model.first_lag_
                )
                before = error_rms(reduced, val, self.horizon, self.initial)
                after = error_rms(model, val, self.horizon, self.initial)
            except ArxidError:
                continue
            if math.isfinite(before) and after > (1.0 - min_improvement) * before:
                self.steps[i] = replace(step, approximation_of=added)
                replaced += list(earlier)
                model = reduced
        return model, tuple(replaced)

    @classmethod
    def run(
        cls,
        model: ArxModel,
        data: IOData | Records | None = None,
        validation: IOData | None = None,
        *,
        max_steps: int = 3,
        horizon: int | None = None,
        initial: str = "zero",
        restructure: bool = False,
        expect: str | None = None,
        **diagnose_kwargs,
    ) -> Ladder:
        """Greedy ladder: diagnose, add the best significant physical effect, repeat.

        Each rung adds the significant suspect of :func:`diagnose` with the lowest validation
        error among the physical effects (and pairs); a structure change (``na+1``, ``nb+1``,
        ``nk-1`` ...) is a rung of its own only when no effect is significant.

        Parameters
        ----------
        model : ArxModel
            Starting model.
        data, validation : IOData
            Estimation and validation data (see :func:`diagnose`); or the records of a fleet as
            ``data`` (:class:`arxid.diagnosis.cluster_records.ClusterRecords`: every step is
            diagnosed and measured where the logs are, and no earlier effect is taken out).
        max_steps : int
            Largest number of suspects added.
        horizon : int or None
            Validation error measure (the first diagnosis may switch a free run to k-step for an
            integrating plant; the whole ladder then uses that horizon).
        initial : {"zero", "estimate"}
            Initial conditions of every validation error, the diagnoses' included (see
            :func:`arxid.compare`); default ``"zero"``.
        restructure : bool
            Re-choose the orders around the current ones each time an effect is added
            (:func:`arxid.diagnosis.restructure.rechoose_structure`; ARX models). Default False:
            the starting model's orders are kept (a structure change is then a rung of its own).
        expect : {None, "stable", "integrating", "double-integrating"}
            What the step sanity check of a re-chosen structure assumes (the sweep's expectation).
        **diagnose_kwargs
            Passed to :func:`diagnose` (``candidates``, ``alpha``, ``min_improvement`` ...).

        Returns
        -------
        Ladder
            ``steps`` (the starting model first) and the ``diagnoses`` made along the way.
        """
        model = check_model(model)
        data = data if data is not None else model.data_
        d = diagnose(model, data, validation, horizon=horizon, initial=initial, **diagnose_kwargs)
        ladder = cls(d.validation, d.horizon, initial)
        if isinstance(data, Records):
            ladder.records = data
        ladder.add(model)
        ladder.diagnoses.append(d)
        for _ in range(int(max_steps)):
            rung = next_rung(d)
            if rung is None:
                break
            model = d.apply(rung.effect)
            if rung.kind == "sensor":  # every other candidate acts before the sensor: the ladder ends here
                ladder.steps.append(ladder._step(model, rung.effect, d.validation, ()))
                break
            rechosen_from = None
            if restructure and rung.kind != "dynamics" and not isinstance(model, PolynomialModel):
                choice = rechoose_structure(
                    model,
                    d.data,
                    d.validation,
                    d.horizon,
                    initial=ladder.initial,
                    expect=expect,
                    min_improvement=d.min_improvement,
                )
                model, rechosen_from = choice.model, (model if choice.changed else None)
            step = ladder.add(
                model, rung.effect, settle=True, min_improvement=d.min_improvement, rechosen_from=rechosen_from
            )
            model = step.model
            d = diagnose(model, data, validation, horizon=d.horizon, initial=initial, **diagnose_kwargs)
            ladder.diagnoses.append(d)
        # What the ladder leaves unexplained is part of its answer: the last diagnosis's dependence
        # test runs now, not when first shown (those of the diagnoses stepped past run if read).
        _ = d.nonlinear_dependence
        return ladder

    @property
    def final_model(self) -> ArxModel:
        """The model of the last step (raises :class:`~arxid.ArxidError` when the ladder is empty)."""
        if not self.steps:
            raise ArxidError("the ladder is empty")
        return self.steps[-1].model

    @property
    def errors(self) -> np.ndarray:
        """Validation RMS of every step, shape (n_steps,)."""
        return np.array([s.rms_sim_val for s in self.steps])

    def __len__(self) -> int:
        return len(self.steps)

    def __str__(self) -> str:
        rows = []
        first = self.steps[0].rms_sim_val if self.steps else math.nan
        for i, s in enumerate(self.steps):
            change = f"{100 * (s.rms_sim_val / first - 1):+.1f}%" if i and math.isfinite(first) and first > 0 else ""
            rows.append((i, s.label(), s.physics, s.structure, s.rms_sim_val, s.fit_val, change))
        text = f"error ladder (validation error, {horizon_label(self.horizon)})\n" + text_table(
            ["step", "added", "physics", "model", "rms", "fit %", "vs start"], rows
        )
        return text + (f"\n{self.unexplained}" if self.unexplained else "")

    @property
    def unexplained(self) -> str:
        """The last diagnosis's sentence for what no candidate explains: an unlogged disturbance with
        its low-frequency share of the error, a nonlinear dependence (``""`` if none, or while a
        suspect is still significant)."""
        return self.diagnoses[-1].unexplained if self.diagnoses else ""

    def __repr__(self) -> str:
        return f"<Ladder {len(self.steps)} steps: " + " -> ".join(s.added or "start" for s in self.steps) + ">"

    def to_list(self) -> list[dict]:
        """The CLI contract: one ``{"added", "structure", "effects", "rms_sim_val", "fit_val"}`` per step,
        plus the keys of :meth:`step_details`.

        Returns
        -------
        list of dict
            With ``physics``, ``approximation_of`` and ``replaces`` too (:meth:`LadderStep.to_dict`).
        """
        return [{**s.to_dict(), **self.step_details(i)} for i, s in enumerate(self.steps)]

    def to_dict(self) -> dict:
        """JSON-ready dict: the horizon and the steps.

        Returns
        -------
        dict
            ``{"horizon": int or None, "steps": [...]}``, the steps as in :meth:`to_list`, and for a
            ladder built by :meth:`run` ``nonlinear_dependence`` of its last diagnosis (what it leaves
            unexplained, with the remaining disturbance).
        """
        out: dict = {"horizon": self.horizon, "steps": self.to_list(), "error_fall": self.error_fall()}
        if self.diagnoses:
            out["nonlinear_dependence"] = self.diagnoses[-1].dependence_dict()
        return out

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None
            Indentation of the JSON; None writes one line.

        Returns
        -------
        str
        """
        import json

        return json.dumps(self.to_dict(), indent=indent)

    def to_pandas(self):
        """One row per step: what was added, the structure, validation RMS and fit.

        Returns
        -------
        pandas.DataFrame
            Columns ``added``, ``structure``, ``rms_sim_val``, ``fit_val``.
        """
        pd = require_pandas()
        return pd.DataFrame(
            [
                {"added": s.added, "structure": s.structure, "rms_sim_val": s.rms_sim_val, "fit_val": s.fit_val}
                for s in self.steps
            ]
        )

    def step_kind(self, i: int) -> str:
        """What step ``i`` changed: ``"start"``, ``"effect"`` (its effects differ from the step
        before) or ``"structure"`` (only na, nb or nk changed).

        Parameters
        ----------
        i : int
            Step index.

        Returns
        -------
        str
        """
        if i == 0:
            return "start"
        return "effect" if self.steps[i].effects != self.steps[i - 1].effects else "structure"

    def step_details(self, i: int) -> dict:
        """The JSON keys a step adds to ``added``/``structure``/``effects``: ``kind`` (see
        :meth:`step_kind`), ``orders`` (``na``, ``nb``, ``nk``, ``effects``) and ``fall`` (share of the
        starting error this step removed, None for the start).

        Parameters
        ----------
        i : int
            Step index.

        Returns
        -------
        dict
        """
        s = self.steps[i]
        m = s.model
        first = self.steps[0].rms_sim_val
        fall = None
        if i and math.isfinite(first) and first > 0 and math.isfinite(s.rms_sim_val):
            fall = float((self.steps[i - 1].rms_sim_val - s.rms_sim_val) / first)
        return {
            "kind": self.step_kind(i),
            "orders": {"na": int(m.na_), "nb": list(m.nb_), "nk": list(m.nk_), "effects": list(s.effects)},
            "fall": finite_or_none(fall) if fall is not None else None,
        }

    def error_fall(self) -> dict:
        """How much of the starting validation error the ladder removed, split by what the steps added.

        A step that added an effect and re-chose the structure counts twice: the fall to the
        error of the effect at the old structure is the effect's, the rest the structure's.

        Returns
        -------
        dict
            ``total``, ``effects`` (steps that added an effect), ``structure`` (steps that changed
            na, nb or nk, and re-chosen structures): shares of the first step's error (0.9 = 90 %),
            None when undefined; ``added_effects`` and ``structure_changes``: the names added by
            each kind of step (a re-chosen structure by its change of orders, ``"nb+1"``).
        """
        parts = {"effect": 0.0, "structure": 0.0}
        names: dict[str, list[str]] = {"effect": [], "structure": []}
        first = self.steps[0].rms_sim_val if self.steps else math.nan
        for i in range(1, len(self.steps)):
            d, step = self.step_details(i), self.steps[i]
            kind = d["kind"]
            fall = d["fall"] if d["fall"] is not None else math.nan
            names[kind].append(step.added)
            if step.restructured:
                by_structure = (step.rms_before_restructure - step.rms_sim_val) / first
                parts["structure"] += by_structure
                names["structure"].append(step.restructured)
                fall -= by_structure
            parts[kind] += fall
        ok = len(self.steps) > 1 and all(math.isfinite(v) for v in parts.values())
        return {
            "total": finite_or_none(parts["effect"] + parts["structure"]) if ok else None,
            "effects": finite_or_none(parts["effect"]) if ok else None,
            "structure": finite_or_none(parts["structure"]) if ok else None,
            "added_effects": names["effect"],
            "structure_changes": names["structure"],
        }

    def plot(self, ax: Any = None) -> Any:
        """Validation error per step (the error falling).

        Parameters
        ----------
        ax : Axes, optional

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_ladder

        return plot_ladder(self, ax=ax)


def next_rung(d: Diagnosis) -> Suspect | None:
    """The suspect the ladder adds next: the significant physical effect (or pair) with the lowest
    validation error; a structure change only when no effect is significant.

    Parameters
    ----------
    d : Diagnosis

    Returns
    -------
    Suspect or None
        None when nothing is significant.
    """
    significant = [s for s in d.suspects if s.significant]  # ranked, the lowest validation error first
    effects = [s for s in significant if s.kind != "dynamics"]
    ranked = effects or significant
    return ranked[0] if ranked else None
