"""The HTML report of an :class:`~arxid.Analysis`: the page is ``template.html`` + ``report.css``;
each section renders the analysis' stored result objects (the same numbers, bounds, bins and
verdicts as the API), with elements built by :func:`el` so every text is escaped."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..._base.formatting import horizon_text
from ...data.iodata import IOData
from ...exceptions import ArxidError
from ...models.polynomial import PolynomialModel
from ...models.wiener import linear_part
from ..pipeline import Analysis
from ..verdicts import ladder_headline, negative_fit_note, percent, residual_sentences
from .blocks import Raw, el, page, script_json
from .blocks import figure as _img
from .blocks import join as _join
from .blocks import number as _num
from .blocks import paragraph as _p
from .blocks import table as _table

__all__ = ["render_html", "el", "script_json", "Raw"]


# ----------------------------------------------------------------------------------------- sections
def _data_section(a: Analysis) -> Raw:
    from ...plots import data_overview

    est, val = a.estimation, a.validation
    lad = a.ladder.errors
    cards = [
        (f"{est.n_samples} + {val.n_samples}", "estimation + validation samples"),
        (f"{est.ts:g} s", "sampling time"),
        (a.model.structure_name(), "chosen structure"),
        (f"{_num(lad[0])} → {_num(lad[-1])}", f"validation RMS error ({horizon_text(a.horizon)})"),
    ]
    fall = a.ladder.error_fall()
    if fall["total"] is not None:
        if fall["added_effects"]:
            cards.append((percent(fall["effects"]), "of the error removed by the added effects"))
        if fall["structure_changes"]:
            cards.append(
                (
                    percent(fall["structure"]),
                    "removed by structure changes (" + ", ".join(fall["structure_changes"]) + ")",
                )
            )
    cards_html = el("div", *[el("div", el("b", v), el("span", k), cls="card") for v, k in cards], cls="cards")
    full = IOData.merge([est, val])
    return _join(
        [
            cards_html,
            el("pre", repr(est), cls="eq"),
            _img(
                data_overview(full, validation_start=est.n_samples),
                "data overview",
                "Output (blue), inputs (orange) and extra signals (green); the dashed line labelled "
                "“estimation | validation” is where the validation data begin.",
            ),
        ]
    )


def _sweep_rows(a: Analysis) -> tuple[list[list[Any]], list[str]]:
    assert a.sweep is not None
    rows, classes = [], []
    skipped = {s for s, _ in a.choice.skipped}
    for r in a.sweep.summary(top=15)["structures"]:
        rows.append(
            [
                r["rank"],
                r["structure"],
                _num(r["rms_est"]),
                _num(r["rms_val"]),
                _num(r["fit_val"], 3),
                _num(r["rms_val_one_step"]),
                _num(r["fpe"]),
                r["n_params"],
                _num(r["stable"]),
                _num(r["max_pole"]),
                r["step_sanity"] or "-",
            ]
        )
        classes.append(
            "chosen" if r["structure"] == a.choice.structure else ("flagged" if r["structure"] in skipped else "")
        )
    return rows, classes


def _sweep_section(a: Analysis) -> Raw:
    if a.sweep is None:
        return _p(f"{a.choice.reason[0].upper()}{a.choice.reason[1:]}, so no sweep was run.")
    res = a.sweep
    rows, classes = _sweep_rows(a)
    head = [
        "rank",
        "structure",
        "RMS est",
        "RMS val",
        "fit val %",
        "RMS val 1-step",
        "FPE",
        "p",
        "stable",
        "largest pole",
        "step check",
    ]
    grid = a.grid_text
    parts: list[str] = [
        _p(
            f"{len(res)} structures ({grid}) fitted on the estimation data and ranked by {res.ranking_text}; the "
            f"best 15 are shown. Chosen: {a.choice.structure}, {a.choice.reason}. Grey rows failed the step "
            f"sanity check."
        ),
        _table(head, rows, classes, left=2),
    ]
    fits = [r[4] for r in rows]
    if any(negative_fit_note(float(f)) for f in fits if f != "-"):
        parts.append(_p(negative_fit_note(-1.0)[0].upper() + negative_fit_note(-1.0)[1:] + ".", cls="small"))
    if a.choice.skipped:
        parts.append(_p("Skipped by the step sanity check: " + "; ".join(f"{s}: {w}" for s, w in a.choice.skipped[:8])))
    if a.choice.grid_edge:
        parts.append(_p(a.choice.grid_edge))
    parts += _growth_parts(a)
    try:
        fig = res.plot(chosen=a.choice.rank)
    except (ArxidError, ValueError) as exc:  # a grid with one na or nk value cannot be drawn as a map
        parts.append(_p(f"(no heat map: {exc})"))
    else:
        grey = [
            res.structure_name(i)
            for i in range(len(res))
            if res.errors[i] is not None or res.diverged_val[i] or res.diverged_est[i]
        ]
        greyed = (
            f" Grey cells ({len(grey)}): "
            + ", ".join(grey[:12])
            + (f" and {len(grey) - 12} more" if len(grey) > 12 else "")
            + " diverged or could not be fitted."
            if grey
            else " No structure diverged."
        )
        parts.append(
            _img(
                fig,
                "sweep heat map",
                f"Ranking error over the order grid (lower is better); the red star marks the chosen structure "
                f"{a.choice.structure}.{greyed}",
            )
        )
    return _join(parts)


def _growth_parts(a: Analysis) -> list[Raw]:
    """The grids tried while growing the grid past the choice's edges, and why growing stopped."""
    g = a.grid_growth
    if g is None or not (g.grew or g.stop != "inside"):
        return []
    if not g.grew:
        return [_p(f"The grid ({g.rounds[0].text}) was swept once: {g.reason}")]
    one = len({r.measure for r in g.rounds}) == 1  # the integrator verdict can change the measure
    rows = [
        [
            r.text,
            f"{r.n_structures:,}",
            f"{r.seconds:.2f}",
            r.structure,
            r.error_text if one else f"{r.error_text} ({r.measure})",
            "yes" if r.edge else "no",
        ]
        for r in g.rounds
    ]
    head = ["grid", "structures", "seconds", "best structure", g.rounds[-1].measure if one else "error", "on an edge"]
    return [_p(g.lines()[0]), _table(head, rows, left=1), _p(f"Growing stopped: {g.reason}")]


