"""Plain-language verdicts of arxid's results: one sentence per test or number a reader must judge.

The CLI, the report and the demo print these sentences before any table, so a control engineer
reads the conclusion first and the statistics second. Each function reads a stored result object
and computes nothing new.

Examples
--------
>>> from arxid.analysis.verdicts import lag_ranges, negative_fit_note
>>> lag_ranges([0, 1, 2, 3, 7, 9, 10])
'0–3, 7, 9–10'
>>> negative_fit_note(-87.8).split("(")[0]
'a negative fit means the model is worse than the constant mean of the measured output '
"""

from __future__ import annotations

import math
import re
from collections.abc import Sequence
from typing import Any

__all__ = [
    "lag_ranges",
    "negative_fit_note",
    "residual_sentences",
    "ladder_headline",
    "percent",
    "delay_notes",
]

#: Sampling intervals [s] at or below which no actuator answers within one sample (1 kHz and faster
#: gyro loops: motors and their propellers take milliseconds to change their thrust).
FAST_SAMPLING = 0.001


def delay_notes(model: Any, data: Any, closed: bool = False) -> tuple[str, ...]:
    """A warning when the chosen model has no delay from an input while that is implausible.

    A delay of zero samples says the input acts on the output within the same sample. At 1 kHz
    and faster no motor does that, and in closed loop a controller that reads the output and writes
    the input within the sample produces exactly this dependence: the model has learned the
    controller, not the plant.

    Parameters
    ----------
    model : ArxModel or PolynomialModel
        The chosen model (its delays ``nk_``).
    data : IOData
        The estimation data (its sampling time and input names).
    closed : bool
        Whether the analysis identified the data as closed loop.

    Returns
    -------
    tuple of str
    """
    nk = list(getattr(model, "nk_", ()) or ())
    zero = [n for n, k in zip(data.input_names, nk) if int(k) == 0]
    if not zero or not (closed or data.ts <= FAST_SAMPLING):
        return ()
    why = (
        "in closed loop this is the controller reacting to the output within the sample, not the plant"
        if closed
        else f"at {1 / data.ts:.0f} Hz no actuator responds within one sample"
    )
    return (
        f"Warning: the chosen model has no delay from {', '.join(zero)} to {data.output_name} (nk = 0): {why}. "
        "Check the delay, or sweep with nk from 1.",
    )


def percent(share: float | None) -> str:
    """``0.943`` → ``94 %`` (``-`` for None or NaN)."""
    if share is None or not math.isfinite(share):
        return "-"
    return f"{100 * share:.0f} %"


def lag_ranges(lags: Sequence[int]) -> str:
    """Runs of consecutive lags, e.g. ``0–7, 12`` (empty string for none).

    Parameters
    ----------
    lags : sequence of int

    Returns
    -------
    str
    """
    out: list[str] = []
    run: list[int] = []
    for k in sorted(int(x) for x in lags):
        if run and k == run[-1] + 1:
            run.append(k)
            continue
        if run:
            out.append(str(run[0]) if len(run) == 1 else f"{run[0]}–{run[-1]}")
        run = [k]
    if run:
        out.append(str(run[0]) if len(run) == 1 else f"{run[0]}–{run[-1]}")
    return ", ".join(out)


def negative_fit_note(fit: float | None) -> str:
    """One line that explains a negative fit percent (empty for a fit ≥ 0).

    Parameters
    ----------
    fit : float or None
        NRMSE fit in percent.

    Returns
    -------
    str
    """
    if fit is None or not math.isfinite(fit) or fit >= 0:
        return ""
    return (
        "a negative fit means the model is worse than the constant mean of the measured output "
        "(fit = 100 (1 − |y − ŷ| / |y − mean y|))"
    )


def _whiteness(rt: Any) -> str:
    out = rt.autocorrelation_outside
    where = f", correlated with itself at lags {lag_ranges(out)}" if len(out) else ""
    if rt.is_white:
        return f"The residuals are white: yes (Ljung–Box p = {rt.ljung_box_p_value:.2g}{where})."
    if not getattr(rt, "whiteness_expected", True):
        return (
            f"The residuals are white: no (Ljung–Box p = {rt.ljung_box_p_value:.2g}{where}), which an output-error "
            "model allows: it models no noise, so coloured output noise stays in its residual. Its test is the "
            "independence of the inputs below."
        )
    return (
        f"The residuals are white: no (Ljung–Box p = {rt.ljung_box_p_value:.2g}{where}): the model misses "
        "dynamics or an effect."
    )


def _slow_p(rt: Any, name: str) -> float:
    return float(getattr(rt, "low_frequency_p_values", {}).get(name, math.nan))


