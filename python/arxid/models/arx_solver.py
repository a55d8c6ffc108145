"""The least-squares steps of an ARX fit, before and after the Rust core's QR: the orders per input,
the checks that the data can determine the parameters (enough rows, inputs that vary), the solve of
the regressors or of their triangular factor, and the error that names a collinear regressor."""

from __future__ import annotations

import functools
import types
import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base import _core
from .._base.limits import check_memory, check_order
from ..data.iodata import IOData
from ..exceptions import DataError, IdentifiabilityError, OrderError
from .effects import EffectLayout, compile_effects
from .excitation import check_excitation
from .regressors import dependent_partners, max_lag, regressor_matrix, regressor_names, row_bound

__all__ = [
    "check_inputs_vary",
    "check_rows",
    "check_size",
    "checked_layout",
    "checked_solution",
    "collinear",
    "fit_memory",
    "per_input",
    "solve",
    "solve_factor",
]


def per_input(name: str, value: Any, m: int) -> tuple[int, ...]:
    """One checked order per input, from a sequence of them or one for all."""
    if isinstance(value, (list, tuple, np.ndarray)):
        vals = tuple(check_order(f"{name}[{i}]", v) for i, v in enumerate(value))
        if len(vals) != m:
            raise OrderError(
                f"{name} has {len(vals)} entries but the data have {m} inputs; give one per input or a single integer"
            )
        return vals
    return (check_order(name, value),) * m


def checked_layout(
    model: Any, data: IOData, first_lag: int, n_threads: int
) -> tuple[tuple[int, tuple[int, ...], tuple[int, ...]], EffectLayout]:
    """The orders per input and the effect layout of ``model`` (an unfitted ARX model's ``na``,
    ``nb``, ``nk``, ``effects``) on ``data``, after the checks of its fit: orders, rows, memory and
    inputs that vary. They read the inputs and the record's size only, so fits of one record that
    differ in the output alone (a sensor's g⁻¹(y)) pass or fail them alike."""
    m = data.n_inputs
    na, nb, nk = check_order("na", model.na), per_input("nb", model.nb, m), per_input("nk", model.nk, m)
    first_lag, n_threads = check_order("first_lag", first_lag), check_order("n_threads", n_threads)
    layout = compile_effects(model.effects, data, nb, nk)
    p, usable = check_size(na, layout, data, first_lag)
    check_memory(
        fit_memory(usable, p, n_threads) + layout.u.nbytes,
        f"the fit of {model.structure_name()} ({p} parameters) on {usable:,} regression rows",
        "lower the orders or use fewer samples",
    )
    check_inputs_vary(data, nb)
    return (na, nb, nk), layout


def checked_solution(
    model: Any, data: IOData, first_lag: int, n_threads: int, rows_like: tuple | None = None
) -> tuple[tuple[int, tuple[int, ...], tuple[int, ...]], EffectLayout, list[str], Any]:
    """What the fit of ``model`` on ``data`` finds, without storing it: the orders per input, the
    effect layout, the regressor names and the core's solution (its ``rss``, ``theta``...), after
    the checks of :func:`checked_layout` (a scan reads the loss of many refits this way)."""
    orders, layout = checked_layout(model, data, first_lag, n_threads)
    names = regressor_names(data.output_name, orders[0], layout)
    first_lag, n_threads = check_order("first_lag", first_lag), check_order("n_threads", n_threads)
    return orders, layout, names, solve(data, orders[0], layout, names, first_lag, n_threads, rows_like)


def check_size(na: int, layout: EffectLayout, data: IOData, first_lag: int) -> tuple[int, int]:
    """The parameter count and the regression rows at most available, after checking the data leave
    enough rows for the parameters.

    Counted, not listed: orders far beyond the data must fail here, not while naming 10^12 regressors.
    """
    lag = max(first_lag, max_lag(na, layout))
    usable = row_bound(data, lag)
    return check_rows(na, layout, usable, data.n_samples, lag), usable


def check_rows(na: int, layout: EffectLayout, usable: int, n_samples: int, lag: int) -> int:
    """The parameter count, after checking that ``usable`` regression rows can determine them."""
    p = na + sum(layout.nb) + len(layout.output_terms)
    if p == 0:
        raise OrderError("the model has no parameters: use na >= 1 or nb >= 1")
    if usable < p + 1:
        raise DataError(
            f"too few samples for the orders: {p} parameters need at least {p + 1} regression rows, "
            f"but {n_samples} samples minus the largest lag {lag} per experiment leave {usable}; "
            f"lower na/nb/nk or use more data"
        )
    return p


