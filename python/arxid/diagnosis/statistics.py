"""The sufficient statistics of the candidate scoring: per-record triangular factors of the model's
regressors, the candidates' columns and the output, and the scoring read off them (step 2 of the
procedure in :mod:`arxid.diagnosis.suspects` for records kept where they are, such as a fleet's logs
on a Dask cluster; the rules are :class:`~arxid.diagnosis.scoring.CandidateScoring`'s).

Each share builds, on its own logs and exactly as :class:`~arxid.diagnosis.scoring.Scoring` builds
them on the merged data, the model's regressors Φ, every candidate's new columns z and the output y
on the model's rows, and reduces ``A = [Φ | z₁ … z_K | 1 | y]`` to one triangular factor per log
(``R'R = A'A`` over that log's rows). Only these q × q factors travel. The client stacks them and
factors again: the R of the whole fleet. Every added-variable test is then read off R
(:class:`FactorTest`): with Φ's columns first, ``R[:p, J]`` is Q'z (what the model explains of the
columns J), ``R[p:, J]`` the stripped columns z̃ and ``R[p:, y]`` the residual e in one orthonormal
basis, so z̃'z̃, z̃'e and e'e come without a sample. The statistics of the test are computed by
the same code as in process (:meth:`AddedVariableTest._from_cross`), so they agree to rounding. A log's
own factor gives the same test on that log alone: which logs the missing effect shows in.

A candidate whose signal has missing samples on the model's rows is tested, as in process, on the
rows both have: each share sends the factor of ``[Φ | z | y]`` on those rows per log (a share whose
logs miss none of them needs not: the factor is that of the columns' sub-block of R).

Not reduced here: threshold scans (``dz(u)``, ``sat(u)``) need the quantiles of the whole fleet's
signal; they are left out with a note (give the threshold, ``dz(u1,0.2)``, to test it on a fleet).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..exceptions import DataError
from ..fleet.cluster import square_factor
from ..models.arx_model import ArxModel
from .added_variable import ROUNDING, AddedVariableResult, AddedVariableTest, stripped_test
from .extension import Candidate
from .scoring import TOO_FEW_COMMON_ROWS, CandidateScoring, Scoring, common_rows_test, scored_entry

__all__ = ["FactorTest", "RegressorStatistics", "combine_statistics", "share_statistics"]

#: Why a candidate is not scored on a fleet.
SCAN_NOTE = "a threshold scan needs the whole fleet's quantiles: give the threshold, e.g. dz(u1,0.2)"


def share_statistics(share: tuple, model: ArxModel, cands: list[Candidate], ones: bool) -> tuple:
    """One factor per log of a share: R of ``[Φ | z₁ … z_K | 1 | y]`` on the model's rows of that log.

    Parameters
    ----------
    share : tuple
        From :func:`arxid.fleet.cluster.load_share`.
    model : ArxModel
    cands : list of Candidate
    ones : bool
        Add a column of ones (for the pairs with an offset).

    Returns
    -------
    tuple
        ``(factors, rows per log, {label: (first column, columns)}, notes, p, own)``: ``own`` holds,
        for a candidate with missing samples on the model's rows, the factors of ``[Φ | z | y]`` on
        the rows both have, and their counts, per log.
    """
    est = share[0]
    sc = Scoring(model, est, cands)  # the model's rows, regressors and candidates' columns, as in process
    blocks, columns, at = [sc.phi0], {}, sc.phi0.shape[1]
    bounds = np.cumsum([0] + [s.n_est for s in share[2]])
    own: dict[str, tuple] = {}
    for c, z, rows in sc.blocks():
        if not sc.are_model_rows(rows):
            # Missing samples in its signal: tested on the rows both have, as in process, from a
            # factor of its own per log; zeros keep the layout of every share's R alike.
            phi, zc, y, common = sc.on_common_rows(z, rows)
            own[c.label] = _per_log(np.column_stack([phi, zc, y]), common, bounds)
            z = np.zeros((len(sc.rows0), z.shape[1]))
        columns[c.label] = (at, z.shape[1])
        blocks.append(z)
        at += z.shape[1]
    notes = dict(sc.notes)
    for c in cands:
        if c.kind == "scan":
            notes[c.label] = SCAN_NOTE
    if ones:
        columns[""] = (at, 1)
        blocks.append(np.ones((len(sc.rows0), 1)))
    factors, counts = _per_log(np.column_stack([*blocks, sc.y0]), sc.rows0, bounds)
    return factors, counts, columns, notes, sc.phi0.shape[1], own


def _per_log(a: np.ndarray, rows: np.ndarray, bounds: np.ndarray) -> tuple[list, list]:
    """The factor of ``a`` (one row per sample index in ``rows``) over each log's rows, and their counts."""
    cut = np.searchsorted(rows, bounds)
    k = len(bounds) - 1
    return [square_factor(a[cut[i] : cut[i + 1]]) for i in range(k)], [int(cut[i + 1] - cut[i]) for i in range(k)]


