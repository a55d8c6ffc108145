"""What a diagnosis finds: the ranked suspects (:class:`Suspect`) and the :class:`Diagnosis` holding
them with the baseline they are judged against, as text, a dict / JSON, a table and a plot.

The ladder sits above the diagnosis and reports with it (``Diagnosis.to_dict(ladder)``); this
module only reads what a ladder lists (:class:`LadderReport`), so it never imports the ladder.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import field
from typing import Any, Protocol

from .._base.formatting import finite_or_none, horizon_label, require_pandas, text_table
from .._base.records import record
from ..checks import ResidualAnalysis
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel
from .disturbance import Disturbance
from .extension import refit
from .nonlinearity import NonlinearDependence, dependence_sentence

__all__ = ["Diagnosis", "Suspect", "LadderReport"]


class LadderReport(Protocol):
    """What :meth:`Diagnosis.to_dict` reads of a :class:`~arxid.Ladder`: its steps and diagnoses."""

    diagnoses: list[Diagnosis]

    def to_list(self) -> list[dict]:
        """One dict per step (see :meth:`arxid.Ladder.to_list`).

        Returns
        -------
        list of dict
        """
        ...


@record(eq=False)
class Suspect:
    """One candidate explanation of the model's error.

    Attributes
    ----------
    effect : str
        What is added: an effect (``u1^2``), a pair (``sign(dy)+const``) or a structure change
        (``na+1``, ``nb+1``, ``nk-1``).
    kind : str
        ``"effect"``, ``"pair"`` or ``"dynamics"``.
    score : float
        Added-variable (partial) correlation with the one-step residual, in [0, 1]; its square is
        the share of residual energy the candidate removes on the estimation data.
    f_statistic : float
        Partial F statistic of the added columns.
    p_value_raw, p_value : float
        F-test p-value, and the same corrected for the number of candidates (Holm).
    n_columns : int
        Regressor columns the candidate adds.
    rms_sim_val_after : float
        Validation error (free run, or k-step) of the model refitted with the candidate; NaN when
        it was not refitted, inf when its simulation diverges.
    improvement : float
        1 − rms_after / rms_before (0.6 = the validation error fell by 60%).
    significant : bool
        Corrected p-value below ``alpha`` and improvement of at least ``min_improvement``.
    note : str
        Why a candidate could not be scored or refitted, or why it is not significant, if so.
    physics : str
        What the candidate stands for (``"Coulomb friction on a speed output"``; see
        :data:`arxid.candidates.CATALOGUE`).
    explained_by : str
        The suspect that makes this one unnecessary (``""`` when none): once it is in the model,
        adding this one gains less than ``min_improvement``.
    """

    effect: str
    kind: str
    effects: tuple[str, ...]
    na: int
    nb: tuple[int, ...]
    nk: tuple[int, ...]
    score: float
    f_statistic: float
    p_value_raw: float
    p_value: float
    n_columns: int
    rms_sim_val_after: float
    improvement: float
    significant: bool
    note: str = ""
    model: Any = field(default=None, repr=False, compare=False)  # ArxModel, or a WienerModel for a sensor
    physics: str = ""
    explained_by: str = ""

    @property
    def refitted(self) -> bool:
        """True when the model was refitted with the candidate (``rms_sim_val_after`` is not NaN)."""
        return not math.isnan(self.rms_sim_val_after)

    def to_dict(self) -> dict:
        """The CLI contract: ``effect``, ``score``, ``p_value``, ``significant``, ``rms_sim_val_after``.

        Returns
        -------
        dict
            Those keys plus ``kind``, ``improvement``, ``note`` and ``explained_by`` (None when no
            other suspect explains it); NaN and inf become None.
        """
        return {
            "effect": self.effect,
            "kind": self.kind,
            "score": finite_or_none(float(self.score)),
            "p_value": finite_or_none(float(self.p_value)),
            "significant": bool(self.significant),
            "rms_sim_val_after": finite_or_none(float(self.rms_sim_val_after)),
            "improvement": finite_or_none(float(self.improvement)),
            "note": self.note,
            "physics": self.physics,
            "explained_by": self.explained_by or None,
        }


@record(eq=False)
class Diagnosis:
    """Ranked suspects for a model's error, with the baseline they are judged against.

    Attributes
    ----------
    model : ArxModel
        The model diagnosed.
    data, validation : IOData
        Estimation data (scores) and validation data (refits are judged on it).
    horizon : int or None
        Validation error measure: None = free run; k = k-step (chosen automatically for plants with
        an integrator, or when the baseline's free run diverges).
    rms_sim_val, rms_pred_val, fit_val : float
        Baseline validation error at ``horizon``, one-step validation RMS, and fit percent at
        ``horizon``.
    suspects : tuple of Suspect
        Significant suspects first (lowest validation error first), then the other refitted ones
        by validation error, then the rest by p-value.
    residual_tests : ResidualAnalysis or None
        Residual analysis of the model on the validation data.
    alpha, min_improvement : float
    n_tested : int
        Number of hypotheses in the multiple-comparison correction.
    validation_is_estimation : bool
        True when no separate validation data were given.
    nonlinear_dependence : tuple of NonlinearDependence
        Signals and lags on which the model's residual still depends nonlinearly
        (:func:`arxid.nonlinearity.nonlinear_dependence`, on the estimation data). The test runs
        when this is first read: it says what no candidate explains, so a ladder reads it of its
        last diagnosis only, and a diagnosis it steps past never pays for it (about a second on 2M
        samples).
    disturbance : Disturbance or None
        The validation error split at the model's slowest mode, and whether the residual is white
        (:func:`~arxid.diagnosis.disturbance.remaining_disturbance`); None when the residual tests
        could not be run.
    """

    model: ArxModel
    data: IOData = field(repr=False)
    validation: IOData = field(repr=False)
    horizon: int | None
    rms_sim_val: float
    rms_pred_val: float
    fit_val: float
    suspects: tuple[Suspect, ...]
    residual_tests: ResidualAnalysis | None = field(default=None, repr=False)
    alpha: float = 0.01
    min_improvement: float = 0.05
    n_tested: int = 0
    validation_is_estimation: bool = False
    # The dependence test, or what runs it on first read (see nonlinear_dependence).
    _dependence: tuple[NonlinearDependence, ...] | Callable[[], tuple[NonlinearDependence, ...]] = field(
        default=(), repr=False
    )
    disturbance: Disturbance | None = None

    @property
    def nonlinear_dependence(self) -> tuple[NonlinearDependence, ...]:
        """Signals and lags on which the residual still depends nonlinearly (run on first read)."""
        found = self._dependence
        if callable(found):
            found = found()
            object.__setattr__(self, "_dependence", found)  # frozen: the one deferred field, set once
        return found

    @property
    def unexplained(self) -> str:
        """What no candidate explains, in plain words (``""`` when there is a significant suspect).

        A nonlinear dependence on an input that no candidate removes comes alone: it is the more
        specific finding, and what it leaves (a backlash's held output) is slow as well. Otherwise an
        unlogged disturbance when one dominates what remains (with the low-frequency share of the
        validation error, :attr:`Disturbance.sentence`), then a nonlinear dependence on the output,
        which such a disturbance causes too (it moves the output); ``""`` when nothing is found.
        """
        if self.significant:
            return ""
        nonlinear = dependence_sentence(self.nonlinear_dependence)
        inputs = set(self.data.input_names)
        if any(d.signal in inputs for d in self.nonlinear_dependence) or self.disturbance is None:
            return nonlinear
        disturbance = self.disturbance.sentence
        if disturbance and nonlinear:
            return f"{disturbance}; {nonlinear} (a disturbance that moves the output can cause this too)"
        return disturbance or nonlinear

    @property
    def significant(self) -> tuple[Suspect, ...]:
        """The significant suspects, best first (empty: no missing effect found)."""
        return tuple(s for s in self.suspects if s.significant)

    @property
    def top(self) -> Suspect | None:
        """The best significant suspect, or None."""
        sig = self.significant
        return sig[0] if sig else None

    def suspect(self, effect: str) -> Suspect:
        """The suspect for ``effect`` (e.g. ``"y^3"``).

        Parameters
        ----------
        effect : str
            The suspect's name as listed (an effect, a pair or a structure change such as ``na+1``).

        Returns
        -------
        Suspect

        Raises
        ------
        ArxidError
            When there is no such suspect.
        """
        for s in self.suspects:
            if s.effect == effect:
                return s
        raise ArxidError(f"no suspect {effect!r}; suspects: {[s.effect for s in self.suspects]}")

    def rank(self, effect: str) -> int:
        """0-based rank of ``effect`` among the suspects.

        Parameters
        ----------
        effect : str
            The suspect's name (see :meth:`suspect`).

        Returns
        -------
        int
            Its position in ``suspects`` (0 = best).

        Raises
        ------
        ArxidError
            When there is no such suspect.
        """
        return self.suspects.index(self.suspect(effect))

    def apply(self, k: int | str = 0) -> ArxModel:
        """The model refitted on the estimation data with suspect ``k`` added.

        Parameters
        ----------
        k : int or str
            Rank (0 = best) or the suspect's name (``"y^3"``).

        Returns
        -------
        ArxModel
            The extended model (the refit made during the diagnosis when there was one).

        Raises
        ------
        ArxidError
            When there are no suspects, or ``k`` names or indexes none.
        """
        if isinstance(k, str):
            s = self.suspect(k)
        else:
            if not self.suspects:
                raise ArxidError("there are no suspects to apply")
            try:
                s = self.suspects[k]
            except (IndexError, TypeError):
                raise ArxidError(
                    f"suspect index {k!r} is out of range: there are {len(self.suspects)} suspects"
                ) from None
        if s.model is not None:
            return s.model
        return refit(self.model, self.data, s)

    def why(self, s: Suspect) -> str:
        """Why ``s`` is or is not significant, in one phrase (its ``note`` when it has one).

        Parameters
        ----------
        s : Suspect

        Returns
        -------
        str
            e.g. ``explained by y^3+const: no gain once it is added`` or ``validation error falls
            only 2 % (needs 5 %)``.
        """
        if s.note:
            return s.note
        need = f"{100 * self.min_improvement:.0f} %"
        if not math.isfinite(s.p_value) or s.p_value >= self.alpha:
            return f"p-value {s.p_value:.2g} is not below {self.alpha:g}: no evidence it is missing"
        if not s.refitted:
            return "not refitted: only the best-scored candidates are judged on validation data"
        if not math.isfinite(s.improvement):
            return "the free run with it diverges"
        if s.significant:
            return f"validation error falls {100 * s.improvement:.0f} %"
        if s.improvement < 0:
            return f"validation error rises {-100 * s.improvement:.0f} % (needs to fall {need})"
        return f"validation error falls only {100 * s.improvement:.1f} % (needs {need})"

    def __str__(self) -> str:
        base = (
            f"diagnosis of {self.model.structure_name()}: validation error ({horizon_label(self.horizon)}) "
            f"{self.rms_sim_val:.4g}, fit {self.fit_val:.2f}%, one-step rms {self.rms_pred_val:.4g}"
        )
        lines = [base]
        if self.validation_is_estimation:
            lines.append("  (no validation data given: judged on the estimation data)")
        if self.residual_tests is not None:
            rt = self.residual_tests
            lines.append(
                f"  residual: Ljung–Box p = {rt.ljung_box_p_value:.3g} ({'white' if rt.is_white else 'not white'})"
            )
        rows = []
        for i, s in enumerate(self.suspects[:15]):
            rows.append(
                (
                    i,
                    s.effect,
                    s.score,
                    s.p_value,
                    s.rms_sim_val_after,
                    f"{100 * s.improvement:+.1f}%" if s.refitted and math.isfinite(s.improvement) else "",
                    "yes" if s.significant else "",
                    s.note if len(s.note) <= 48 else s.note[:45] + "...",
                )
            )
        lines.append(
            text_table(
                ["#", "suspect", "score", "p (Holm)", "val rms after", "change", "significant", "note"], rows, digits=3
            )
        )
        if not self.significant:
            lines.append(
                "no significant missing effect: no candidate passes both the corrected F-test "
                f"(alpha {self.alpha}) and a {100 * self.min_improvement:.0f}% validation improvement"
            )
            if self.unexplained:
                lines.append(self.unexplained)
        else:
            top = self.significant[0]
            what = f" — {top.physics}" if top.physics else ""
            lines.append(
                f"best: add {top.effect}{what} (validation error {self.rms_sim_val:.4g} -> "
                f"{top.rms_sim_val_after:.4g}); diagnosis.apply(0) refits with it"
            )
        return "\n".join(lines)

    def to_dict(self, ladder: LadderReport | None = None) -> dict:
        """The machine-readable report (the ``arxid diagnose --json`` contract).

        Keys ``model`` (na, nb, nk, effects), ``baseline`` (rms_sim_val, rms_pred_val, fit_val,
        horizon), ``residual_tests``, ``suspects`` (effect, score, p_value, significant,
        rms_sim_val_after), ``ladder`` (effects, rms_sim_val) and ``nonlinear_dependence`` (what the
        ladder's last diagnosis leaves unexplained, see :meth:`dependence_dict`); without ``ladder``
        the ladder holds the diagnosed model only.

        Parameters
        ----------
        ladder : Ladder, optional
            Steps to report under ``ladder`` (see :meth:`Ladder.to_list`).

        Returns
        -------
        dict
            JSON-ready; NaN and inf become None.
        """
        m = self.model
        last = ladder.diagnoses[-1] if ladder and ladder.diagnoses else self
        if ladder is None:
            steps = [{"effects": list(m.effects), "rms_sim_val": finite_or_none(float(self.rms_sim_val))}]
        else:
            steps = ladder.to_list()
        return {
            "model": {
                "na": m.na_,
                "nb": list(m.nb_),
                "nk": list(m.nk_),
                "structure": m.structure_name(),
                "effects": list(m.effects),
                **_polynomial_orders(m),
            },
            "baseline": {
                "rms_sim_val": finite_or_none(float(self.rms_sim_val)),
                "rms_pred_val": finite_or_none(float(self.rms_pred_val)),
                "fit_val": finite_or_none(float(self.fit_val)),
                "horizon": self.horizon,
            },
            "residual_tests": self.residual_tests.to_dict() if self.residual_tests is not None else {},
            "suspects": [{**s.to_dict(), "why": self.why(s)} for s in self.suspects],
            "ladder": steps,
            "nonlinear_dependence": last.dependence_dict(),
        }

    def dependence_dict(self) -> dict:
        """What no candidate explains: where the residual still depends nonlinearly, and the remaining
        disturbance.

        Returns
        -------
        dict
            ``signals`` one dict per :class:`~arxid.nonlinearity.NonlinearDependence`;
            ``unexplained`` the sentence of :attr:`unexplained`; and, only when that sentence reports
            an unlogged disturbance, ``disturbance``: its numbers (:meth:`Disturbance.to_dict`: the
            low-frequency share of the validation error, the split frequency, the colour test).
        """
        sentence = self.unexplained
        out: dict = {"signals": [d.to_dict() for d in self.nonlinear_dependence], "unexplained": sentence}
        if self.disturbance is not None and self.disturbance.sentence and self.disturbance.sentence in sentence:
            out["disturbance"] = self.disturbance.to_dict()
        return out

    def to_json(self, indent: int | None = 2, ladder: LadderReport | None = None) -> str:
        """JSON of :meth:`to_dict` (the ``arxid diagnose --json`` output).

        Parameters
        ----------
        indent : int or None
            Indentation of the JSON; None writes one line.
        ladder : Ladder, optional
            Steps to report under ``ladder``.

        Returns
        -------
        str
        """
        import json

        return json.dumps(self.to_dict(ladder), indent=indent)

    def to_pandas(self):
        """One row per suspect: score, p-values, validation error after, improvement, significant.

        Returns
        -------
        pandas.DataFrame
            Rows in ranked order; columns ``suspect``, ``kind``, ``score``, ``f_statistic``,
            ``p_value_raw``, ``p_value``, ``rms_sim_val_after``, ``improvement``, ``significant``, ``note``.
        """
        pd = require_pandas()
        return pd.DataFrame(
            [
                {
                    "suspect": s.effect,
                    "kind": s.kind,
                    "score": s.score,
                    "f_statistic": s.f_statistic,
                    "p_value_raw": s.p_value_raw,
                    "p_value": s.p_value,
                    "rms_sim_val_after": s.rms_sim_val_after,
                    "improvement": s.improvement,
                    "significant": s.significant,
                    "note": s.note,
                }
                for s in self.suspects
            ]
        )

    def plot(self, n: int = 12):
        """Scores and validation change of the top ``n`` suspects.

        Parameters
        ----------
        n : int
            Suspects to show, best first.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_diagnosis

        return plot_diagnosis(self, n)


def _polynomial_orders(m: ArxModel) -> dict:
    """A polynomial model's class and orders beyond na, nb, nk (nothing for ARX: its contract is fixed)."""
    if not isinstance(m, PolynomialModel):
        return {}
    return {"kind": m.kind, "nc": m.nc_, "nd": m.nd_, "nf": list(m.nf_)}