def _model_section(a: Analysis) -> Raw:
    title = "Chosen model" if a.choice.rank is not None or a.sweep is not None else "The model"
    parts = [el("h3", title), el("pre", str(a.model), cls="eq"), *_parameter_table(a.model)]
    if a.final_model is not a.model:
        parts += [el("h3", "With the added effects"), el("pre", str(a.final_model), cls="eq")]
        parts += _parameter_table(a.final_model)
    return _join(parts)


def _parameter_table(model: Any) -> list[Raw]:
    """A polynomial model's parameters (A, B, C, D, F blocks in MATLAB's getpvec order) with their
    standard errors."""
    if not isinstance(model, PolynomialModel):
        return []
    continuous = getattr(model, "parameter_dict", None)  # a continuous-time model: its own parameters
    if continuous is not None:
        rows = [[k, _num(v), _num(e, 3), _num(abs(v) / e, 3) if e > 0 else "-"] for k, (v, e) in continuous().items()]
        return [_table(["parameter", "value", "standard error", "|value| / s.e."], rows)]
    se = model.standard_errors_
    rows = [
        [label, _num(v), _num(e, 3), _num(abs(v) / e, 3) if e > 0 else "-"]
        for label, v, e in zip(model.parameter_labels(), model.parameters_, se)
    ]
    return [_table(["parameter", "value", "standard error", "|value| / s.e."], rows)]


def _step_section(a: Analysis) -> Raw:
    from ...plots import step_checks

    val = a.validation
    amp = float(np.nanstd(val.u[:, 0])) or 1.0
    n = min(val.n_samples, max(50, int(round(2.0 / val.ts)) if val.ts < 0.05 else 200))
    models = [("chosen " + a.model.structure_name(), a.model)]
    flags = {}
    if a.sweep is not None:
        names = [a.sweep.structure_name(i) for i in range(min(len(a.sweep), 40))]
        for name, reason in a.choice.skipped[:3]:
            if name in names:
                models.append((name, a.sweep.model(names.index(name))))
                flags[name] = reason
    from ...checks.bands import response_band
    from ...selection.sanity import step_deviation, step_inputs

    # What the step does, s(a) - s(0), as the step sanity check judges it: an offset or a logged
    # signal (held at its mean) moves both steps alike and is not drawn as part of the response.
    extra = step_inputs(val, n)
    band = response_band(a.model, lambda m: step_deviation(m, n, amp, 0, extra=extra), np.arange(n) * val.ts)
    responses = [(models[0][0], band.response)] + [
        (label, step_deviation(m, n, amp, 0, extra=extra)) for label, m in models[1:]
    ]
    negatives = {label: step_deviation(m, n, -amp, 0, extra=extra) for label, m in models}
    unit = f" [{val.output_unit}]" if val.output_unit else ""
    fig = step_checks(
        responses, val.ts, flags, ylabel=val.output_name + unit, bands={models[0][0]: band}, negatives=negatives
    )
    in_unit = f" {val.input_units[0]}" if val.input_units[0] else ""
    stable = a.model.is_stable
    dc = ", ".join(_num(g) for g in np.atleast_1d(a.model.dc_gain())) if stable else ""
    text = (
        f"Response to a step of one standard deviation of {val.input_names[0]} ({amp:.4g}{in_unit}) over "
        f"{n * val.ts:g} s, with its {band.description}. "
        f"A plausible model responds with the sign and size the measured output suggests (a published quadrotor "
        f"study, Sarıoğlu & Kural, rejected its best-ranked ARX(2,2,0) this way). The chosen model is "
        + ("stable" if stable else "not asymptotically stable (integrating)")
        + (f", DC gain {dc}" if dc else "")
        + "."
    )
    return _join(
        [
            _p(text),
            _img(
                fig,
                "step responses",
                "Positive and negative steps of the chosen structure"
                + (" and of the better-ranked structures the check rejected (dashed)." if flags else "."),
            ),
        ]
    )


