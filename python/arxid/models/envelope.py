"""Fits of many structures on the same rows from one factorization of their envelope.

Structures fitted on the same regression rows (a neighbourhood of orders searched around a model, or
the model with each of its candidate effects) are all sub-structures of one envelope: the largest
na, the union of their columns (inputs and effects), and per column the earliest delay and the
latest lag. The Rust core reduces the envelope's regressors ``[Φ | y]`` to
their triangular factor R in one pass over the data; each structure's least-squares fit is then a
small QR of its columns of R (``fit_from_factor``), with the same parameters, loss and (Φ'Φ)⁻¹ as
its own fit on those rows, to rounding. A neighbourhood of 26 structures costs one pass over the
data instead of 26.
"""

from __future__ import annotations

import types
from collections import Counter
from collections.abc import Iterator, Sequence
from itertools import accumulate

import numpy as np

from .._base import _core
from .._base.columns import write_columns
from ..data.iodata import IOData
from ..exceptions import ArxidError
from .effects import EffectLayout, compile_effects, effect_names, layout_column
from .regressors import max_lag, output_term_values, regressor_names

__all__ = ["EnvelopeFactor", "envelope_columns", "envelope_inputs"]

#: (na, nb, nk, effects) of one structure, nb and nk one per input.
Spec = tuple[int, Sequence[int], Sequence[int], Sequence[str]]


class EnvelopeFactor:
    """The triangular factor of the envelope of ``structures`` on ``data``.

    Parameters
    ----------
    data : IOData
        Estimation data without missing samples (structures on data with gaps keep their own rows:
        fit them one by one).
    structures : sequence of (na, nb, nk, effects)
        The structures to fit; nb and nk one per input. Their effects may differ: the envelope holds
        the union of their columns, an output term's regressor (g(y(t-1))·s(t-1) on the measured
        output) as one more column.
    first_lag : int
        Start the regression rows at least this far into each experiment (as ``ArxModel.fit``).

    Attributes
    ----------
    first_lag : int
        The first regression row of every experiment: the one most structures start on (at least
        ``first_lag``). A structure whose own fit starts elsewhere is left out of the envelope
        (:meth:`has` is False).

    Raises
    ------
    ArxidError
        When the data have missing samples.
    """

    def __init__(self, data: IOData, structures: Sequence[Spec], first_lag: int = 0):
        if not structures:
            raise ArxidError("an envelope needs at least one structure")
        self.data = data
        self.structures = [
            (int(na), tuple(int(b) for b in nb), tuple(int(k) for k in nk), effect_names(eff))
            for na, nb, nk, eff in structures
        ]
        # Each layout is compiled without its samples; the envelope's columns are computed one by one
        # (not every structure's whole input matrix). An output term is a column too: on the
        # estimation rows it is g(y(t-1))·s(t-1), a lag of its series.
        self.layouts = [compile_effects(eff, data, nb, nk, samples=False) for _, nb, nk, eff in self.structures]
        self.given_first_lag = int(first_lag)
        rows = [max(int(first_lag), max_lag(na, lay)) for (na, *_), lay in zip(self.structures, self.layouts)]
        # the most common (the first of equals, as Counter.most_common(1), without importing heapq)
        self.first_lag = max(Counter(rows).items(), key=lambda item: item[1])[0]
        self.inside = [r == self.first_lag for r in rows]
        labels = list(dict.fromkeys(c for lay, ok in zip(self.layouts, self.inside) if ok for c in _labels(lay)))
        _refuse_missing_output(data)  # before any column is formed
        # A column two labels name (a shape that replaces the input by an effect's own series) is
        # one column of the envelope: a duplicate would cost its share of the QR and fit nothing.
        self.alias = _same_columns(data, labels, [lay for lay, ok in zip(self.layouts, self.inside) if ok])
        self.labels = [label for label in labels if label not in self.alias]
        terms = {
            _TERM + text: (kind, power, self._at(lay.column_labels[carrier]) if carrier >= 0 else None)
            for lay in self.layouts
            for text, (kind, power, carrier) in zip(lay.effect_of_term, lay.output_terms)
        }
        columns = list(envelope_columns(data, self.labels, terms))
        self.columns = [_column_orders(lay, self.labels, self.alias) for lay in self.layouts]
        na_env = max(na for (na, *_), ok in zip(self.structures, self.inside) if ok)
        self.envelope = _envelope(na_env, [c for c, ok in zip(self.columns, self.inside) if ok])
        # The rows start at first_lag (at least the envelope's largest lag): a later start costs no
        # output lags the structures do not read.
        y = np.require(data.y, requirements=["C", "A"])
        starts = list(data.experiment_starts)
        self.r, self.n_rows = _core.envelope_factor(y, columns, starts, self.envelope, self.first_lag, n_threads=0)

    def has(self, i: int) -> bool:
        """Whether structure ``i`` is fitted from the factor (on its own rows).

        Parameters
        ----------
        i : int

        Returns
        -------
        bool
        """
        return self.inside[i]

    def add(self, structure: Spec) -> int | None:
        """Fit one more structure from the factor when the envelope holds it: its columns, lags
        within the envelope's and the envelope's rows (the same fit to rounding as from the factor of
        its own envelope, without another pass over the data).

        Parameters
        ----------
        structure : (na, nb, nk, effects)

        Returns
        -------
        int or None
            Its index (for :meth:`solve`), None when the envelope does not hold it.
        """
        na, nb, nk, eff = structure
        spec = (int(na), tuple(int(b) for b in nb), tuple(int(k) for k in nk), effect_names(eff))
        try:
            lay = compile_effects(spec[3], self.data, spec[1], spec[2], samples=False)
        except ArxidError:
            return None
        have = set(self.labels)
        if max(self.given_first_lag, max_lag(spec[0], lay)) != self.first_lag or spec[0] > self.envelope[0]:
            return None
        own = [self._at(label) for label in _labels(lay)]
        if any(label not in have for label in own) or len(set(own)) < len(own):  # two names of one column
            return None
        cols = _column_orders(lay, self.labels, self.alias)
        for b, k, b_env, k_env in zip(*cols, self.envelope[1], self.envelope[2], strict=True):
            if b > 0 and (k < k_env or b + k > b_env + k_env):
                return None
        self.structures.append(spec)
        self.layouts.append(lay)
        self.inside.append(True)
        self.columns.append(cols)
        return len(self.structures) - 1

    def _at(self, label: str) -> str:
        """The envelope's name of a structure's column."""
        return self.alias.get(label, label)

    def solve(self, i: int) -> tuple[EffectLayout, list[str], types.SimpleNamespace]:
        """The fit of structure ``i`` from the factor.

        Parameters
        ----------
        i : int
            Index into the structures given.

        Returns
        -------
        layout : EffectLayout
            The structure's own layout, without its samples.
        names : list of str
            Its regressor names.
        result : namespace
            ``theta``, ``rss``, ``n_rows``, ``n_skipped`` and ``inv_gram``, as the core's fit gives them,
            in the structure's own parameter order.

        Raises
        ------
        ArxidError
            When the structure is not in the envelope (see :meth:`has`).
        """
        if not self.inside[i]:
            raise ArxidError(f"structure {i} is fitted on other rows than the envelope's")
        layout, na = self.layouts[i], self.structures[i][0]
        nb, nk = self.columns[i]
        out = _core.fit_from_factor(self.r, self.n_rows, self.envelope, (na, nb, nk), [])
        own = _own_order(na, layout, self.labels, self.alias)
        theta = np.empty(len(own))
        theta[own] = np.asarray(out.theta)
        inv = np.empty((len(own), len(own)))
        inv[own[:, None], own] = np.asarray(out.inv_gram)
        res = types.SimpleNamespace(theta=theta, rss=out.rss, n_rows=out.n_rows, n_skipped=0, inv_gram=inv)
        return layout, regressor_names(self.data.output_name, na, layout), res