@functools.lru_cache(maxsize=256)
def fit_memory(usable: int, p: int, n_threads: int) -> int:
    """The core's estimate of a fit's bytes (the same few sizes, asked for by every refit of a diagnosis)."""
    return int(_core.fit_memory(usable, p, n_threads))


def check_inputs_vary(data: IOData, nb: Sequence[int]) -> None:
    """:func:`~arxid.models.excitation.check_excitation`, once per input matrix: a diagnosis refits
    dozens of models on records that share one (a sensor shape's fit reads the output through g⁻¹
    and the inputs as they are). Only a pass is kept: a refused input is refused each time."""
    need = frozenset(i for i, b in enumerate(nb) if b)
    u, key = data.u, id(data.u)
    seen = _VARY.get(key)
    done = seen[1] if seen is not None and seen[0]() is u else frozenset()
    if need <= done:
        return
    check_excitation(data, nb)
    # the entry goes with the samples (a later array may reuse the id)
    _VARY[key] = (weakref.ref(u, functools.partial(_forget, key)), done | need)


def _forget(key: int, _: weakref.ref) -> None:
    _VARY.pop(key, None)


#: The inputs found to vary, by input matrix (its id, with a reference that says it is still that
#: one). Each access is one dict operation (atomic under the GIL: no lock, which a weak reference's
#: callback run inside a locked block would deadlock on).
_VARY: dict[int, tuple[weakref.ref, frozenset[int]]] = {}


def solve(
    data: IOData,
    na: int,
    layout: EffectLayout,
    names: list[str],
    first_lag: int,
    n_threads: int,
    rows_like: tuple[int, Sequence[int], Sequence[int]] | None,
) -> Any:
    """The core's QR solve; a rank-deficient regressor is named with the columns it depends on."""
    y = np.require(data.y, requirements=["C", "A"])  # arrays unpickled on a Dask worker may be misaligned
    try:
        res = _core.fit(
            y,
            layout.u,
            list(data.experiment_starts),
            na,
            list(layout.nb),
            list(layout.nk),
            list(layout.output_terms),
            first_lag=first_lag,
            n_threads=n_threads,
            rows_like=rows_like,
        )
    except IdentifiabilityError as exc:
        if getattr(exc, "column", None) is None:
            raise
        phi, _, _ = regressor_matrix(data, na, layout, first_lag)
        raise collinear(exc.column, phi, names) from None  # type: ignore[attr-defined]
    return res


def collinear(col: int, phi: np.ndarray, names: list[str]) -> IdentifiabilityError:
    """The error naming a regressor that depends on the ones before it. ``phi`` is the regressor
    matrix, or its triangular factor R (the same least squares, so the same partners)."""
    partners = dependent_partners(phi, col, names)
    return IdentifiabilityError(
        f"regressor {names[col]} is a linear combination of {', '.join(partners) or 'the regressors before it'} "
        f"on these data (collinear regressors): remove one of them, lower the orders, or use data that excite them "
        f"independently",
        tuple(partners) + (names[col],),
    )


def solve_factor(r: np.ndarray, n_rows: int, usable: int, na: int, layout: EffectLayout, names: list[str]) -> Any:
    """The fit from the triangular factor R of ``[Φ | y]`` over logs kept elsewhere, as :func:`solve`
    gives it (``theta``, ``rss``, ``n_rows``, ``n_skipped``, ``inv_gram``)."""
    if n_rows < r.shape[0]:
        raise DataError(
            f"too few complete regression rows on these logs: {r.shape[0] - 1} parameters need at least "
            f"{r.shape[0]}, the logs have {n_rows} without missing samples; lower na/nb/nk or use more data"
        )
    orders = (na, list(layout.nb), list(layout.nk))
    try:
        out = _core.fit_from_factor(r, n_rows, orders, orders, list(layout.output_terms))
    except IdentifiabilityError as exc:
        if getattr(exc, "column", None) is None:
            raise
        raise collinear(exc.column, r[:, :-1], names) from None  # type: ignore[attr-defined]
    return types.SimpleNamespace(
        theta=out.theta, rss=out.rss, n_rows=n_rows, n_skipped=usable - n_rows, inv_gram=out.inv_gram
    )