def _compare_section(a: Analysis) -> Raw:
    c = a.comparison
    rows = [
        [n, _num(f, 3), _num(r), "diverged" if d else ""]
        for n, f, r, d in zip(c.names, c.fit_percent, c.rms, c.diverged)
    ]
    from ...plots import plot_comparison

    notes = [negative_fit_note(f) for f in c.fit_percent if negative_fit_note(f)]
    worst = a.failures[0].worst_segments if a.failures else ()
    zoom = (worst[0].start_time, worst[0].end_time) if worst else None
    long = len(c.time) > 3000
    caption = "Measured output (black) and model outputs, error underneath" + (
        "; shaded around each model: its 99 % band from the parameter covariance." if a.bands else "."
    )
    if long:
        caption += (
            f" {len(c.time)} samples are drawn as min–max envelopes; the bottom panel zooms in, at full resolution, "
            "on the window where the first model fails worst."
        )
    return _join(
        [
            _p(f"Validation data, {horizon_text(c.horizon)}."),
            _table(["model", "fit %", "RMS error", ""], rows),
            *[_p(n[0].upper() + n[1:] + ".", cls="small") for n in notes[:1]],
            _img(plot_comparison(c, bands=a.bands or None, zoom=zoom), "measured vs simulated", caption),
        ]
    )


def _residual_section(a: Analysis) -> Raw:
    rt = a.residual_tests
    if rt is None:
        return _p("The residual tests could not be run on these validation data.")
    lb = (
        f"Ljung–Box Q = {rt.ljung_box_statistic:.4g} with {rt.ljung_box_dof} degrees of freedom, "
        f"p = {rt.ljung_box_p_value:.3g}: the residual is " + rt.whiteness_text + "."
    )
    out = rt.autocorrelation_outside
    auto = f"Autocorrelation: 99 % bound ±{rt.autocorrelation_bound:.3g}, " + (
        f"{len(out)} of {len(rt.lags) - 1} lags outside." if len(out) else "every lag inside."
    )
    rows = []
    for name, d in rt.to_dict()["cross_correlation"].items():
        rows.append(
            [
                name,
                _num(d["max_abs"], 3),
                d["lag_of_max"],
                _num(d["bound"], 3),
                f"{len(d['lags_outside'])} of {len(rt.cross_lags)}",
                _num(d["p_value"], 3),
                _num(d["p_value_low_frequency"], 3),
                rt.verdict(name),
            ]
        )
    head = ["signal", "largest |correlation|", "at lag", "99 % bound", "lags outside", "p-value", "low-frequency p"]
    table = _table([*head, "independent"], rows)
    note = (
        "Independence is judged by a test on the prewhitened series (Haugh), not by counting lags outside the "
        "bound: a coloured signal can leave the bound at many lags and still be independent. Prewhitening removes "
        f"slow changes, so a second test compares means over {rt.low_frequency_block} samples: it sees a residual "
        "that drifts with a signal (“NO (slowly)”)."
    )
    plain = el("ul", *[el("li", t) for t in residual_sentences(rt, a.diagnosis)], cls="verdicts")
    return _join(
        [
            plain,
            el("h3", "Details"),
            _p(lb),
            _p(auto),
            table,
            _p(note, cls="small"),
            _img(
                rt.plot(),
                "residual correlations",
                "Correlations of the one-step residual with the analysis' own 99 % bounds; red: outside.",
            ),
        ]
    )


