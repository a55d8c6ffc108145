"""The analysis of a state-space model of several inputs and outputs: :func:`analyse_state_space`
→ :class:`StateSpaceAnalysis`, what ``arxid ssest`` prints and its report renders.

It estimates the model by subspace identification on the estimation data, then checks each output
on the validation data as a single-output model is checked: its fit, its residual tests and where
its error is large; and it measures the cross-coupling of the inputs and outputs. With
``diagnose=True`` it also searches each output for a missing effect (:func:`arxid.diagnose`).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from typing import Any

from .._base.formatting import finite_or_none, horizon_label, json_safe, text_table
from ..checks import Comparison, FailureAnalysis, ResidualAnalysis, compare, residuals, where_it_fails
from ..data.iodata import IOData
from ..diagnosis.result import Diagnosis
from ..diagnosis.suspects import diagnose as diagnose_model
from ..exceptions import ArxidError
from ..models.arguments import check_data, check_horizon
from ..models.polynomial import check_initial
from ..models.state_space import StateSpaceModel
from ..models.subspace import ssest
from .coupling import Coupling, coupling
from .pipeline import DEFAULT_SPLIT
from .verdicts import negative_fit_note

__all__ = ["StateSpaceAnalysis", "analyse_state_space", "NO_EFFECT_SEARCH"]

#: The line every state-space analysis carries about the diagnosis it does not run.
NO_EFFECT_SEARCH = (
    "No search for a missing effect in this analysis: ask for it with diagnose=True (arxid ssest --diagnose), "
    "or run arxid.diagnose(model, estimation, validation), which tests candidate terms on each output."
)


@dataclass(frozen=True, eq=False)
class StateSpaceAnalysis:
    """A state-space model and its checks, per output, on validation data.

    Attributes
    ----------
    model : StateSpaceModel
        Estimated on ``estimation``.
    estimation, validation : IOData
    comparisons : dict of str to Comparison
        Each output's measured against predicted validation samples.
    residual_tests : dict of str to ResidualAnalysis
        Each output's one-step residual tests (empty when the validation data are too short).
    failures : dict of str to FailureAnalysis
        Where each output's error is large, in time and by operating point.
    coupling : Coupling
        The gains of every input → output path.
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction.
    initial : str
        Initial state of each validation stretch (``"estimate"`` or ``"zero"``).
    notes : tuple of str
        What the analysis did not do, and why.
    timings : dict of str to float
        Seconds per step.
    diagnoses : dict of str to Diagnosis
        Each output's search for a missing effect (empty unless asked for).
    """

    model: StateSpaceModel
    estimation: IOData
    validation: IOData
    comparisons: dict[str, Comparison]
    residual_tests: dict[str, ResidualAnalysis]
    failures: dict[str, FailureAnalysis]
    coupling: Coupling
    horizon: int | None
    initial: str
    notes: tuple[str, ...]
    timings: dict[str, float]
    diagnoses: dict[str, Diagnosis] = field(default_factory=dict)

    @property
    def fit_percent(self) -> dict[str, float]:
        """Validation fit of each output in percent (100 is perfect)."""
        return {name: c.fit_percent[0] for name, c in self.comparisons.items()}

    def output_rows(self) -> list[list[Any]]:
        """One row per output: name, validation fit, RMS, whiteness, dependence on inputs, and the
        input that drives it most.

        Returns
        -------
        list of list
        """
        rows = []
        for name, c in self.comparisons.items():
            rt = self.residual_tests.get(name)
            dependent = [] if rt is None else [k for k, ok in rt.independent.items() if not ok]
            rows.append(
                [
                    name,
                    c.fit_percent[0],
                    c.rms[0],
                    "untested" if rt is None else ("yes" if rt.is_white else "no"),
                    "untested" if rt is None else (", ".join(dependent) or "none"),
                    self.coupling.strongest_input(name),
                ]
            )
        return rows

    def summary_lines(self) -> list[str]:
        """The analysis as text: the model, each output's checks, the coupling and the notes.

        Returns
        -------
        list of str
        """
        head = ["output", "fit %", "RMS", "residual white", "residual follows", "driven most by"]
        lines = [
            str(self.model),
            "",
            f"validation ({self.validation.n_samples} samples, {horizon_label(self.horizon)}, "
            f"initial state {'estimated' if self.initial == 'estimate' else 'zero'}):",
            text_table(head, self.output_rows()),
        ]
        lines += [f"({note})" for note in map(negative_fit_note, self.fit_percent.values()) if note][:1]
        lines += ["", str(self.coupling)]
        lines += ["", *self.effect_lines()] if self.diagnoses else []
        return lines + ["", *self.notes]

    def effect_lines(self) -> list[str]:
        """One line per output: the missing effect found, with the validation error before and after.

        Returns
        -------
        list of str
        """
        lines = ["missing effects (validation error before -> after):"]
        for name, d in self.diagnoses.items():
            top = d.top
            if top is None:
                lines.append(f"  {name}: none found ({d.rms_sim_val:.4g})")
            else:
                lines.append(f"  {name}: {top.effect} ({d.rms_sim_val:.4g} -> {top.rms_sim_val_after:.4g})")
        return lines

    def to_dict(self) -> dict:
        """JSON-ready summary: the model's shape and order choice, per-output checks, coupling.

        Returns
        -------
        dict
        """
        m = self.model
        return json_safe(
            {
                "model": {
                    "method": m.method,
                    "order": m.order,
                    "order_fixed": m.order_fixed,
                    "inputs": list(m.input_names),
                    "outputs": list(m.output_names),
                    "ts": m.ts,
                    "stable": m.is_stable,
                    "singular_values": [float(v) for v in m.singular_values],
                    "order_criterion": [finite_or_none(float(v)) for v in m.order_criterion],
                },
                "horizon": self.horizon,
                "initial": self.initial,
                "outputs": {
                    name: {
                        "fit_percent": finite_or_none(c.fit_percent[0]),
                        "rms": finite_or_none(c.rms[0]),
                        "residuals": self.residual_tests[name].to_dict() if name in self.residual_tests else None,
                        "worst_segments": [vars(s) for s in self.failures[name].worst_segments]
                        if name in self.failures
                        else [],
                    }
                    for name, c in self.comparisons.items()
                },
                "coupling": self.coupling.to_dict(),
                "diagnosis": {name: d.to_dict() for name, d in self.diagnoses.items()},
                "notes": list(self.notes),
                "timings": self.timings,
            }
        )

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None

        Returns
        -------
        str
        """
        return json.dumps(self.to_dict(), indent=indent)

    def __str__(self) -> str:
        return "\n".join(self.summary_lines())