def _independence(rt: Any, name: str) -> str:
    p = rt.cross_p_values.get(name, math.nan)
    slow = _slow_p(rt, name)
    block = getattr(rt, "low_frequency_block", 0)
    out = rt.cross_outside(name)
    if not math.isfinite(p):
        return f"Whether the residuals depend on {name} could not be tested (no numbers where the residual exists)."
    if p < rt.alpha:
        lead = [int(k) for k in out if k >= 0]
        lag = [int(k) for k in out if k < 0]
        where = f" at lags {lag_ranges(lead)}" if lead else ""
        also = ""
        if math.isfinite(slow):
            also = f"; {'slowly too, ' if slow < rt.alpha else ''}low-frequency p = {slow:.2g}"
        text = (
            f"The residuals still depend on {name}{where} (p = {p:.2g}{also}): the model misses something driven "
            f"by {name}"
        )
        if lag and not lead:
            text += f", or {name} responds to the output (feedback: only negative lags {lag_ranges(lag)})"
        return text + "."
    if math.isfinite(slow) and slow < rt.alpha:
        return (
            f"The residuals drift with {name} (low-frequency test on {block}-sample means: p = {slow:.2g}): their "
            f"slow changes follow {name}, as when an effect of {name} builds up over the record. The prewhitened "
            f"test (p = {p:.2g}) cannot see it: prewhitening turns a slow signal into its sample-to-sample changes "
            "and discounts a drift."
        )
    tail = f", p = {slow:.2g} on {block}-sample means" if math.isfinite(slow) else ""
    text = f"The residuals do not depend on {name} (p = {p:.2g} on the prewhitened signals{tail})"
    if len(out):
        text += (
            f"; the raw correlation leaves its 99 % band at {len(out)} of {len(rt.cross_lags)} lags only "
            f"because {name} and the residual change slowly, which a prewhitened test discounts"
        )
    return text + "."


def _signals_of(effect: str, names: Sequence[str]) -> list[str]:
    """The signals of ``names`` an effect string is built from (``collective*vbat`` → collective, vbat)."""
    words = set(re.findall(r"[A-Za-z_]\w*", effect))
    return [n for n in names if n in words]


def _named_but_unseen(rt: Any, diagnosis: Any) -> list[str]:
    """A sentence for each logged signal a significant suspect uses that neither residual test sees."""
    extra = set(getattr(diagnosis.validation, "extra", {}) or {})
    out = []
    for s in diagnosis.significant:
        for name in _signals_of(s.effect, [n for n in rt.cross_correlation if n in extra]):
            p, slow = rt.cross_p_values.get(name, math.nan), _slow_p(rt, name)
            if (math.isfinite(p) and p < rt.alpha) or (math.isfinite(slow) and slow < rt.alpha):
                continue
            out.append(
                f"The diagnosis names {s.effect} although neither residual test sees {name} in this record: its "
                f"evidence is the validation error, which falls {100 * s.improvement:.0f} % when {s.effect} is "
                f"added (a residual test on one record cannot tell a slow effect of {name} from other slow drift)."
            )
    return out


def residual_sentences(rt: Any, diagnosis: Any = None) -> list[str]:
    """One sentence per residual test: whiteness, then independence of each signal.

    Parameters
    ----------
    rt : ResidualAnalysis
    diagnosis : Diagnosis, optional
        When given, a sentence follows for each logged signal a significant suspect uses that no
        residual test sees, saying what the diagnosis rests on instead.

    Returns
    -------
    list of str
    """
    lines = [_whiteness(rt)] + [_independence(rt, name) for name in rt.cross_correlation]
    return lines + (_named_but_unseen(rt, diagnosis) if diagnosis is not None else [])


def ladder_headline(ladder: Any) -> str:
    """What the ladder removed, the effects' share apart from the structure changes'.

    Parameters
    ----------
    ladder : Ladder

    Returns
    -------
    str
        e.g. ``the added effects (y^3+const) removed 82 % of the validation error; structure changes
        (nb+1, nb+1) removed 12 % more (94 % in all)``; empty for a ladder of one step.
    """
    fall = ladder.error_fall()
    if len(ladder.steps) < 2 or fall["total"] is None:
        return ""
    parts = []
    if fall["added_effects"]:
        parts.append(
            f"the added effects ({', '.join(fall['added_effects'])}) removed {percent(fall['effects'])} of the "
            "validation error"
        )
    if fall["structure_changes"]:
        more = " more" if parts else " of the validation error"
        parts.append(
            f"structure changes ({', '.join(fall['structure_changes'])}) removed {percent(fall['structure'])}{more}"
        )
    text = "; ".join(parts)
    if len(parts) > 1:
        text += f" ({percent(fall['total'])} in all)"
    return text[0].upper() + text[1:] + "."
