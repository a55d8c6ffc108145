"""A fitted ARX model as text (``str(model)``): its structure, one fraction B(z)/A(z) per input or
effect column, the output-derived terms over A(z), and the quality of the fit."""

from __future__ import annotations

from typing import Any

from .._base.formatting import format_polynomial

__all__ = ["describe"]


def describe(model: Any) -> str:
    """The printed form of a fitted ARX model.

    Parameters
    ----------
    model : ArxModel
        Fitted.

    Returns
    -------
    str
    """
    lines = [f"{model.structure_name()}   ts = {model.ts:g} s"] + _fraction_lines(model) + _term_lines(model)
    lines.append(
        f"  fit {model.fit_percent_:.2f}% (one-step, estimation), noise variance {model.noise_variance_:.4g}, "
        f"FPE {model.fpe_:.4g}, {model.n_rows_} rows"
        + (f", {model.n_skipped_} rows skipped (NaN)" if model.n_skipped_ else "")
    )
    if model.output_unit:
        lines.append(f"  output unit: {model.output_unit}")
    return "\n".join(lines)


def _fraction_lines(model: Any) -> list[str]:
    """y(z) = B(z)/A(z) u(z) z^-nk, one fraction per input or effect column (as a published
    quadrotor study, Sarıoğlu & Kural, writes it)."""
    den = format_polynomial(model.a.tolist())
    labels, lines, c = model.input_labels(), [], model.na_
    lhs = f"{model.output_name}(z) = "
    pad = " " * len(lhs)
    for j, (b, k) in enumerate(zip(model.layout_.nb, model.layout_.nk)):
        if b == 0:
            continue
        coefs = model.parameters_[c : c + b]
        c += b
        num = format_polynomial(coefs.tolist()) if b > 1 else f"{coefs[0]:.4g}"
        width = max(len(num), len(den))
        lines.append(pad + num.center(width))
        lines.append(
            (lhs if j == 0 else pad[:-2] + "+ ") + "-" * width + f" {labels[j]}(z)" + (f" z^-{k}" if k else "")
        )
        lines.append(pad + den.center(width))
    return lines


def _term_lines(model: Any) -> list[str]:
    c = model.na_ + sum(model.layout_.nb)
    out = []
    for j, (kind, power, mult) in enumerate(model.layout_.output_terms):
        coef = model.parameters_[c + j]
        out.append(f"      {'+' if coef >= 0 else '-'} {abs(coef):.4g}/A(z) · {_term_text(model, kind, power, mult)}")
    return out


def _term_text(model: Any, kind: str, power: int, mult: int) -> str:
    y = model.output_name
    g = {
        "pow": f"{y}(t-1)^{power}" if power != 1 else f"{y}(t-1)",
        "abs": f"|{y}(t-1)|",
        "sign": f"sign({y}(t-1))",
        "signdiff": f"sign(d{y}(t-1))",
    }[kind]
    return g + (" · carrier(t-1)" if mult >= 0 else "")
