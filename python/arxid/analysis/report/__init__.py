"""One self-contained HTML report of an identification: data, sweep, model, checks, diagnosis, ladder.

:func:`render_html` renders an :class:`~arxid.Analysis` (from :func:`arxid.analyse`) as one HTML file
whose plots are embedded PNG images; it opens offline and prints. :func:`build_report` does both.

Examples
--------
>>> import arxid
>>> from arxid.report import build_report
>>> rep = build_report(data, orders=(2, 1, 3))                    # doctest: +SKIP
>>> rep.save("report.html")                                        # doctest: +SKIP
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..._base.formatting import format_value, json_safe
from ...data.iodata import IOData
from ..pipeline import Analysis, analyse
from .html import render_html

__all__ = ["Report", "render_html", "build_report", "json_safe", "Analysis", "analyse"]


@dataclass(frozen=True, eq=False)
class Report:
    """A rendered report: ``html`` (one self-contained document) and the ``analysis`` behind it."""

    html: str
    analysis: Analysis

    def save(self, path: str | Path) -> Path:
        """Write the HTML to ``path`` (UTF-8).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        p = Path(path)
        p.write_text(self.html, encoding="utf-8")
        return p

    def __str__(self) -> str:
        lad = " → ".join(format_value(v) for v in self.analysis.ladder.errors)
        return f"Report: {self.analysis.model.structure_name()}, ladder {lad}, {len(self.html) / 1e6:.1f} MB of HTML"


def build_report(
    data: IOData, validation: IOData | None = None, *, title: str | None = None, source: str = "", **analyse_kwargs: Any
) -> Report:
    """:func:`arxid.analyse` then :func:`render_html`: the whole report in one call.

    Parameters
    ----------
    data, validation
        As in :func:`arxid.analyse`.
    title, source
        As in :func:`render_html`.
    **analyse_kwargs
        Passed to :func:`arxid.analyse` (``split``, ``orders``, ``grid``, ``horizon``, ``max_steps`` ...).

    Returns
    -------
    Report
        ``.html`` (the document), ``.analysis``; ``.save(path)`` writes it.
    """
    a = analyse(data, validation, **analyse_kwargs)
    return Report(render_html(a, title=title, source=source), a)