def _failure_section(a: Analysis) -> Raw:
    from ...plots import plot_error_by_signal

    fa = a.failures[0]
    rows = [
        [
            f"{s.start_time:.4g}",
            f"{s.end_time:.4g}",
            _num(s.rms),
            _num(s.ratio, 3),
            _num(s.p_value, 3),
            "yes" if s.significant else "no",
        ]
        for s in fa.worst_segments
    ]
    bins = [
        [b.signal, _num(b.ratio, 3), _num(b.p_value, 3), "yes" if b.signal in fa.significant_signals else "no"]
        for b in fa.by_signal
    ]
    other = a.failures[1] if len(a.failures) > 1 else None
    return _join(
        [
            _p(f"{fa.model_name}, {horizon_text(fa.horizon)}: RMS {_num(fa.rms)} over the record."),
            _table(["from [s]", "to [s]", "RMS", "× overall", "p-value", "significant"], rows),
            _img(fa.plot(), "error in time", "Rolling RMS of measured − model on validation data."),
            _table(["signal", "largest bin / overall", "p-value", "significant"], bins),
            _img(
                plot_error_by_signal(fa, other),
                "error by operating point",
                "Residual RMS binned by each signal; a trend names the missing physics.",
            ),
        ]
    )


def _frequency_section(a: Analysis) -> Raw:
    if not a.frequency:
        return _p("No frequency check: " + " ".join(n for n in a.notes if n.startswith("No frequency check")))
    fc = a.frequency[0]
    sentences = el(
        "ul", *[el("li", el("b", f"{f.model_name}: "), f.summary + ".") for f in a.frequency], cls="verdicts"
    )
    how = _p(
        f"Grey: the frequency response estimated from the validation data alone (Welch averages of "
        f"{fc.segment_length}-sample Hann segments, H1 = S_yu/S_uu, {fc.n_averages:.0f} effective averages) "
        f"with its {100 * fc.level:g} % band; blue: the model's transfer function (B/A, or B/F for OE and BJ) "
        "with its band from the parameter covariance. "
        "Red shading: frequencies where the model's error is still explained by the input beyond both "
        "uncertainties (the test behind the sentence above). Low coherence means the input does not excite "
        "that frequency or the output there is noise, and the data say little.",
        cls="small",
    )
    return _join([sentences, _img(fc.plot(), "frequency check", f"Frequency check of {fc.model_name}."), how])


def _bode_section(a: Analysis) -> Raw:
    from ...frequency_domain import model_response
    from ...plots.bode import plot_bode

    fr = a.bode
    if fr is None:
        return _p(
            "No Bode view: the validation data are too short for a frequency response, or several inputs "
            "have no reference each."
        )
    model = a.final_model
    where = ", ".join(f"{lo:.3g} Hz" if lo == hi else f"{lo:.3g}–{hi:.3g} Hz" for lo, hi in a.bode_misses)
    verdict = (
        f"The model {model.structure_name()} leaves the measured response's band at {where}."
        if where
        else f"The model {model.structure_name()} stays inside the measured response's band wherever the "
        "coherence is at least 0.5."
    )
    how = _p(
        f"Black: {fr.method_text}, with its {100 * fr.confidence:g} % band (grey). Blue: the model. Grey shading: "
        "coherence below 0.5 (the data say little there). Red shading: where the model leaves the band.",
        cls="small",
    )
    figure = plot_bode(fr, model_response(linear_part(model), fr.frequency), model_name=model.structure_name())
    return _join([_p(verdict), _img(figure, "Bode view"), how])


def _shape_section(a: Analysis) -> Raw:
    from ...plots.shapes import plot_static_map

    if not a.input_shapes:
        return _p("The final model feeds no input through a static shape.")
    parts = []
    for shape, m in a.input_shapes:
        nearest = ", ".join(f"{label} {fit:.1f} %" for label, fit, _ in m.matches[:4])
        parts.append(_p(el("b", shape.physics().capitalize()), f". Fit of each named shape to the map: {nearest}."))
        if m.fit_of(shape) - m.fit_of(None) < 1.0:  # the held levels alone do not tell the shape
            parts.append(_p(f"At the levels the estimation data hold, the map is as straight as it is {shape.text} "
                            f"({m.fit_of(None):.1f} % against {m.fit_of(shape):.1f} %): the validation data, with "
                            "other levels and transitions, are what chose the shape."))  # fmt: skip
        parts.append(_img(plot_static_map(shape, m, a.estimation.output_name), f"static map of {m.input}"))
    how = _p(
        "Black: the steady-state output with the input held at each knot, from a model whose input enters "
        "through one coefficient per knot and lag (piecewise linear, estimated with the dynamics; Bai's "
        f"over-parameterisation), with two standard errors. One shape explains {100 * m.rank_one_share:.1f} % "
        "of those coefficients. Blue: the shape the model uses, scaled to the map; grey: a straight line.",
        cls="small",
    )
    return _join([*parts, how])


