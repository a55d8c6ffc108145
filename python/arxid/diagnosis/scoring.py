"""Scoring the candidates of an ARX model by added-variable tests (step 2 of the procedure in
:mod:`arxid.diagnosis.suspects`).

Every candidate's new regressor columns are tested against the model's regressors on common rows;
thresholds (``dz(u)``, ``sat(u)``) are found by a grid scan, ``abs(u)`` and ``pos(u)`` are one
hypothesis, and strong effects are also tried in pairs: with ``const`` (asymmetric Coulomb friction
is c·sign(v) plus an offset) and, when nothing else is found, with the partner that they hide.
"""

from __future__ import annotations

import math
import re
import weakref
from collections.abc import Iterable, Iterator
from typing import TypeVar

import numpy as np

from .._base import _core
from .._base.nested import cholesky_factor, least_squares
from ..data.iodata import IOData
from ..exceptions import DataError, OrderError
from ..models.arx_model import ArxModel
from ..models.effects import (
    EffectLayout,
    compile_effects,
    factor_series,
    format_threshold,
    layout_column,
    parse_effect,
    thresholded_products,
)
from ..models.regressors import (
    finite_regressor_columns,
    first_of_run,
    lagger,
    max_lag,
    output_term_values,
    regressor_columns,
    regressor_matrix,
    regressor_names,
)
from .added_variable import AddedVariableResult, AddedVariableTest, all_finite, held_columns, holm, lagged_view
from .candidates import scan_threshold, signal_thresholds
from .extension import Candidate, layout_for

__all__ = ["CandidateScoring", "Scoring", "TOO_FEW_COMMON_ROWS", "common_rows_test", "input_index", "scored_entry"]

_Key = TypeVar("_Key")