#: Label prefix of an output term's column in the envelope.
_TERM = "term:"


def _labels(layout: EffectLayout) -> list[str]:
    """The envelope columns a structure brings: its layout's, then one per output term."""
    return list(layout.column_labels) + [_TERM + text for text in layout.effect_of_term]


#: Columns of the envelope's input matrix computed before they are written together, a block of
#: rows at a time (:func:`write_columns`): one pass over the matrix per group, not per column.
_COLUMNS_AT_ONCE = 4


def envelope_inputs(data: IOData, labels: list[str], terms: dict[str, tuple] | None = None) -> np.ndarray:
    """The envelope's input matrix, one column per label (row-major, as the core reads it): an
    input or effect (:func:`layout_column`) or an output term's series (after its carrier's column,
    as the labels list them). Raises ArxidError when a sample is missing.

    Parameters
    ----------
    data : IOData
    labels : list of str
        Column labels (inputs, effects, output terms).
    terms : dict, optional
        ``label → (kind, power, carrier label or None)`` of the output terms among ``labels``.

    Returns
    -------
    ndarray of shape (n_samples, len(labels))
    """
    u = np.empty((data.n_samples, len(labels)))
    pending: dict[int, np.ndarray] = {}
    for j, col in enumerate(envelope_columns(data, labels, terms)):
        pending[j] = col
        if len(pending) == _COLUMNS_AT_ONCE:
            write_columns(u, pending)
            pending.clear()
    write_columns(u, pending)
    return u


