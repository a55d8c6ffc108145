"""The HTML report of a :class:`~arxid.analysis.state_space.StateSpaceAnalysis`: the data, the
order choice (singular values and the criterion), each output's fit, the cross-coupling of the
inputs and outputs, each output's residual tests and where its error is large. Same page, styles
and blocks as the ARX report (:mod:`arxid.analysis.report.html`)."""

from __future__ import annotations

import numpy as np

from ..._base.formatting import horizon_text
from ..state_space import StateSpaceAnalysis
from ..verdicts import negative_fit_note
from .blocks import Raw, el, join, number, page, paragraph, table
from .blocks import figure as image

__all__ = ["render_state_space_html"]


def _data_section(a: StateSpaceAnalysis) -> Raw:
    est, val = a.estimation, a.validation
    units = [f"{n} [{u}]" if u else n for n, u in zip(est.output_names, est.output_units, strict=True)]
    return join(
        [
            paragraph(f"Outputs: {', '.join(units)}. Inputs: {', '.join(est.input_names)}."),
            paragraph(
                f"Estimation: {est.n_samples} samples ({est.n_samples * est.ts:.4g} s); validation: "
                f"{val.n_samples} samples ({val.n_samples * val.ts:.4g} s); Ts = {est.ts:g} s."
            ),
        ]
    )


def _order_section(a: StateSpaceAnalysis) -> Raw:
    from ...plots.state_space import plot_singular_values

    m = a.model
    how = (
        "fixed by the caller"
        if m.order_fixed
        else "chosen where the singular value criterion SVC(n) = ρ²(n+1) + n (2 ny + nu) ln(N) / N is smallest "
        "(ρ the canonical correlations of future outputs and past data)"
    )
    radius = float(np.max(np.abs(m.poles))) if m.order else 0.0
    return join(
        [
            paragraph(f"{m.method.upper()}, {m.order} states, {how}."),
            paragraph(
                f"Largest pole magnitude {radius:.4f} ({'stable' if radius < 1 else 'unstable'}); "
                f"past and future horizons {m.horizon[0]} and {m.horizon[1]} samples."
            ),
            image(
                plot_singular_values(m),
                "singular values and order criterion",
                "Left: singular values of the weighted projection, those kept as states filled. "
                "Right: the criterion over the order; the star marks the model's order.",
            ),
        ]
    )


def _fit_section(a: StateSpaceAnalysis) -> Raw:
    from ...plots import plot_comparison

    head = ["output", "fit %", "RMS error", "residual white", "residual follows", "driven most by"]
    rows = [[r[0], number(r[1], 3), number(r[2]), *r[3:]] for r in a.output_rows()]
    notes = [n for n in map(negative_fit_note, a.fit_percent.values()) if n][:1]
    start = "estimated on them" if a.initial == "estimate" else "zero"
    parts = [
        paragraph(f"Validation data, {horizon_text(a.horizon)}; the initial state of each record {start}."),
        table(head, rows),
        *[paragraph(n[0].upper() + n[1:] + ".", cls="small") for n in notes],
    ]
    for name, c in a.comparisons.items():
        parts.append(
            image(
                plot_comparison(c), f"measured vs simulated {name}", f"Output {name}: measured (black), model, error."
            )
        )
    return join(parts)


def _coupling_section(a: StateSpaceAnalysis) -> Raw:
    from ...plots.state_space import plot_coupling

    cp = a.coupling

    def gains(values: np.ndarray) -> list[list[str]]:
        return [[out, *[number(v, 3) for v in values[i]]] for i, out in enumerate(cp.output_names)]

    head = ["output \\ input", *cp.input_names]
    return join(
        [
            paragraph(
                "How strongly each input drives each output. The heat map shows, on the validation data, the "
                "RMS of each output simulated from one input alone (the others held at zero) over the RMS of "
                "the output: the share of its motion that input's path carries. A plant without cross-coupling "
                "has large values only where each output meets its own input; a large value elsewhere is "
                "cross-coupling."
            ),
            image(
                plot_coupling(cp),
                "coupling heat map",
                "Share of each output carried by each input; rows outputs, columns inputs.",
            ),
            el("h3", "Steady-state gains (output unit per input unit)"),
            table(head, gains(cp.steady_state)),
            el("h3", "Peak gains and where they are reached"),
            table(head, gains(cp.peak)),
            paragraph("Frequency of each peak:", cls="small"),
            table(
                head, [[out, *[f"{f:.3g} Hz" for f in cp.peak_frequency[i]]] for i, out in enumerate(cp.output_names)]
            ),
        ]
    )