class CandidateScoring:
    """The scoring's rules, whatever holds the samples: every candidate's own added-variable test
    (:meth:`_singles`), ``abs(u)`` and ``pos(u)`` merged into one hypothesis, the strong effects
    paired with an offset, and Holm's correction over all.

    A subclass says how a block of columns is tested: :class:`Scoring` from the record's rows,
    :class:`arxid.diagnosis.statistics.RegressorStatistics` from the records' triangular factors.
    It sets ``model``, ``notes``, ``input_names`` and ``base_regressors`` (the model's regressor
    names), and gives :meth:`_singles`, :meth:`_on_model_rows`, :meth:`_coefficients` and
    :meth:`_tested_with_offset`.
    """

    model: ArxModel
    notes: dict[str, str]
    input_names: tuple[str, ...]
    base_regressors: list[str]

    def _singles(self) -> list[dict]:
        """Every candidate's own test, as :func:`scored_entry` (a candidate that cannot be tested
        gets a note instead)."""
        raise NotImplementedError

    def _on_model_rows(self, label: str) -> bool:
        """Whether the candidate was tested on the model's rows (only those are paired)."""
        raise NotImplementedError

    def _coefficients(self, label: str) -> np.ndarray:
        """Least-squares coefficients of y on the model's regressors and the candidate's columns."""
        raise NotImplementedError

    def _tested_with_offset(self, cands: list[Candidate]) -> Iterator[tuple[Candidate, AddedVariableResult | None]]:
        """Each candidate's columns tested with a column of ones beside them."""
        raise NotImplementedError

    def run(self, alpha: float, n_pairs: int) -> tuple[list[dict], dict[str, str]]:
        """Every candidate's added-variable test, one-direction terms merged, the strong effects
        paired with an offset, and the Holm-corrected p-values.

        Parameters
        ----------
        alpha : float
        n_pairs : int

        Returns
        -------
        tuple of (list of dict, dict of str to str)
            The scored entries (:func:`scored_entry` with ``p_adj``) and the notes.
        """
        scored = self._one_direction_term(self._singles())
        if "const" not in self.model.effects and n_pairs > 0:
            scored += self._pairs_with_offset(scored, alpha, n_pairs)
        for s, pa in zip(scored, holm(np.array([s["p"] for s in scored]))):
            s["p_adj"] = float(pa)
        return scored, self.notes

    def _one_direction_term(self, scored: list[dict]) -> list[dict]:
        """``abs(u)`` and ``pos(u)`` are one hypothesis when u is in the model (|u| = 2 pos(u) − u):
        keep ``abs(u)`` when the fitted gains for u > 0 and u < 0 have opposite signs (a response
        that ignores the direction), else ``pos(u)`` (different gains for the two directions)."""
        labels = {s["c"].label for s in scored}
        p = len(self.base_regressors)
        drop = set()
        for label in labels:
            m = re.fullmatch(r"pos\((\w+)\)", label)
            if not m or f"abs({m[1]})" not in labels or not self._on_model_rows(label):
                continue
            idx = input_index(self.input_names, m[1])
            name = f"{self.input_names[idx]}(" if idx >= 0 else None
            own = [j for j, nm in enumerate(self.base_regressors) if name is not None and nm.startswith(name)]
            coef = self._coefficients(label)
            negative = float(np.sum(coef[own]))
            positive = negative + float(np.sum(coef[p:]))
            drop.add(f"abs({m[1]})" if positive * negative >= 0 else label)
        return [s for s in scored if s["c"].label not in drop]

    def _pairs_with_offset(self, scored: list[dict], alpha: float, n_pairs: int) -> list[dict]:
        """Strong effects tried together with ``const`` (asymmetric Coulomb friction, an output
        that was not detrended: the effect only helps together with a constant)."""
        adj = holm(np.array([s["p"] for s in scored]))
        strong = sorted(
            (
                s
                for s, pa in zip(scored, adj)
                if pa < alpha
                and s["c"].kind == "effect"
                and s["c"].label not in ("const", "time")
                and self._on_model_rows(s["c"].label)
            ),
            key=lambda s: s["p"],
        )
        have = {s["c"].label for s in scored}
        pairs = [s["c"] for s in strong[:n_pairs] if f"{s['c'].label}+const" not in have]
        out = []
        for c, res in self._tested_with_offset(pairs):
            if res is not None:
                pc = Candidate(f"{c.label}+const", c.effects + ("const",), c.na, c.nb, c.nk, "pair")
                out.append(scored_entry(pc, res))
        return out


def input_index(names: tuple[str, ...], signal: str) -> int:
    """The index of input ``signal`` (a name, or ``u1``, ``u2`` ...); -1 when it is no input."""
    idx = names.index(signal) if signal in names else int(signal[1:]) - 1 if signal[1:].isdigit() else -1
    return idx if 0 <= idx < len(names) else -1