class FactorTest(AddedVariableTest):
    """Added-variable tests read off the triangular factor R of ``[Φ | Z | y]`` (Φ's ``p`` columns
    first, y last) over ``n`` rows; a block of columns is given by its column indices in R.

    Parameters
    ----------
    r : ndarray of shape (q, q)
    n : int
        Rows behind R.
    p : int
        Columns of Φ.
    """

    def __init__(self, r: np.ndarray, n: int, p: int):
        self.n, self.p = n, p
        self._rr = r
        self._m = r[p:]  # the columns stripped of Φ, in one orthonormal basis
        self._e = self._m[:, -1]
        self.rss0 = float(self._e @ self._e)
        y = r[:, -1]
        self.exact = self.rss0 <= ROUNDING**2 * float(y @ y)

    def _cross(self, z: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Q'z, z'z and z'e of the columns ``z`` (indices into R: :meth:`test` takes indices here)."""
        z = np.asarray(z, dtype=int)
        b, m = self._rr[: self.p, z], self._m[:, z]
        return b, b.T @ b + m.T @ m, m.T @ self._e

    def _stripped(self, z: np.ndarray, keep: np.ndarray, norms: np.ndarray) -> tuple[AddedVariableResult | None, str]:
        """The in-process QR test of the stripped block (the block is Q₂ m in the basis Q₂ of R's rows below Φ)."""
        m = self._m[:, np.asarray(z, dtype=int)[keep]] / norms[keep]
        return stripped_test(m, self._e, self.n - self.p, self.rss0)

    def coefficients(self, z: np.ndarray) -> np.ndarray:
        """Least-squares coefficients of y on ``[Φ | columns z]``.

        Parameters
        ----------
        z : ndarray of int

        Returns
        -------
        ndarray of shape (p + len(z),)
        """
        cols = np.concatenate([np.arange(self.p), np.asarray(z, dtype=int), [self._rr.shape[1] - 1]])
        r = np.asarray(np.linalg.qr(self._rr[:, cols], mode="r"))
        k = len(cols) - 1
        return np.linalg.lstsq(r[:k, :k], r[:k, k], rcond=None)[0]


@dataclass
class RegressorStatistics(CandidateScoring):
    """The records' factors of one model and its candidates, combined, and the scoring done on them
    (the rules of :class:`~arxid.diagnosis.scoring.CandidateScoring`, each block tested from R).

    Attributes
    ----------
    model : ArxModel
    cands : list of Candidate
    factors : list of ndarray
        One R per log, in the fleet's order.
    rows : list of int
        The model's rows in each log.
    columns : dict
        ``{label: (first column, columns)}`` in R (``""`` for the column of ones).
    notes : dict of str to str
    p : int
        Columns of Φ.
    input_names : tuple of str
    output_name : str
    own : dict
        ``{label: (factors, rows)}`` per log, in the fleet's order, of the candidates with missing
        samples on the model's rows: R of ``[Φ | z | y]`` on the rows both have.
    """

    model: ArxModel
    cands: list
    factors: list
    rows: list
    columns: dict
    notes: dict
    p: int
    input_names: tuple
    output_name: str
    own: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        n = int(sum(self.rows))
        if n <= self.p + 2:
            raise DataError(f"too few regression rows ({n}) to diagnose a model with {self.p} parameters")
        self.test = FactorTest(square_factor(np.vstack(self.factors)), n, self.p)
        self.base_regressors = list(self.model.regressor_names_)

    def index(self, label: str) -> np.ndarray:
        """The columns of R of a candidate (``""``: the column of ones).

        Parameters
        ----------
        label : str

        Returns
        -------
        ndarray of int
        """
        at, k = self.columns[label]
        return np.arange(at, at + k)

    def _singles(self) -> list[dict]:
        scored = []
        for c in self.cands:
            if c.label not in self.columns or c.label in self.notes:
                continue
            res, why = self._own_test(c.label) if c.label in self.own else self.test.test(self.index(c.label))
            if res is None:
                self.notes[c.label] = why
                continue
            scored.append(scored_entry(c, res))
        return scored

    def _on_model_rows(self, label: str) -> bool:
        return label in self.columns and label not in self.own

    def _coefficients(self, label: str) -> np.ndarray:
        return self.test.coefficients(self.index(label))

    def _tested_with_offset(self, cands: list[Candidate]) -> Iterator[tuple[Candidate, AddedVariableResult | None]]:
        if "" not in self.columns:  # no column of ones: the model has an offset
            return
        for c in cands:
            yield c, self.test.test(np.concatenate([self.index(c.label), self.index("")]))[0]

    def _own_test(self, label: str) -> tuple[AddedVariableResult | None, str]:
        """A candidate with missing samples tested on the rows both have (as :meth:`Scoring._score`)."""
        factors, rows = self.own[label]
        n, k = int(sum(rows)), self.columns[label][1]
        if not common_rows_test(n, self.p, k):
            return None, TOO_FEW_COMMON_ROWS
        return FactorTest(square_factor(np.vstack(factors)), n, self.p).test(np.arange(self.p, self.p + k))

    def per_log_own(self, label: str) -> list[AddedVariableResult | None]:
        """The test of a candidate with missing samples on each log's own common rows.

        Parameters
        ----------
        label : str

        Returns
        -------
        list of AddedVariableResult or None
        """
        factors, rows = self.own[label]
        return _each_log(factors, rows, self.p, np.arange(self.p, self.p + self.columns[label][1]))

    def per_log(self, idx: np.ndarray) -> list[AddedVariableResult | None]:
        """The added-variable test of the columns ``idx`` of R on each log's own rows.

        Parameters
        ----------
        idx : ndarray of int

        Returns
        -------
        list of AddedVariableResult or None
            One per log (None where the log's rows cannot test them).
        """
        return _each_log(self.factors, self.rows, self.p, idx)


def _each_log(factors: list, rows: list, p: int, idx: np.ndarray) -> list[AddedVariableResult | None]:
    """The test of the columns ``idx`` from each log's own factor (None where its rows are too few)."""
    return [FactorTest(r, n, p).test(idx)[0] if n > p + len(idx) + 1 else None for r, n in zip(factors, rows)]


def combine_statistics(
    model: ArxModel, cands: list[Candidate], outs: list[tuple], order: list[int], sig: Any
) -> RegressorStatistics:
    """The shares' statistics (:func:`share_statistics`) as those of the fleet, logs in the fleet's order.

    Parameters
    ----------
    model : ArxModel
    cands : list of Candidate
    outs : list of tuple
        One per share.
    order : list of int
        The fleet's index of each log, share after share.
    sig : LogSignals

    Returns
    -------
    RegressorStatistics
    """
    factors, rows = [None] * len(order), [0] * len(order)
    notes: dict[str, str] = {}
    flat = [(f, n) for o in outs for f, n in zip(o[0], o[1])]
    for j, (f, n) in zip(order, flat):
        factors[j], rows[j] = f, n
    for o in outs:
        notes.update(o[3])
    columns, p = outs[0][2], outs[0][4]
    own: dict[str, tuple] = {}
    for label in dict.fromkeys(lab for o in outs for lab in o[5]):
        at, k = columns[label]
        q = outs[0][0][0].shape[1]
        cols = np.r_[np.arange(p), np.arange(at, at + k), q - 1]
        # A share whose logs have every sample of the candidate: its rows are the model's, and the
        # factor of those columns is that of the sub-block of each log's R.
        parts = [
            o[5][label] if label in o[5] else ([square_factor(f[:, cols]) for f in o[0]], list(o[1])) for o in outs
        ]
        per = [None] * len(order)
        counts = [0] * len(order)
        for j, (f, n) in zip(order, [(f, n) for fs, ns in parts for f, n in zip(fs, ns)]):
            per[j], counts[j] = f, n
        own[label] = (per, counts)
    return RegressorStatistics(model, cands, factors, rows, columns, notes, p, sig.input_names, sig.output_name, own)


#: The name this class had while only a fleet used it.
FleetStatistics = RegressorStatistics