def _residual_section(a: StateSpaceAnalysis) -> Raw:
    if not a.residual_tests:
        return paragraph("The residual tests could not be run on these validation data.")
    inputs = list(a.validation.input_names) + list(a.validation.extra)
    rows = []
    for name, rt in a.residual_tests.items():
        verdicts = [rt.verdict(s) if s in rt.cross_correlation else "" for s in inputs]
        white = "yes" if rt.is_white else ("no (expected: no noise model)" if not rt.whiteness_expected else "no")
        rows.append([name, f"{rt.ljung_box_p_value:.3g}", white, *verdicts])
    parts = [
        paragraph(
            "The one-step residual of each output (the innovation form's prediction error) should be white and "
            "independent of every input: a residual that follows an input means the model misses part of that "
            "input's path to this output."
        ),
        table(["output", "Ljung–Box p", "white", *[f"independent of {s}" for s in inputs]], rows),
    ]
    for name, rt in a.residual_tests.items():
        parts.append(
            image(rt.plot(), f"residual correlations of {name}", f"Output {name}: correlations with 99 % bounds.")
        )
    return join(parts)


def _failure_section(a: StateSpaceAnalysis) -> Raw:
    rows = []
    for name, fa in a.failures.items():
        for s in fa.worst_segments[:2]:
            rows.append(
                [
                    name,
                    f"{s.start_time:.4g}",
                    f"{s.end_time:.4g}",
                    number(s.ratio, 3),
                    number(s.p_value, 3),
                    "yes" if s.significant else "no",
                ]
            )
    signals = [[name, ", ".join(fa.significant_signals) or "none"] for name, fa in a.failures.items()]
    return join(
        [
            table(["output", "from [s]", "to [s]", "× overall RMS", "p-value", "significant"], rows),
            el("h3", "Operating points where the residual is larger"),
            table(["output", "significant signals"], signals),
        ]
    )


def _effect_section(a: StateSpaceAnalysis) -> Raw:
    if not a.diagnoses:
        return paragraph("Not searched (arxid ssest --diagnose, or analyse_state_space(..., diagnose=True)).")
    rows = []
    for name, d in a.diagnoses.items():
        top = d.top
        found = "none" if top is None else f"{top.effect}" + (f" — {top.physics}" if top.physics else "")
        after = d.rms_sim_val if top is None else top.rms_sim_val_after
        rows.append([name, found, number(d.rms_sim_val), number(after), len(d.suspects)])
    return join(
        [
            paragraph(
                "Each output searched for the physical effect the model misses: candidate terms as extra inputs, "
                "a Holm-corrected test on the estimation data, then the model refitted with each of the best ones "
                "(its modes held) and judged on the validation data (named only when the validation error falls by "
                f"{100 * next(iter(a.diagnoses.values())).min_improvement:.0f} % or more)."
            ),
            table(["output", "missing effect", "validation error", "with it", "candidates"], rows),
        ]
    )


def _not_available_section(a: StateSpaceAnalysis) -> Raw:
    return join([paragraph(n) for n in a.notes])


_SECTIONS = (
    ("data", "Data", _data_section),
    ("order", "Order choice", _order_section),
    ("fit", "Fit of each output", _fit_section),
    ("coupling", "Cross-coupling", _coupling_section),
    ("residuals", "Residual tests of each output", _residual_section),
    ("fails", "Where each output fails", _failure_section),
    ("effects", "Missing effects of each output", _effect_section),
    ("not-run", "What this report does not do", _not_available_section),
)


def render_state_space_html(a: StateSpaceAnalysis, title: str | None = None, source: str = "") -> str:
    """The report of ``a`` as one self-contained HTML document (plots embedded as PNG).

    Parameters
    ----------
    a : StateSpaceAnalysis
    title : str, optional
    source : str
        Where the data came from, shown under the title.

    Returns
    -------
    str
    """
    m = a.model
    title = title or f"arxid state-space report: {', '.join(m.output_names)} from {', '.join(m.input_names)}"
    sections = [(key, name, fn(a)) for key, name, fn in _SECTIONS]
    text = page(title, source, sections, (), a.timings, horizon_text(a.horizon), a.to_dict())
    return text.replace("arxid diagnose --json", "arxid ssest --json")