def _suspect_section(a: Analysis) -> Raw:
    d = a.diagnosis
    top = d.top
    verdict = (
        _p(
            el("b", f"Missing effect: {top.effect}"),
            f" (validation error {_num(d.rms_sim_val)} → {_num(top.rms_sim_val_after)}).",
        )
        if top
        else _p(
            el("b", "No significant missing effect"),
            ": no candidate passed both the corrected F-test and a "
            f"{100 * d.min_improvement:.0f} % validation improvement.",
        )
    )
    rows, classes = [], []
    for i, s in enumerate(d.suspects[:15], start=1):
        rows.append(
            [
                i,
                s.effect,
                _num(s.score, 3),
                _num(s.p_value, 3),
                "yes" if s.significant else "no",
                _num(s.rms_sim_val_after),
                s.explained_by or "-",
                d.why(s).removeprefix(f"explained by {s.explained_by}: ") if s.explained_by else d.why(s),
            ]
        )
        classes.append("chosen" if s is top else "")
    table = _table(
        [
            "rank",
            "effect",
            "score",
            "p-value (Holm)",
            "significant",
            "val. error after",
            "explained by",
            "why",
        ],
        rows,
        classes,
        left=2,
        wrap=(6, 7),
    )
    how = _p(
        "A suspect is significant when its corrected p-value is below "
        f"{d.alpha:g} and adding it lowers the validation error by at least {100 * d.min_improvement:.0f} %; "
        "a tiny p-value alone is not enough, and a suspect that gains nothing once a better one is in the "
        "model is “explained by” it. Rows are ranked by that verdict, then by the validation error after. "
        "Score: partial correlation of the candidate with the model's one-step residual.",
        cls="small",
    )
    return _join([verdict, table, how])


def _ladder_section(a: Analysis) -> Raw:
    first = a.ladder.errors[0]
    lad = a.ladder
    rows = [
        [
            i,
            s.label(),
            {"start": "-", "effect": "effect", "structure": "structure change"}[lad.step_kind(i)],
            s.structure,
            _num(s.rms_sim_val),
            _num(s.fit_val, 3),
            f"{100 * (1 - s.rms_sim_val / first):.1f} %" if i and first > 0 else "-",
        ]
        for i, s in enumerate(a.ladder.steps)
    ]
    headline = ladder_headline(lad)
    return _join(
        [
            *([_p(el("b", headline))] if headline else []),
            _table(
                ["step", "added", "kind", "model", "validation RMS error", "fit %", "fall vs. step 0"], rows, left=4
            ),
            *([_p(a.ladder.unexplained[0].upper() + a.ladder.unexplained[1:] + ".")] if a.ladder.unexplained else []),
            _img(a.ladder.plot(), "error ladder", "Each step adds the best significant suspect and re-diagnoses."),
        ]
    )


_SECTIONS = (
    ("data", "Data", _data_section),
    ("sweep", "Order sweep", _sweep_section),
    ("model", "Model equation", _model_section),
    ("steps", "Step-response checks", _step_section),
    ("compare", "Measured against simulated output", _compare_section),
    ("residuals", "Residual tests", _residual_section),
    ("fails", "Where it fails", _failure_section),
    ("frequency", "Where it fails in frequency", _frequency_section),
    ("bode", "Bode view", _bode_section),
    ("suspects", "Which effect is missing", _suspect_section),
    ("ladder", "Error ladder", _ladder_section),
    ("shape", "How the input acts", _shape_section),
)


def render_html(a: Analysis, title: str | None = None, source: str = "") -> str:
    """The report of ``a`` as one self-contained HTML document (plots embedded as PNG).

    Parameters
    ----------
    a : Analysis
    title : str, optional
    source : str
        Where the data came from, shown under the title.

    Returns
    -------
    str
    """
    est = a.estimation
    title = title or f"arxid report: {est.output_name} from {', '.join(est.input_names)}"
    sections = [(key, name, fn(a)) for key, name, fn in _SECTIONS]
    return page(title, source, sections, a.notes, a.timings, horizon_text(a.horizon), a.to_dict())
