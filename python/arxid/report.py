"""One self-contained HTML report of an identification: data, sweep, model, checks, diagnosis, ladder.

:func:`analyse` runs the workflow (sweep, choose the best sane structure, diagnose, climb the error
ladder) and returns an :class:`Analysis`; :func:`render_html` turns it into one HTML file whose plots
are embedded PNG images, with no network fetch, that opens offline and prints; :func:`build_report`
does both.

Examples
--------
>>> import arxid
>>> from arxid.report import build_report
>>> rep = build_report(data, orders=(2, 1, 3))                    # doctest: +SKIP
>>> rep.save("report.html")                                        # doctest: +SKIP
"""

from __future__ import annotations

import html
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from .data import IOData
from .exceptions import ArxidError, DataError
from .model import ArxModel, arx

__all__ = ["Analysis", "Report", "analyse", "render_html", "build_report", "json_safe", "DEFAULT_GRID"]

#: Order grid of ``arxid report`` / ``arxid sweep`` when none is given: na 1..4, nb 1..3, nk 0..10.
DEFAULT_GRID = {"na": range(1, 5), "nb": range(1, 4), "nk": range(0, 11)}


def json_safe(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays turned into Python values and NaN/inf into ``None``,
    so ``json.dumps(..., allow_nan=False)`` gives valid JSON."""
    if isinstance(obj, dict):
        return {str(k): json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist())
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if hasattr(obj, "to_dict") and callable(obj.to_dict):
        return json_safe(obj.to_dict())
    return obj


def _script_json(obj) -> str:
    """JSON for a ``<script type="application/json">`` element: its text is raw (no entities), so
    the JSON is not HTML-escaped; ``<``, ``>`` and ``&`` become ``\\u`` escapes so that no
    ``</script>`` can end the element early. ``JSON.parse(el.textContent)`` reads it back."""
    text = json.dumps(json_safe(obj), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


# ---------------------------------------------------------------------------------------- analysis
@dataclass(frozen=True, eq=False)
class Analysis:
    """Everything the report shows.

    Attributes
    ----------
    estimation, validation : IOData
    sweep : SweepResult or None
        None when the orders were given.
    table : pandas.DataFrame or None
        The sweep as a table, best first.
    model : ArxModel
        The chosen structure, without added effects.
    rejected : dict of str to str
        Structures the step sanity check rejected and why (structure name → reason).
    diagnosis : dict
        The diagnosis in the JSON shape of ``arxid diagnose --json`` (model, baseline,
        residual_tests, suspects, ladder).
    final_model : ArxModel
        ``model`` with the effects of the last ladder step.
    timings : dict of str to float
        Seconds spent in each stage.
    notes : list of str
        Anything the reader should know (a fallback used, a stage skipped).
    """

    estimation: IOData
    validation: IOData
    sweep: Any
    table: Any
    model: ArxModel
    rejected: dict
    diagnosis: dict
    final_model: ArxModel
    timings: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    @property
    def horizon(self) -> int | None:
        h = self.diagnosis.get("baseline", {}).get("horizon")
        return int(h) if h is not None else None

    @property
    def ladder(self) -> list[dict]:
        return list(self.diagnosis.get("ladder", []))


def _structure(model: ArxModel) -> tuple:
    nb = model.nb if len(model.nb) > 1 else model.nb[0]
    nk = model.nk if len(model.nk) > 1 else model.nk[0]
    return (model.na, nb, nk)


def _grid_kwargs(grid) -> dict:
    g = dict(DEFAULT_GRID if grid is None else grid)
    unknown = set(g) - {"na", "nb", "nk"}
    if unknown:
        raise ArxidError(f"grid keys must be na, nb, nk; got {sorted(unknown)}")
    return {k: g.get(k, DEFAULT_GRID[k]) for k in ("na", "nb", "nk")}


def run_sweep(est: IOData, val: IOData, grid=None, progress: bool = False, expect: str | None = None,
              horizon: int | None = None):
    """Sweep the grid with :func:`arxid.sweep` and choose the best structure that passes the step
    sanity checks.

    Parameters
    ----------
    est, val : IOData
        Estimation and validation data.
    grid : dict with keys na, nb, nk, optional
        Order ranges (default :data:`DEFAULT_GRID`).
    progress : bool
        Progress bar on stderr for long sweeps.
    expect : str, optional
        Step sanity expectation (``"stable"``, ``"integrating"``, ``"double-integrating"``).
    horizon : int, optional
        Validation measure (None: free run, or the sweep's k-step for integrating plants).

    Returns
    -------
    (SweepResult, pandas.DataFrame, ArxModel, dict of rejected structure name → reason)
        The table is best first; ``rejected`` lists the better-ranked structures the sanity check
        skipped.
    """
    import arxid

    kw = _grid_kwargs(grid)
    res = arxid.sweep(est, validation=val, progress=progress, expect=expect, horizon=horizon, **kw)
    table = res.to_pandas()
    model = res.best(sane=True, explain=False)
    sel = getattr(model, "selection_", None)
    rejected = {name: "; ".join(reasons) for _, name, reasons in (sel.skipped if sel is not None else ())}
    return res, table, model, rejected


def _orders_of(orders) -> tuple:
    if len(orders) != 3:
        raise ArxidError(f"orders must be (na, nb, nk), got {orders!r}")
    return tuple(orders)


def diagnose_ladder(est: IOData, val: IOData, model: ArxModel, horizon: int | None = None, max_steps: int = 3):
    """Diagnose ``model`` and climb the greedy error ladder (:meth:`arxid.Ladder.run`).

    Parameters
    ----------
    est, val : IOData
        Estimation and validation data.
    model : ArxModel
        The model to diagnose.
    horizon : int, optional
        Validation measure (None: free run; integrating plants get a k-step horizon).
    max_steps : int
        Largest number of effects added.

    Returns
    -------
    (dict, Ladder)
        The diagnosis in the JSON shape of ``arxid diagnose --json`` and the ladder itself.
    """
    from .diagnose import Ladder

    ladder = Ladder.run(model, est, val, max_steps=max_steps, horizon=horizon)
    return ladder.diagnoses[0].to_dict(ladder), ladder


def analyse(data: IOData, validation: IOData | float | None = None, *, orders=None, grid=None,
            horizon: int | None = None, max_steps: int = 3, progress: bool = False,
            expect: str | None = None) -> Analysis:
    """Sweep (unless ``orders`` are given), choose the best sane model, diagnose it and climb the ladder.

    Parameters
    ----------
    data : IOData
        Estimation data, or all data when ``validation`` is a fraction.
    validation : IOData or float, optional
        Validation data, or the fraction of ``data`` used for estimation (default 0.7).
    orders : (na, nb, nk), optional
        Fixed structure; skips the sweep.
    grid : dict with keys na, nb, nk, optional
        Sweep grid (default :data:`DEFAULT_GRID`).
    horizon : int, optional
        Prediction horizon for validation errors (None: free run, or what the sweep detected for an
        integrating plant).
    max_steps : int
        Largest number of effects the ladder adds.
    progress : bool
        Progress bars on stderr.
    expect : str, optional
        Passed to the sweep's step sanity check (``"stable"``, ``"integrating"``,
        ``"double-integrating"``).
    """
    if not isinstance(data, IOData):
        raise DataError(f"analyse needs arxid.IOData, got {type(data).__name__}")
    if validation is None:
        validation = 0.7
    if isinstance(validation, IOData):
        est, val = data, validation
    else:
        est, val = data.split(float(validation))
    timings, notes = {}, []
    t0 = time.perf_counter()
    sw = table = None
    rejected: dict = {}
    if orders is None:
        sw, table, model, rejected = run_sweep(est, val, grid, progress=progress, expect=expect, horizon=horizon)
        if horizon is None and getattr(sw, "horizon", None) is not None:
            horizon = int(sw.horizon)  # an integrating plant: diagnose on the sweep's k-step measure
            notes.append(f"The sweep found an integrating plant ({getattr(sw, 'integrating_reason', '')}); "
                         f"validation errors are {horizon}-step-ahead prediction errors, not free-run.")
    else:
        na, nb, nk = _orders_of(orders)
        model = arx(est, na, nb, nk)
    timings["sweep"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    diag, ladder = diagnose_ladder(est, val, model, horizon=horizon, max_steps=max_steps)
    timings["diagnose"] = time.perf_counter() - t0
    final = ladder.final_model if len(ladder) > 1 else model
    return Analysis(est, val, sw, table, model, rejected, diag, final, timings, notes)


# ---------------------------------------------------------------------------------------- HTML
_CSS = """
:root { --ink:#1d232a; --muted:#5b6670; --line:#d5dbe1; --accent:#1f6feb; --bad:#b42318; --good:#067647; }
* { box-sizing: border-box; }
body { font: 15px/1.5 system-ui, -apple-system, "Segoe UI", Roboto, "DejaVu Sans", sans-serif; color: var(--ink);
       max-width: 1000px; margin: 0 auto; padding: 1.5rem 1.25rem 4rem; background: #fff; }
h1 { font-size: 1.6rem; margin: 0 0 .25rem; }
h2 { font-size: 1.2rem; margin: 2.2rem 0 .6rem; padding-bottom: .2rem; border-bottom: 2px solid var(--line); }
h3 { font-size: 1rem; margin: 1.2rem 0 .4rem; }
p.lead { color: var(--muted); margin-top: 0; }
nav ol { columns: 2; font-size: .9rem; padding-left: 1.2rem; }
nav a, a { color: var(--accent); text-decoration: none; }
table { border-collapse: collapse; font-size: .85rem; margin: .4rem 0 1rem; font-variant-numeric: tabular-nums; }
th, td { border-bottom: 1px solid var(--line); padding: .25rem .6rem; text-align: right; white-space: nowrap; }
th { background: #f3f5f7; text-align: center; }
td.l, th.l { text-align: left; }
tr.chosen td { background: #e8f1fd; font-weight: 600; }
tr.flagged td { color: var(--muted); }
.sig { color: var(--good); font-weight: 600; }
.bad { color: var(--bad); }
figure { margin: .6rem 0 1.2rem; }
figure img { max-width: 100%; height: auto; border: 1px solid var(--line); }
figcaption { font-size: .85rem; color: var(--muted); }
pre.eq { background: #f6f8fa; border: 1px solid var(--line); padding: .7rem; overflow-x: auto; font-size: .82rem; white-space: pre-wrap; }
.cards { display: flex; flex-wrap: wrap; gap: .6rem; margin: .6rem 0; }
.card { border: 1px solid var(--line); border-radius: 6px; padding: .5rem .8rem; min-width: 11rem; }
.card b { display: block; font-size: 1.25rem; }
.card span { font-size: .8rem; color: var(--muted); }
.note { background: #fff8e6; border-left: 4px solid #f5a524; padding: .4rem .8rem; font-size: .9rem; }
footer { margin-top: 3rem; font-size: .8rem; color: var(--muted); }
@media print {
  body { max-width: none; padding: 0; font-size: 10.5pt; }
  nav { display: none; }
  h2 { break-before: auto; break-after: avoid; }
  figure, table, .cards { break-inside: avoid; }
  a { color: inherit; }
}
"""


def _e(x) -> str:
    return html.escape(str(x), quote=True)


def _num(v, digits: int = 4) -> str:
    if v is None:
        return "–"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    try:
        f = float(v)
    except (TypeError, ValueError):
        return _e(v)
    if not math.isfinite(f):
        return "–" if math.isnan(f) else ("∞" if f > 0 else "−∞")
    return f"{f:.{digits}g}"


def _img(fig, alt: str, caption: str = "") -> str:
    from .plots.report import figure_to_data_uri

    uri = figure_to_data_uri(fig)
    cap = f"<figcaption>{_e(caption)}</figcaption>" if caption else ""
    return f'<figure><img src="{uri}" alt="{_e(alt)}">{cap}</figure>'


def _table(headers: Sequence[str], rows: Sequence[Sequence[str]], classes: Sequence[str] | None = None,
           left: int = 1) -> str:
    th = "".join(f'<th class="{"l" if i < left else ""}">{_e(h)}</th>' for i, h in enumerate(headers))
    body = []
    for k, r in enumerate(rows):
        cls = f' class="{classes[k]}"' if classes and classes[k] else ""
        tds = "".join(f'<td class="{"l" if i < left else ""}">{c}</td>' for i, c in enumerate(r))
        body.append(f"<tr{cls}>{tds}</tr>")
    return f"<table><thead><tr>{th}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _horizon_text(h) -> str:
    return "free-run simulation" if h is None else f"{h}-step-ahead prediction"


_SWEEP_COLUMNS = ("structure", "rms_est", "rms_val", "fit_val", "rms_val_one_step", "fpe", "n_params", "stable",
                  "max_pole", "step_sanity")


def _sweep_section(a: Analysis) -> str:
    from .plots.report import sweep_heatmap

    if a.table is None:
        return "<p>The orders were given, so no sweep was run.</p>"
    df = a.table
    cols = [c for c in _SWEEP_COLUMNS if c in df.columns] or [c for c in df.columns if c != "parameters"]
    chosen = a.model.structure_name()
    rows, classes = [], []
    for _, r in df.head(15).iterrows():
        cells = []
        for c in cols:
            v = r[c]
            if isinstance(v, (list, tuple, np.ndarray)):
                v = ",".join(str(x) for x in np.ravel(v))
            cells.append(_e(v) if isinstance(v, str) else _num(v))
        rows.append(cells)
        name = str(r.get("structure", ""))
        classes.append("chosen" if name == chosen else ("flagged" if name in a.rejected else ""))
    measure = getattr(a.sweep, "measure", "free-run simulation")
    parts = [f"<p>{len(df)} structures fitted on the estimation data ({a.estimation.n_samples} samples) and "
             f"validated on the validation data ({a.validation.n_samples} samples) by {_e(measure)}; the best 15 "
             f"are shown, ranked by validation RMS (<code>rms_val</code>). The chosen structure is highlighted; "
             f"grey rows failed the step sanity check.</p>",
             _table(cols, rows, classes, left=1)]
    if a.rejected:
        parts.append("<p>Skipped by the step sanity check: " + "; ".join(
            f"<b>{_e(k)}</b>: {_e(v)}" for k, v in a.rejected.items()) + "</p>")
    fig = None
    if hasattr(a.sweep, "plot"):
        try:
            fig = a.sweep.plot()
        except (ArxidError, ValueError, ImportError):  # the sweep's own plot is optional; ours follows
            fig = None
    if fig is None and {"na", "nb", "nk", "rms_val"} <= set(df.columns) and df["nb"].map(np.isscalar).all():
        fig = sweep_heatmap(df, "rms_val", nb_value=a.model.nb[0] if len(a.model.nb) == 1 else None)
    if fig is not None:
        parts.append(_img(fig, "sweep heat map", "Validation error over the order grid; lower is better."))
    return "\n".join(parts)


def _step_section(a: Analysis) -> str:
    from .plots.report import step_checks

    val = a.validation
    amp = float(np.nanstd(val.u[:, 0])) or 1.0
    n = min(val.n_samples, max(50, int(round(2.0 / val.ts)) if val.ts < 0.05 else 200))
    models = [("chosen " + a.model.structure_name(), a.model)]
    flags = {}
    if a.sweep is not None and a.rejected:
        names = [a.sweep.structure_name(i) for i in range(min(len(a.sweep), 40))]
        for name, reason in list(a.rejected.items())[:3]:
            if name in names:
                models.append((name, a.sweep.model(names.index(name))))
                flags[name] = reason
    responses = []
    for label, m in models:
        try:
            responses.append((label, m.step(n, amp, 0)))
        except ArxidError:
            continue
    fig = step_checks(responses, val.ts, flags)
    dc = a.model.dc_gain() if a.model.is_stable else None
    text = (f"<p>Response to a step of one standard deviation of {_e(val.input_names[0])} "
            f"({amp:.4g}) over {n * val.ts:g} s. A plausible model responds with the sign and size the "
            f"measured output suggests (seed 004 rejected its best-ranked ARX(2,2,0) this way). "
            f"The chosen model is {'stable' if a.model.is_stable else 'not asymptotically stable (integrating)'}"
            + (f", DC gain {', '.join(_num(g) for g in np.atleast_1d(dc))}" if dc is not None else "") + ".</p>")
    return text + _img(fig, "step responses", "Positive and negative steps of the chosen (and rejected) structures.")


def _residual_tests_html(rt: dict) -> str:
    if not rt:
        return "<p>No residual tests were reported.</p>"
    rows = []
    def walk(prefix, obj):
        if isinstance(obj, dict):
            for k, v in obj.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        elif isinstance(obj, (list, tuple)) and obj and isinstance(obj[0], dict):
            for i, v in enumerate(obj):
                walk(f"{prefix}[{v.get('signal', v.get('name', i))}]", {k: x for k, x in v.items() if k not in ("signal", "name")})
        else:
            if isinstance(obj, (list, tuple)) and len(obj) > 8:
                obj = f"{len(obj)} values"
            rows.append([_e(prefix), _num(obj) if not isinstance(obj, (str, list, tuple)) else _e(obj)])
    walk("", rt)
    return _table(["test", "value"], rows[:60])


def _suspects_html(suspects: list) -> str:
    if not suspects:
        return "<p>No candidate effects were scored.</p>"
    rows, classes = [], []
    for i, s in enumerate(suspects[:15], start=1):
        sig = bool(s.get("significant"))
        rows.append([str(i), _e(s.get("effect")), _num(s.get("score")), _num(s.get("p_value")),
                     f'<span class="{"sig" if sig else ""}">{"yes" if sig else "no"}</span>',
                     _num(s.get("rms_sim_val_after"))])
        classes.append("chosen" if sig and i == 1 else "")
    return _table(["rank", "effect", "score (partial corr.)", "p-value", "significant", "validation error after"],
                  rows, classes, left=2)


def _ladder_rows(a: Analysis) -> list[tuple[str, float]]:
    out = []
    for step in a.ladder:
        eff = step.get("effects") or []
        out.append(("ARX" if not eff else "+ " + ", ".join(eff), step.get("rms_sim_val")))
    return out


def render_html(a: Analysis, title: str | None = None, source: str = "") -> str:
    """The report of ``a`` as one self-contained HTML document (plots embedded as PNG).

    Parameters
    ----------
    a : Analysis
    title : str, optional
    source : str
        Where the data came from, shown under the title.
    """
    from .plots import report as plots

    est, val, model, final = a.estimation, a.validation, a.model, a.final_model
    h = a.horizon
    title = title or f"arxid report: {est.output_name} from {', '.join(est.input_names)}"
    diag = a.diagnosis
    base = diag.get("baseline", {})
    ladder = _ladder_rows(a)
    first = ladder[0][1] if ladder else base.get("rms_sim_val")
    last = ladder[-1][1] if ladder else first
    fall = (1 - last / first) * 100 if first and last is not None and first > 0 else None
    sections: list[tuple[str, str, str]] = []

    # 1. data
    full = IOData.merge([est, val]) if hasattr(IOData, "merge") else est
    cards = (f'<div class="cards"><div class="card"><b>{est.n_samples} + {val.n_samples}</b><span>estimation + validation samples</span></div>'
             f'<div class="card"><b>{est.ts:g} s</b><span>sampling time</span></div>'
             f'<div class="card"><b>{_e(model.structure_name())}</b><span>chosen structure</span></div>'
             f'<div class="card"><b>{_num(first)} → {_num(last)}</b><span>validation RMS error ({_e(_horizon_text(h))})</span></div>'
             + (f'<div class="card"><b>{fall:.0f} %</b><span>error removed by the added effects</span></div>' if fall is not None else "")
             + "</div>")
    sections.append(("data", "Data", cards + f"<pre class=\"eq\">{_e(repr(est))}</pre>"
                     + _img(plots.data_overview(full), "data overview", "Output (blue), inputs (orange) and extra signals (green).")))
    # 2. sweep
    sections.append(("sweep", "Order sweep", _sweep_section(a)))
    # 3. model
    eq = f"<h3>Chosen model</h3><pre class=\"eq\">{_e(str(model))}</pre>"
    if final is not model:
        eq += f"<h3>With the added effects</h3><pre class=\"eq\">{_e(str(final))}</pre>"
    sections.append(("model", "Model equation", eq))
    # 4. step checks
    sections.append(("steps", "Step-response checks", _step_section(a)))
    # 5. compare
    p0 = model.predict(val, h)
    preds = [(f"{model.structure_name()} (fit {model._fit_percent(val.y, p0):.1f} %)", p0)]
    if final is not model:
        p1 = final.predict(val, h)
        preds.append((f"+ {', '.join(final.effects)} (fit {final._fit_percent(val.y, p1):.1f} %)", p1))
    sections.append(("compare", "Measured against simulated output",
                     f"<p>Validation data, {_e(_horizon_text(h))}.</p>"
                     + _img(plots.measured_vs_simulated(val, preds), "measured vs simulated",
                            "Measured output (black) and model outputs, error underneath.")))
    # 6. residuals
    e1 = val.y - model.predict(val, 1)
    sig = {n: val.signal(n) for n in (*val.input_names, *list(val.extra)[:5])}
    sections.append(("residuals", "Residual tests",
                     _residual_tests_html(diag.get("residual_tests") or {})
                     + _img(plots.residual_correlations(e1, sig), "residual correlations",
                            "Whiteness of the one-step residual and its independence from inputs and logged signals.")))
    # 7. where it fails
    errs = [(model.structure_name(), val.y - p0)]
    if final is not model:
        errs.append(("+ " + ", ".join(final.effects), val.y - preds[1][1]))
    names = [val.output_name, "d" + val.output_name, *val.input_names, *list(val.extra)[:4]]
    sections.append(("fails", "Where it fails",
                     _img(plots.error_in_time(val, errs), "error in time", "Rolling RMS of measured − model on validation data.")
                     + _img(plots.error_by_signal(val, errs[0][1], names, other=errs[1][1] if len(errs) > 1 else None),
                            "error by operating point", "Error binned by each signal; a trend names the missing physics.")))
    # 8. suspects
    suspects = diag.get("suspects") or []
    sig_s = [s for s in suspects if s.get("significant")]
    verdict = (f"<p><b>Missing effect: {_e(sig_s[0]['effect'])}</b> (validation error {_num(base.get('rms_sim_val'))} → "
               f"{_num(sig_s[0].get('rms_sim_val_after'))}).</p>" if sig_s else
               "<p><b>No significant missing effect</b>: no candidate passed both the corrected F-test and a real "
               "validation improvement.</p>")
    sections.append(("suspects", "Which effect is missing", verdict + _suspects_html(suspects)))
    # 9. ladder
    lad = ""
    if ladder:
        rows = [[str(i), _e(lbl), _num(v), (f"{(1 - v / first) * 100:.1f} %" if first and v is not None else "–")]
                for i, (lbl, v) in enumerate(ladder)]
        lad = _table(["step", "model", "validation RMS error", "fall vs. step 0"], rows, left=2)
        lad += _img(plots.error_ladder(ladder, f"validation RMS error ({_horizon_text(h)})"), "error ladder",
                    "Each step adds the best significant suspect and re-diagnoses.")
    sections.append(("ladder", "Error ladder", lad or "<p>No ladder.</p>"))

    notes = "".join(f'<p class="note">{_e(n)}</p>' for n in a.notes)
    nav = "<nav><ol>" + "".join(f'<li><a href="#{k}">{_e(t)}</a></li>' for k, t, _ in sections) + "</ol></nav>"
    body = "\n".join(f'<section id="{k}"><h2>{i}. {_e(t)}</h2>\n{c}</section>' for i, (k, t, c) in enumerate(sections, 1))
    timing = ", ".join(f"{k} {v:.1f} s" for k, v in a.timings.items())
    import arxid
    return (f"<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
            f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>"
            f"<header><h1>{_e(title)}</h1><p class=\"lead\">{_e(source)}"
            f"{' · ' if source else ''}generated by arxid {_e(arxid.__version__)} on {time.strftime('%Y-%m-%d %H:%M')}</p></header>"
            f"{notes}{nav}{body}<footer>Timings: {_e(timing)}. Validation errors are {_e(_horizon_text(h))} RMS on the "
            f"validation data. Diagnosis data (JSON) embedded below.</footer>"
            f"<script type=\"application/json\" id=\"diagnosis\">{_script_json(diag)}</script>"
            f"</body></html>\n")


@dataclass(frozen=True, eq=False)
class Report:
    """A rendered report: ``html`` (one self-contained document) and the ``analysis`` behind it."""

    html: str
    analysis: Analysis

    def save(self, path) -> Path:
        """Write the HTML to ``path`` (UTF-8) and return the path."""
        p = Path(path)
        p.write_text(self.html, encoding="utf-8")
        return p

    def __str__(self) -> str:
        a = self.analysis
        lad = " → ".join(_num(v) for _, v in _ladder_rows(a))
        return f"Report: {a.model.structure_name()}, ladder {lad}, {len(self.html) / 1e6:.1f} MB of HTML"


def build_report(data: IOData, validation: IOData | float | None = None, *, orders=None, grid=None,
                 horizon: int | None = None, max_steps: int = 3, progress: bool = False,
                 expect: str | None = None, title: str | None = None, source: str = "") -> Report:
    """:func:`analyse` then :func:`render_html`: the whole report in one call.

    Parameters
    ----------
    data, validation, orders, grid, horizon, max_steps, progress, expect
        As in :func:`analyse`.
    title, source
        As in :func:`render_html`.

    Returns
    -------
    Report
        ``.html`` (the document), ``.analysis``; ``.save(path)`` writes it.
    """
    a = analyse(data, validation, orders=orders, grid=grid, horizon=horizon, max_steps=max_steps,
                progress=progress, expect=expect)
    return Report(render_html(a, title=title, source=source), a)
