"""Plain-text and JSON formatting shared by every result's ``__str__``, the CLI and the report."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = [
    "finite_or_none",
    "json_safe",
    "horizon_label",
    "horizon_text",
    "text_table",
    "format_value",
    "require_pandas",
    "format_polynomial",
]


def finite_or_none(x: Any) -> Any:
    """``x`` as a float, or None for NaN/inf (JSON has no NaN); other values unchanged."""
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(x) else None
    return x


def json_safe(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays turned into Python values and NaN/inf into ``None``,
    so ``json.dumps(..., allow_nan=False)`` gives valid JSON; objects with ``to_dict`` are expanded.

    Parameters
    ----------
    obj : Any
        A value, possibly nested in dicts, lists and tuples (dict keys become ``str``).

    Returns
    -------
    Any
        The same structure of dicts, lists, ``bool``, ``int``, ``float``, ``None`` and other values
        passed through unchanged.
    """
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
        return finite_or_none(float(obj))
    if hasattr(obj, "to_dict") and callable(obj.to_dict):
        return json_safe(obj.to_dict())
    return obj


def horizon_label(horizon: int | None) -> str:
    """Short name of an error measure: ``free run``, ``one-step`` or ``k-step``."""
    return "free run" if horizon is None else ("one-step" if horizon == 1 else f"{horizon}-step")


def horizon_text(horizon: int | None) -> str:
    """Long name of an error measure: ``free-run simulation`` or ``k-step-ahead prediction``."""
    return "free-run simulation" if horizon is None else f"{horizon}-step-ahead prediction"


def format_value(v: Any, digits: int = 4) -> str:
    """A table cell: ``-`` for None/NaN, yes/no for booleans, 4 significant digits for floats."""
    if v is None:
        return "-"
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, str):
        return v
    try:
        f = float(v)
    except (TypeError, ValueError):
        return str(v)
    if math.isnan(f):
        return "-"
    if math.isinf(f):
        return "inf" if f > 0 else "-inf"
    return f"{f:.{digits}g}"


def text_table(headers: Sequence[str], rows: Sequence[Sequence[Any]], title: str = "", digits: int = 4) -> str:
    """Plain-text table: first column left-aligned, the others right-aligned, a rule under the header."""
    cells = [[format_value(c, digits) for c in r] for r in rows]
    widths = [max([len(h)] + [len(r[i]) for r in cells]) for i, h in enumerate(headers)]

    def line(r: Sequence[str]) -> str:
        return "  ".join((c.ljust(w) if i == 0 else c.rjust(w)) for i, (c, w) in enumerate(zip(r, widths)))

    out = ([title] if title else []) + [line(list(headers)), "  ".join("-" * w for w in widths)]
    return "\n".join(out + [line(r) for r in cells])


def require_pandas() -> Any:
    """The pandas module, or an ImportError that names the extra to install."""
    try:
        import pandas as pd
    except ImportError:  # pragma: no cover
        raise ImportError("this needs pandas: pip install 'arxid[pandas]'") from None
    return pd


def format_polynomial(coefs: Sequence[float], var: str = "z", start: int = 0) -> str:
    """``1 - 1.959 z^-1 + 0.9567 z^-2`` from coefficients of z^-start, z^-(start+1), ..."""
    parts = []
    for i, c in enumerate(coefs):
        if c == 0 and len(coefs) > 1:
            continue
        p = start + i
        mag = f"{abs(c):.4g}"
        term = mag if p == 0 else (f"{mag} {var}^-{p}" if mag != "1" else f"{var}^-{p}")
        sign = "-" if c < 0 else "+"
        parts.append((sign, term))
    if not parts:
        return "0"
    first_sign, first = parts[0]
    out = ("-" if first_sign == "-" else "") + first
    for sign, term in parts[1:]:
        out += f" {sign} {term}"
    return out
