"""The blocks the HTML reports are built from: elements whose text is escaped (:func:`el`), tables,
paragraphs, embedded figures, the JSON of a ``<script>`` element, and the page itself
(:func:`page`: ``template.html`` with ``report.css``)."""

from __future__ import annotations

import html
import json
import string
import time
from collections.abc import Mapping, Sequence
from importlib import resources
from typing import Any

from ..._base.formatting import format_value, json_safe

__all__ = ["Raw", "el", "join", "script_json", "number", "table", "figure", "paragraph", "page"]


class Raw(str):
    """Markup that is already safe (built by :func:`el`), inserted as it is."""


def el(tag: str, *children: Any, cls: str = "", **attrs: str) -> Raw:
    """One element: text children are escaped, :class:`Raw` children are inserted as they are.

    Parameters
    ----------
    tag : str
        Element name.
    *children : str or Raw
        Content, in order.
    cls : str
        The class attribute.
    **attrs : str
        Other attributes.

    Returns
    -------
    Raw
    """
    if cls:
        attrs["class"] = cls
    at = "".join(f' {k}="{html.escape(str(v), quote=True)}"' for k, v in attrs.items())
    inner = "".join(c if isinstance(c, Raw) else html.escape(str(c)) for c in children)
    return Raw(f"<{tag}{at}>{inner}</{tag}>")


def join(parts: Sequence[str]) -> Raw:
    """Blocks one after the other, one a line (plain strings escaped).

    Parameters
    ----------
    parts : sequence of str or Raw

    Returns
    -------
    Raw
    """
    return Raw("\n".join(p if isinstance(p, Raw) else html.escape(p) for p in parts))


def script_json(obj: Any) -> str:
    """JSON for a ``<script type="application/json">`` element: its text is raw (no entities), so
    ``<``, ``>`` and ``&`` become ``\\u`` escapes and no ``</script>`` can end it early.

    Parameters
    ----------
    obj : Any
        JSON-able after :func:`arxid._format.json_safe`.

    Returns
    -------
    str
    """
    text = json.dumps(json_safe(obj), allow_nan=False)
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def number(v: Any, digits: int = 4) -> str:
    """A number as the reports print it (``format_value``: NaN and inf in words).

    Parameters
    ----------
    v : float
    digits : int
        Significant digits.

    Returns
    -------
    str
    """
    return format_value(v, digits)


def table(
    headers: Sequence[str],
    rows: Sequence[Sequence[Any]],
    classes: Sequence[str] = (),
    left: int = 1,
    wrap: Sequence[int] = (),
) -> Raw:
    """A table; the first ``left`` columns are left-aligned, the columns in ``wrap`` wrap their text.

    Parameters
    ----------
    headers : sequence of str
    rows : sequence of sequences
        Cells: text (escaped) or :class:`Raw`.
    classes : sequence of str
        A class per row (``"chosen"``, ...).
    left : int
        Left-aligned columns, from the first.
    wrap : sequence of int
        Columns whose text wraps.

    Returns
    -------
    Raw
    """

    def cls(i: int) -> str:
        return "l wrap" if i in wrap else ("l" if i < left else "")

    head = el("tr", *[el("th", h, cls=cls(i)) for i, h in enumerate(headers)])
    body = []
    for k, r in enumerate(rows):
        cells = [el("td", c if isinstance(c, Raw) else str(c), cls=cls(i)) for i, c in enumerate(r)]
        body.append(el("tr", *cells, cls=classes[k] if k < len(classes) else ""))
    return el("table", el("thead", head), el("tbody", *body))


def figure(fig: Any, alt: str, caption: str = "") -> Raw:
    """A figure embedded as a PNG (no file, no network), with its caption.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    alt : str
        The image's text for screen readers and broken images.
    caption : str

    Returns
    -------
    Raw
    """
    from ...plots import figure_to_data_uri

    parts = [Raw(f'<img src="{figure_to_data_uri(fig)}" alt="{html.escape(alt, quote=True)}">')]
    if caption:
        parts.append(el("figcaption", caption))
    return el("figure", *parts)


def paragraph(*children: Any, cls: str = "") -> Raw:
    """A paragraph (text escaped).

    Parameters
    ----------
    *children : str or Raw
    cls : str
        Its class (``"small"`` for a note).

    Returns
    -------
    Raw
    """
    return el("p", *children, cls=cls)


def page(
    title: str,
    source: str,
    sections: Sequence[tuple[str, str, Raw]],
    notes: Sequence[str],
    timings: Mapping[str, float],
    measure: str,
    analysis: Any,
) -> str:
    """One self-contained HTML document: the title, the notes, a numbered section a part with the
    table of contents, the timings and the analysis' JSON.

    Parameters
    ----------
    title : str
    source : str
        Where the data came from, shown under the title.
    sections : sequence of (str, str, Raw)
        Each section's anchor, heading and body.
    notes : sequence of str
        Shown above the contents.
    timings : mapping of str to float
        Seconds per step.
    measure : str
        What the validation errors are (``free-run simulation``).
    analysis : dict
        Embedded as JSON (``<script id="diagnosis">``).

    Returns
    -------
    str
    """
    from ... import __version__

    files = resources.files(__package__)
    generated = f"generated by arxid {__version__} on {time.strftime('%Y-%m-%d %H:%M')}"
    return string.Template(files.joinpath("template.html").read_text(encoding="utf-8")).substitute(
        title=html.escape(title),
        css=files.joinpath("report.css").read_text(encoding="utf-8"),
        lead=html.escape(f"{source}{' · ' if source else ''}{generated}"),
        notes=join([paragraph(n, cls="note") for n in notes]),
        nav=join([el("li", el("a", name, href=f"#{key}")) for key, name, _ in sections]),
        sections=join(
            [el("section", el("h2", f"{i}. {name}"), body, id=key) for i, (key, name, body) in enumerate(sections, 1)]
        ),
        timings=html.escape(", ".join(f"{k} {v:.1f} s" for k, v in timings.items())),
        measure=html.escape(measure),
        analysis_json=script_json(analysis),
    )