def envelope_columns(data: IOData, labels: list[str], terms: dict[str, tuple] | None = None) -> Iterator[np.ndarray]:
    """The columns of :func:`envelope_inputs`, one at a time (C-contiguous; an input or a logged
    signal is the data's own samples), as the core's envelope factor reads them. Raises ArxidError
    at the first missing sample.

    Parameters
    ----------
    data : IOData
    labels : list of str
    terms : dict, optional

    Yields
    ------
    ndarray of shape (n_samples,)
    """
    terms = terms or {}
    # Refused at the first missing sample, before the other columns are formed (a record with gaps
    # is fitted structure by structure: they would be thrown away).
    _refuse_missing_output(data)
    carriers = {by for _, _, by in terms.values() if by is not None}
    kept: dict[str, np.ndarray] = {}  # the carriers, until their terms come (after them)
    for label in labels:
        if label in terms:
            kind, power, by = terms[label]
            col = _term_series(kind, power, None if by is None else kept[by], data)
        else:
            col = layout_column(label, data)
        if not np.isfinite(col).all():
            raise ArxidError(_MISSING)
        col = np.ascontiguousarray(col, dtype=float)
        if label in carriers:
            kept[label] = col
        yield col


_MISSING = "the envelope's fits need data without missing samples"


def _refuse_missing_output(data: IOData) -> None:
    if not np.isfinite(data.y).all():
        raise ArxidError(_MISSING)


def _term_series(kind: str, power: int, carrier: np.ndarray | None, data: IOData) -> np.ndarray:
    """g(y(t), y(t-1))·s(t) of an output term (kind, power; s the samples of its carrier column, 1
    without one): its regressor at row t + 1, as the core evaluates it (an experiment's first sample,
    never read, is 0 for sign(dy))."""
    y = np.asarray(data.y, dtype=float)

    def previous() -> np.ndarray:  # y(t-1), and y(t) itself at an experiment's first sample
        p = np.empty_like(y)
        p[1:] = y[:-1]
        p[[a for a, _ in data.segments]] = y[[a for a, _ in data.segments]]
        return p

    with np.errstate(over="ignore", invalid="ignore"):
        g = output_term_values(kind, power, y, previous)
        return g * carrier if carrier is not None else g


def _same_columns(data: IOData, labels: list[str], layouts: list[EffectLayout]) -> dict[str, str]:
    """``through(e) → e`` for a shape whose series is the effect ``e``'s, to the bit, where both are
    among ``labels`` and no structure has both (their own fit has the column twice)."""
    have = set(labels)
    alias = {}
    for label in labels:
        inner = label[len("through(") : -1] if label.startswith("through(") and label.endswith(")") else None
        if inner not in have or any({label, inner} <= set(lay.column_labels) for lay in layouts):
            continue
        try:
            same = np.array_equal(layout_column(label, data), layout_column(inner, data))
        except ArxidError:  # a column that cannot be formed: envelope_inputs says why
            continue
        if same:
            alias[label] = inner
    return alias


def _column_orders(
    layout: EffectLayout, labels: list[str], alias: dict[str, str] | None = None
) -> tuple[list[int], list[int]]:
    """(nb, nk) of a structure per envelope column: its own, or no lag where it has no such column
    (an output term's column: one lag, delay 1); ``alias`` names the envelope's column of a label
    that shares one (:func:`_same_columns`)."""
    alias = alias or {}
    own = {alias.get(label, label): orders for label, orders in zip(layout.column_labels, zip(layout.nb, layout.nk))}
    own.update({_TERM + text: (1, 1) for text in layout.effect_of_term})
    nb = [int(own[label][0]) if label in own else 0 for label in labels]
    nk = [int(own[label][1]) if label in own else 0 for label in labels]
    return nb, nk


def _own_order(na: int, layout: EffectLayout, labels: list[str], alias: dict[str, str]) -> np.ndarray:
    """For each parameter of a structure as the envelope orders them (output lags, then the
    envelope's columns in its order, output terms among them), its position in the structure's own
    order (output lags, input columns, output terms)."""
    starts = list(accumulate((int(b) for b in layout.nb), initial=na))  # each column's first parameter
    at = {alias.get(label, label): j for j, label in enumerate(layout.column_labels)}
    term_at = {_TERM + text: starts[-1] + i for i, text in enumerate(layout.effect_of_term)}
    order = list(range(na))
    for label in labels:
        j = at.get(label)
        if j is not None:
            order += range(starts[j], starts[j + 1])
        elif label in term_at:
            order.append(term_at[label])
    return np.array(order, dtype=np.intp)


def _envelope(na: int, columns: list[tuple[list[int], list[int]]]) -> tuple[int, list[int], list[int]]:
    """Per layout column: the earliest delay and the latest lag over the structures that use it."""
    n_cols = len(columns[0][0])
    nb_env, nk_env = [], []
    for j in range(n_cols):
        used = [(nb[j], nk[j]) for nb, nk in columns if nb[j] > 0]
        if not used:
            nb_env.append(0)
            nk_env.append(min(nk[j] for _, nk in columns))
            continue
        k0 = min(k for _, k in used)
        nk_env.append(k0)
        nb_env.append(max(b + k for b, k in used) - k0)
    return na, nb_env, nk_env
