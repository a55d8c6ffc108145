"""Fits of many structures on the same rows from one factorization of their envelope.

Structures that share their effects and their regression rows (a neighbourhood of orders searched
around a model) are all sub-structures of one envelope: the largest na, and per layout column the
earliest delay and the latest lag. The Rust core reduces the envelope's regressors ``[Φ | y]`` to
their triangular factor R in one pass over the data; each structure's least-squares fit is then a
small QR of its columns of R (``fit_from_factor``), with the same parameters, loss and (Φ'Φ)⁻¹ as
its own fit on those rows, to rounding. A neighbourhood of 26 structures costs one pass over the
data instead of 26.
"""

from __future__ import annotations

import types
from collections.abc import Sequence

import numpy as np

from .._base import _core
from ..data.iodata import IOData
from ..exceptions import ArxidError
from .effects import EffectLayout, compile_effects
from .regressors import max_lag, regressor_names

__all__ = ["EnvelopeFactor"]

Orders = tuple[int, tuple[int, ...], tuple[int, ...]]


class EnvelopeFactor:
    """The triangular factor of the envelope of ``structures`` (all with ``effects``) on ``data``.

    Parameters
    ----------
    data : IOData
        Estimation data without missing samples (structures on data with gaps keep their own rows:
        fit them one by one).
    effects : sequence of str
        The effects every structure has.
    structures : sequence of (na, nb, nk)
        The structures to fit; nb and nk one per input.
    first_lag : int
        Start the regression rows at least this far into each experiment (as ``ArxModel.fit``).

    Attributes
    ----------
    first_lag : int
        The first regression row of every experiment (the envelope's largest lag): each structure
        is fitted on the rows from there on.

    Raises
    ------
    ArxidError
        When the data have missing samples or the structures add output terms (their rows differ).
    """

    def __init__(self, data: IOData, effects: Sequence[str], structures: Sequence[Orders], first_lag: int = 0):
        if not structures:
            raise ArxidError("an envelope needs at least one structure")
        self.data, self.effects = data, tuple(effects)
        self.structures = [(int(na), tuple(int(b) for b in nb), tuple(int(k) for k in nk)) for na, nb, nk in structures]
        self.layouts = [compile_effects(self.effects, data, nb, nk) for _, nb, nk in structures]
        first = self.layouts[0]
        if not (np.isfinite(data.y).all() and np.isfinite(first.u).all()):
            raise ArxidError("the envelope's fits need data without missing samples")
        self.na = [int(na) for na, _, _ in structures]
        self.columns = [_column_orders(lay) for lay in self.layouts]
        lag = max(max_lag(na, lay) for na, lay in zip(self.na, self.layouts))
        self.first_lag = max(lag, int(first_lag))
        # Later first rows than the structures need: output lags up to there in the envelope (its
        # rows start at its largest lag; the structures do not read those columns).
        self.envelope = _envelope(max(max(self.na), self.first_lag if self.first_lag > lag else 0), self.columns)
        grid = np.array([[self.envelope[0], *self.envelope[1], *self.envelope[2]]], dtype=np.int64)
        self.r, self.n_rows = _core.grid_factor(
            np.require(data.y, requirements=["C", "A"]),
            first.u,
            list(data.experiment_starts),
            grid,
            list(first.output_terms),
        )

    def solve(self, i: int) -> tuple[EffectLayout, list[str], types.SimpleNamespace]:
        """The fit of structure ``i`` from the factor.

        Parameters
        ----------
        i : int
            Index into the structures given.

        Returns
        -------
        layout : EffectLayout
            The structure's own layout.
        names : list of str
            Its regressor names.
        result : namespace
            ``theta``, ``rss``, ``n_rows``, ``n_skipped`` and ``inv_gram``, as the core's fit gives them.
        """
        layout, na = self.layouts[i], self.na[i]
        nb, nk = self.columns[i]
        out = _core.fit_from_factor(self.r, self.n_rows, self.envelope, (na, nb, nk), list(layout.output_terms))
        res = types.SimpleNamespace(theta=out.theta, rss=out.rss, n_rows=out.n_rows, n_skipped=0, inv_gram=out.inv_gram)
        return layout, regressor_names(self.data.output_name, na, layout), res


def _column_orders(layout: EffectLayout) -> tuple[list[int], list[int]]:
    return [int(b) for b in layout.nb], [int(k) for k in layout.nk]


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