def _by_output(result: Any, data: IOData) -> dict[str, Any]:
    """A check's result as a dict by output (a single output's result is not a mapping)."""
    return dict(result) if data.n_outputs > 1 else {data.output_names[0]: result}


def analyse_state_space(
    data: IOData,
    validation: IOData | None = None,
    *,
    order: int | None = None,
    method: str = "n4sid",
    stable: bool = False,
    horizon: int | None = None,
    initial: str = "estimate",
    split: float = DEFAULT_SPLIT,
    max_lag: int = 25,
    diagnose: bool = False,
) -> StateSpaceAnalysis:
    """Estimate a state-space model and check each output on validation data.

    Parameters
    ----------
    data : IOData
        Data of one or several outputs; the estimation data when ``validation`` is given, else
        split at ``split`` into estimation and validation parts.
    validation : IOData, optional
        Validation data with the same signals.
    order, method, stable
        As :func:`arxid.ssest` (``order=None`` chooses it by the singular value criterion).
    horizon : int or None
        Validation error: None free run, k k-step prediction.
    initial : {"estimate", "zero"}
        Initial state of each validation stretch: fitted to the validation data (default, as
        MATLAB ``compare`` does for a state-space model) or zero.
    split : float
        Estimation share of ``data`` when no validation data are given.
    max_lag : int
        Largest lag of the residual tests.
    diagnose : bool
        Also search each output for a missing effect (:func:`arxid.diagnose`, at ``horizon`` from
        the ``initial`` state).

    Returns
    -------
    StateSpaceAnalysis
    """
    data = check_data(data)
    horizon, initial = check_horizon(horizon), check_initial(initial)
    est, val = (data, check_data(validation, "validation")) if validation is not None else data.split(split)
    clock, timings = time.perf_counter(), {}

    def lap(step: str) -> None:
        nonlocal clock
        now = time.perf_counter()
        timings[step], clock = now - clock, now

    model = ssest(est, order, method=method, stable=stable)
    lap("estimation")
    comparisons = _by_output(compare(model, val, horizon, initial), val)
    notes = [] if diagnose else [NO_EFFECT_SEARCH]
    try:
        tests = _by_output(residuals(model, val, max_lag), val)
    except ArxidError as exc:
        tests = {}
        notes.append(f"No residual tests: {exc}.")
    failures = _by_output(where_it_fails(model, val, horizon, initial=initial), val)
    lap("checks")
    diagnoses = {}
    if diagnose:
        diagnoses = _by_output(diagnose_model(model, est, val, horizon=horizon, initial=initial), val)
        lap("diagnosis")
    if not model.is_stable:
        notes.append("The model is unstable (a pole on or outside the unit circle): estimate with stable=True.")
    return StateSpaceAnalysis(
        model,
        est,
        val,
        comparisons,
        tests,
        failures,
        coupling(model, val),
        horizon,
        initial,
        tuple(notes),
        timings,
        diagnoses,
    )