class Scoring(CandidateScoring):
    """Added-variable tests of every candidate against the model's regressors on the record's rows."""

    def __init__(self, model: ArxModel, data: IOData, cands: list[Candidate]):
        self.model, self.data, self.cands = model, data, cands
        self.notes: dict[str, str] = {}
        self.input_names = data.input_names
        self.base_layout = compile_effects(model.effects, data, model.nb_, model.nk_)
        self.base_regressors = regressor_names(data.output_name, model.na_, self.base_layout)
        self.base_names = set(self.base_regressors)
        lag = max(model.first_lag_, max_lag(model.na_, self.base_layout))
        self.prepared = []
        self._lags: dict[str, EffectLayout] = {}  # each candidate's layout without samples
        self.scans: dict[str, list[Candidate]] = {}
        for c in cands:
            if c.kind == "scan":
                self.scans.setdefault(c.label[c.label.index("(") + 1 : -1], []).append(c)
                continue
            try:
                _, lay = layout_for(c, model, data, samples=False)
            except (OrderError, DataError) as exc:
                self.notes[c.label] = str(exc)
                continue
            self._lags[c.label] = lay
            lag = max(lag, max_lag(c.na, lay))
            self.prepared.append(c)  # its columns are built when it is scored, one candidate at a time
        self.lag = lag
        self._tall: tuple[np.ndarray, np.ndarray, AddedVariableTest] | None = None
        phi0, _, self.rows0 = self._regressors()
        if len(self.rows0) <= phi0.shape[1] + 2:
            raise DataError(
                f"too few regression rows ({len(self.rows0)}) to diagnose a model with {phi0.shape[1]} parameters"
            )
        self.lagged = lagger(self.rows0)  # x[rows0 - lag], a slice when the rows are consecutive
        self._first_row = first_of_run(self.rows0)
        self._samples: dict[tuple[str, int, int], np.ndarray] = {}  # one signal's, during its scan
        self._phi_y_gram: np.ndarray | None = None
        # The columns of each candidate tested on the model's rows, rebuilt when asked for (pairs
        # are formed from a few of them): holding every candidate's columns would cost a copy of
        # the record per candidate.
        self.single_z = _Rebuilt(self)
        self._threshold_lags: dict[tuple[str, str], tuple[int, int]] = {}

    def run(self, alpha: float, n_pairs: int) -> tuple[list[dict], dict[str, str]]:
        """As :meth:`CandidateScoring.run`; the model's regressors are then let go (the stages after
        the scoring hold their own tall arrays) and rebuilt if :meth:`masked_pairs` needs them."""
        try:
            return super().run(alpha, n_pairs)
        finally:
            self.release()

    def release(self) -> None:
        """Let go of the model's regressors, their fit and the scan's samples (rows × columns each);
        they are rebuilt, the same, when next read."""
        self._tall = None
        self._samples = {}

    def _regressors(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The model's regressors, output and rows (:func:`regressor_matrix`), and their test."""
        phi0, y0, rows0 = regressor_matrix(self.data, self.model.na_, self.base_layout, self.lag)
        self._tall = (phi0, y0, AddedVariableTest(phi0, y0))
        return phi0, y0, rows0

    def _held(self) -> tuple[np.ndarray, np.ndarray, AddedVariableTest]:
        """The model's regressors, output and test, rebuilt if :meth:`release` let them go."""
        if self._tall is None:
            self._regressors()
        assert self._tall is not None
        return self._tall

    @property
    def phi0(self) -> np.ndarray:
        """The model's regressors on its rows (rebuilt after :meth:`release`)."""
        return self._held()[0]

    @property
    def y0(self) -> np.ndarray:
        """The output on the model's rows."""
        return self._held()[1]

    @property
    def proj0(self) -> AddedVariableTest:
        """The added-variable test against the model's regressors."""
        return self._held()[2]

    def _singles(self) -> list[dict]:
        scored = self._score_all()
        return scored + [s for s in (self._scan(sig, group) for sig, group in self.scans.items()) if s is not None]

    def _on_model_rows(self, label: str) -> bool:
        return label in self.single_z

    def _coefficients(self, label: str) -> np.ndarray:
        z = self.single_z[label]
        coef = self.proj0.coefficients(z)
        return least_squares(np.column_stack([self.phi0, z]), self.y0) if coef is None else coef  # ill-conditioned

    def _tested_with_offset(self, cands: list[Candidate]) -> Iterator[tuple[Candidate, AddedVariableResult | None]]:
        for c, res, _ in self._grouped_tests(((c, self.single_z[c.label]) for c in cands), offset=True):
            yield c, res

    def _columns(self, c: Candidate) -> tuple[np.ndarray, np.ndarray]:
        """The candidate's new columns and their rows: the model's rows unless its columns are
        missing there. Raises DataError when its samples overflow."""
        z = self._effect_columns(c)
        if z is not None:
            return z, self.rows0
        lay = layout_for(c, self.model, self.data)[1]
        names = regressor_names(self.data.output_name, c.na, lay)
        new = [i for i, nm in enumerate(names) if nm not in self.base_names]
        if max_lag(c.na, lay) <= self.lag:  # only the new columns, on the model's rows
            z = regressor_columns(self.data, c.na, lay, self.rows0, new)
            if all_finite(z):
                return z, self.rows0
        return finite_regressor_columns(self.data, c.na, lay, self.lag, new)

    def _effect_columns(self, c: Candidate) -> np.ndarray | None:
        """The columns of a candidate that adds one effect, built without the input matrix of the
        model with it (dozens of candidates are scored one at a time): an input-side effect's own
        column (:func:`layout_column`) at the lags of its layout, or an output term without a
        carrier from the output alone. None when the candidate is not of that kind or a sample is
        missing on the model's rows."""
        lay = self._lags.get(c.label)
        if c.kind != "effect" or lay is None or len(c.effects) != 1:
            return None
        if lay.effect_of_column[-1] == parse_effect(c.effects[0], self.data).text:  # its column is the last
            z = self._lag_columns(layout_column(lay.column_labels[-1], self.data), lay.nb[-1], lay.nk[-1])
        else:  # an output term: its columns read the output, and the inputs only for a carrier
            names = regressor_names(self.data.output_name, c.na, lay)
            new = [i for i, nm in enumerate(names) if nm not in self.base_names]
            first_term = c.na + sum(lay.nb)
            if any(i < first_term for i in new):
                return None
            z = self._output_term_columns(lay, [i - first_term for i in new])
        return z if all_finite(z) else None

    def _output_term_columns(self, lay: EffectLayout, terms: list[int]) -> np.ndarray:
        """The columns of the output terms ``terms`` of ``lay`` on the model's rows, as
        :func:`regressor_columns` writes them (the same operations, so the same bits): a carrier is
        its own column (:func:`layout_column`), not the input matrix of the model with it."""
        y = self.data.y
        columns = []
        for t in terms:
            kind, power, mult = lay.output_terms[t]
            g = output_term_values(kind, power, self.lagged(y, 1), lambda: self.lagged(y, 2))
            if mult >= 0:  # g is a new array: multiplied in place (one column less held on gathered rows)
                g *= self.lagged(layout_column(lay.column_labels[mult], self.data), 1)
            columns.append(g)
        return columns[0].reshape(-1, 1) if len(columns) == 1 else np.column_stack(columns)

    def _score_all(self) -> list[dict]:
        """Every prepared candidate scored, in order; those on the model's rows in groups that
        share one pass over the regressors (:meth:`_grouped_tests`)."""
        slots: list[dict | None] = []

        def on_model_rows() -> Iterator[tuple[tuple[int, Candidate], np.ndarray]]:
            for c, z, rows in self.blocks():
                if self.are_model_rows(rows):
                    slots.append(None)
                    yield (len(slots) - 1, c), z
                else:
                    slots.append(self._score_on_common_rows(c, z, rows))

        for (i, c), res, why in self._grouped_tests(on_model_rows()):
            if res is None:
                self.notes[c.label] = why
                continue
            self.single_z.keep(c.label, ("candidate", c))
            slots[i] = scored_entry(c, res)
        return [s for s in slots if s is not None]

    def _grouped_tests(
        self, blocks: Iterable[tuple[_Key, np.ndarray]], offset: bool = False
    ) -> Iterator[tuple[_Key, AddedVariableResult | None, str]]:
        """Each block's test against the model's regressors (with a column of ones beside it when
        ``offset``), as ``(key, result, why)``: the blocks are tested in groups that read the
        regressors once per block of rows (:meth:`AddedVariableTest.tests`), each group's columns
        within :data:`_GROUP_BYTES` (a lagged view holds one column, whatever its width)."""
        budget = max(1, _GROUP_BYTES // (8 * max(len(self.rows0), 1)))
        group: list[tuple[_Key, np.ndarray]] = []
        for key, z in blocks:
            group.append((key, z))
            if sum(held_columns(g[1]) for g in group) >= budget:
                yield from self._group_tested(group, offset)
                group = []
        yield from self._group_tested(group, offset)

    def _group_tested(
        self, group: list[tuple[_Key, np.ndarray]], offset: bool
    ) -> Iterator[tuple[_Key, AddedVariableResult | None, str]]:
        for (key, _), (res, why) in zip(group, self.proj0.tests([z for _, z in group], offset)):
            yield key, res, why

    def blocks(self) -> Iterator[tuple[Candidate, np.ndarray, np.ndarray]]:
        """Every prepared candidate with its new columns and their rows (the model's, unless its
        columns are missing there), one candidate at a time: what each candidate's test reads,
        wherever it is tested (here, or from the factors of a fleet's shares,
        :func:`arxid.diagnosis.statistics.share_statistics`). A candidate without columns gets a
        note instead.

        Yields
        ------
        tuple of (Candidate, ndarray of shape (n_rows, q), ndarray of int)
        """
        for c in self.prepared:
            got = self._columns_of(c)
            if got is not None:
                yield c, *got

    def are_model_rows(self, rows: np.ndarray) -> bool:
        """Whether ``rows`` are the model's regression rows.

        Parameters
        ----------
        rows : ndarray of int

        Returns
        -------
        bool
        """
        return len(rows) == len(self.rows0) and np.array_equal(rows, self.rows0)

    def on_common_rows(self, z: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The model's regressors, a candidate's columns ``z`` (on ``rows``) and the output on the
        rows both have, and those rows: where a candidate with missing samples is tested.

        Parameters
        ----------
        z : ndarray of shape (len(rows), q)
        rows : ndarray of int

        Returns
        -------
        tuple of (ndarray, ndarray, ndarray, ndarray)
            Φ, z, y and the common rows.
        """
        common, i0, i1 = np.intersect1d(self.rows0, rows, return_indices=True)
        return self.phi0[i0], z[i1], self.y0[i0], common

    def _columns_of(self, c: Candidate) -> tuple[np.ndarray, np.ndarray] | None:
        """A candidate's new columns and their rows (None, with a note, when it has none)."""
        try:
            z, rows = self._columns(c)
        except DataError as exc:  # its samples overflow
            self.notes[c.label] = str(exc)
            return None
        if z.shape[1] == 0:
            self.notes[c.label] = "adds no regressor"
            return None
        return z, rows

    def _score_on_common_rows(self, c: Candidate, z: np.ndarray, rows: np.ndarray) -> dict | None:
        """A candidate with missing samples: tested on the rows both it and the model have."""
        phi, z, y, common = self.on_common_rows(z, rows)
        if not common_rows_test(len(common), phi.shape[1], z.shape[1]):
            self.notes[c.label] = TOO_FEW_COMMON_ROWS
            return None
        res, why = AddedVariableTest(phi, y).test(z)
        if res is None:
            self.notes[c.label] = why
            return None
        return scored_entry(c, res)

    def _threshold_lag(self, op: str, signal: str) -> tuple[int, int]:
        """nb and nk of the columns of ``op(signal, c)`` (they do not depend on the threshold)."""
        if (op, signal) not in self._threshold_lags:
            lay = compile_effects((f"{op}({signal},1)",), self.data, self.model.nb_, self.model.nk_, samples=False)
            self._threshold_lags[op, signal] = (lay.nb[-1], lay.nk[-1])
        return self._threshold_lags[op, signal]

    def _threshold_columns(self, op: str, signal: str, c: float) -> tuple[Candidate, np.ndarray]:
        """The candidate ``op(signal,c)`` and its columns on the common rows, read straight off the
        effect's series (the scan tries some forty thresholds, so no regressor matrix is rebuilt)."""
        label = f"{op}({signal},{format_threshold(c)})"
        cand = Candidate(label, (label,), self.model.na_, self.model.nb_, self.model.nk_, "effect")
        b, k = self._threshold_lag(op, signal)
        col = factor_series(parse_effect(label, self.data).factors[0], self.data)
        return cand, self._lag_columns(col, b, k)

    def _threshold_shares(self, op: str, signal: str, cs: np.ndarray) -> np.ndarray:
        """The share of every threshold in ``cs`` (NaN where it cannot be scored), all from one pass
        over the model's regressors per block of rows (:meth:`AddedVariableTest.shares`)."""
        b, k = self._threshold_lag(op, signal)
        labels = [f"{op}({signal},{format_threshold(c)})" for c in cs]
        thresholds = [parse_effect(lab, self.data).factors[0].threshold for lab in labels]
        lagged = self._threshold_samples(signal, b, k)
        if b and all_finite(lagged):
            ts = np.array(thresholds, dtype=float)
            got = self.proj0.shares(lambda phi, e: thresholded_products(op, phi, e, lagged, ts), len(cs), b)
            if got is not None:
                return got
        return np.array([self._one_share(op, signal, float(c)) for c in cs])

    def _threshold_samples(self, signal: str, b: int, k: int) -> np.ndarray:
        """The samples of ``signal`` each of a threshold effect's ``b`` columns shapes, on the
        model's rows: ``(rows, b)``, C-ordered, kept for the scan of that signal."""
        key = (signal, b, k)
        if key not in self._samples:
            x = np.asarray(self.data.signal(signal), dtype=float)
            self._samples = {key: np.ascontiguousarray(self._lag_columns(x, b, k))}
        return self._samples[key]

    def _lag_columns(self, x: np.ndarray, b: int, k: int) -> np.ndarray:
        """``(rows, b)``: column j holds ``x[rows0 - k - j]``. When the rows are consecutive it is
        a read-only strided view of ``x`` (nothing copied: a test reads it a block of rows at a
        time), else a gather."""
        n = len(self.rows0)
        if self._first_row is not None and self._first_row - k - (b - 1) >= 0:
            return lagged_view(x, self._first_row - k, b, n)
        z = np.empty((n, b))
        for j in range(b):
            z[:, j] = self.lagged(x, k + j)
        return z

    def _one_share(self, op: str, signal: str, c: float) -> float:
        z = self._threshold_columns(op, signal, c)[1]
        return self.proj0.share(z) if z.shape[1] and all_finite(z) else math.nan

    def _scan(self, signal: str, group: list[Candidate]) -> dict | None:
        """The threshold of ``dz`` / ``sat`` on ``signal`` by a grid scan (:func:`arxid.candidates.scan_threshold`).

        With the input in the model, ``dz(u,c)`` and ``sat(u,c)`` add the same span, so the two are
        one hypothesis: one scan, then the name of the shape that alone replaces the input better.
        """
        ops = [c.label[: c.label.index("(")] for c in group]
        x = np.asarray(self.data.signal(signal), dtype=float)
        c, n = scan_threshold(
            x, lambda cs: self._threshold_shares(ops[0], signal, cs), signal_thresholds(self.data, signal)
        )
        if not math.isfinite(c):
            for cand in group:
                why = "no threshold could be tested" if n else f"|{signal}| takes too few distinct values to scan"
                self.notes[cand.label] = why
            return None
        op = self._threshold_shape(signal, c) if len(ops) > 1 else ops[0]
        cand, z = self._threshold_columns(op, signal, c)
        res, why = self.proj0.test(z)
        if res is None:
            self.notes[group[0].label] = why
            return None
        self.single_z.keep(cand.label, ("threshold", op, signal, c))
        self.notes[cand.label] = f"threshold scanned over {n} quantiles of |{signal}| (p-value x {n})"
        scored = scored_entry(cand, res)
        scored["p"] = min(1.0, scored["p"] * n)
        return scored

    def _threshold_shape(self, signal: str, c: float) -> str:
        """``dz`` or ``sat``: whichever, in place of the input itself, leaves the smaller residual."""
        idx = input_index(self.input_names, signal)
        if idx < 0:
            return "dz"
        keep = [j for j, nm in enumerate(self.base_regressors) if not nm.startswith(f"{self.input_names[idx]}(")]
        both = self._both_shapes(signal, c)
        rss = {op: self._shape_rss(op, keep, signal, c, both.get(op)) for op in ("dz", "sat")}
        return min(rss, key=lambda k: rss[k])

    def _shape_threshold(self, op: str, signal: str, c: float) -> float:
        return parse_effect(f"{op}({signal},{format_threshold(c)})", self.data).factors[0].threshold

    def _both_shapes(self, signal: str, c: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """The products :meth:`_shape_rss` reads for ``dz`` and ``sat`` at ``c``, both from one pass
        over the model's regressors (each the same bits as alone); none when their columns differ
        or a sample is missing."""
        (b, k), other = self._threshold_lag("dz", signal), self._threshold_lag("sat", signal)
        lagged = self._threshold_samples(signal, b, k)
        if (b, k) != other or not b or not all_finite(lagged):
            return {}
        ts = np.array([self._shape_threshold(op, signal, c) for op in ("dz", "sat")])
        a, y = (np.ascontiguousarray(v, dtype=float) for v in (self.phi0, self.y0))
        cross, zz = _core.dead_zone_and_saturation_products(a, y, lagged, ts)
        return {op: (cross[:, :, t], zz[None, :, :, t]) for t, op in enumerate(("dz", "sat"))}

    def _shape_rss(
        self, op: str, keep: list[int], signal: str, c: float, products: tuple[np.ndarray, np.ndarray] | None = None
    ) -> float:
        """Residual sum of squares of y on the model's ``keep`` regressors and the columns of
        ``op(signal, c)``: from the cross products of ``[Φ | z | y]`` (one pass over the rows, the
        columns never formed; ``products``: those :meth:`_both_shapes` found) when they are well
        conditioned, else from the fit itself."""
        p = self.phi0.shape[1]
        b, k = self._threshold_lag(op, signal)
        lagged = self._threshold_samples(signal, b, k)
        threshold = self._shape_threshold(op, signal, c)
        r = None
        if products is not None or all_finite(lagged):
            cross, zz = products or thresholded_products(op, self.phi0, self.y0, lagged, np.array([threshold]))
            gram = np.empty((p + b + 1, p + b + 1))  # [Φ | z | y]'[Φ | z | y]
            gram[np.ix_(range(p), range(p))] = self._gram[:p, :p]
            gram[:p, -1] = gram[-1, :p] = self._gram[:p, p]
            gram[-1, -1] = self._gram[p, p]
            gram[:p, p:-1], gram[-1, p:-1] = cross[:p], cross[p]
            gram[p:-1, :p], gram[p:-1, -1] = cross[:p].T, cross[p]
            gram[p:-1, p:-1] = zz[0]
            sel = keep + list(range(p, p + b + 1))
            r = cholesky_factor(gram[np.ix_(sel, sel)], 1e-10)
        if r is not None:
            return float(r[-1, -1] ** 2)
        x = np.column_stack([self.phi0[:, keep], self._threshold_columns(op, signal, c)[1]])
        return float(np.sum((self.y0 - x @ least_squares(x, self.y0)) ** 2))

    @property
    def _gram(self) -> np.ndarray:
        """``[Φ | y]'[Φ | y]`` of the model's rows (formed when first asked for)."""
        if self._phi_y_gram is None and self.proj0.gram is not None:  # formed by the base fit
            self._phi_y_gram = self.proj0.gram
        if self._phi_y_gram is None:
            p = self.phi0.shape[1]
            g = np.empty((p + 1, p + 1))
            g[:p, :p], g[:p, p], g[p, p] = self.phi0.T @ self.phi0, self.phi0.T @ self.y0, self.y0 @ self.y0
            g[p, :p] = g[:p, p]
            self._phi_y_gram = g
        return self._phi_y_gram

    def masked_pairs(self, scored: list[dict], alpha: float, n_partners: int = 3) -> list[dict]:
        """Pairs for two effects that hide each other (each alone barely lowers the free-run error).

        The strongest significant effect by score is put beside the model's regressors; every other
        effect is scored again given it, and the ``n_partners`` strongest that pass ``alpha``
        (Bonferroni over those re-tests) form pairs with it. A pair's p-value is the joint F-test of
        both, Bonferroni-corrected by every hypothesis tried; it is then validated like any candidate.
        """
        singles = [s for s in scored if s["c"].kind == "effect" and s["c"].label in self.single_z]
        strong = [s for s in singles if s["p_adj"] < alpha and s["c"].label not in ("const", "time")]
        if not strong:
            return []
        first = max(strong, key=lambda s: s["score"])["c"]
        z1 = self.single_z[first.label]
        given = AddedVariableTest(np.column_stack([self.phi0, z1]), self.y0)
        n_tests = len(singles) - 1
        partners = []
        for s in singles:
            res = given.test(self.single_z[s["c"].label])[0] if s["c"] is not first else None
            if res is not None and res.p_value * n_tests < alpha:
                partners.append((res.score, s["c"]))
        out = []
        for _, c in sorted(partners, key=lambda t: -t[0])[:n_partners]:
            res = self.proj0.test(np.column_stack([z1, self.single_z[c.label]]))[0]
            if res is None:
                continue
            pair = Candidate(f"{first.label}+{c.label}", first.effects + c.effects, c.na, c.nb, c.nk, "pair")
            scored_pair = scored_entry(pair, res)
            scored_pair["p_adj"] = min(1.0, res.p_value * (len(scored) + n_partners))
            out.append(scored_pair)
        return out


#: Bytes of candidate columns scored together in one pass over the model's regressors: a few
#: copies of a column of the record at most, so memory does not grow with the number of candidates.
_GROUP_BYTES = 128 * 2**20


class _Rebuilt(dict):
    """A dict of label -> columns on the model's rows, rebuilt from a stored recipe on each access:
    ``("candidate", c)`` or ``("threshold", op, signal, c)``. The scoring is held weakly, so the
    recipes make no reference cycle that would keep the scoring's arrays alive."""

    def __init__(self, scoring: Scoring):
        super().__init__()
        self._scoring = weakref.ref(scoring)

    def keep(self, label: str, recipe: tuple) -> None:
        super().__setitem__(label, recipe)

    def __getitem__(self, label: str) -> np.ndarray:
        recipe, sc = super().__getitem__(label), self._scoring()
        assert sc is not None
        if recipe[0] == "candidate":
            c = recipe[1]
            return sc._columns(c)[0]
        return sc._threshold_columns(*recipe[1:])[1]


#: Why a candidate with missing samples on the model's rows is not tested.
TOO_FEW_COMMON_ROWS = "too few rows where its signal exists"


def common_rows_test(n: int, p: int, q: int) -> bool:
    """Whether ``n`` rows both the model and a candidate have can test its ``q`` columns beside the
    model's ``p`` (the same rule for one record and for a fleet).

    Parameters
    ----------
    n, p, q : int

    Returns
    -------
    bool
    """
    return n > p + q + 2


def scored_entry(c: Candidate, res: AddedVariableResult) -> dict:
    """A scored candidate as the procedure passes it on: ``c``, ``score``, ``f``, ``p`` and the
    number of columns ``q`` (the Holm-corrected ``p_adj`` is added once all are scored)."""
    return {"c": c, "score": res.score, "f": res.f_statistic, "p": res.p_value, "q": res.n_columns}
