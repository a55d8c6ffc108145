"""Where a model fails: its error located in time (rolling RMS, worst segments) and by operating
point (RMS of the one-step residual binned by each signal, with a significance test).

:func:`where_it_fails` returns a :class:`FailureAnalysis`. It tells *where* a model is wrong;
:func:`arxid.diagnose` tells *which effect* is missing.
"""

from __future__ import annotations

import hashlib
import json
import math
import weakref
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._base import _core, metrics
from .._base.formatting import finite_or_none, horizon_label, require_pandas, text_table
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arguments import check_data, check_horizon, check_model
from ..models.arx_model import ArxModel
from .comparison import prediction_error

__all__ = ["where_it_fails", "FailureAnalysis", "WorstSegment", "SignalBins"]


@dataclass(frozen=True)
class WorstSegment:
    """A stretch of time where the error is largest.

    ``start_time``/``end_time`` in seconds from the first sample of the data (experiments laid end
    to end), ``start``/``end`` sample indices (half open), ``rms`` the error RMS inside, ``ratio``
    that RMS over the RMS of the whole record.

    ``p_value`` asks whether the one-step residual is larger inside the window than outside: a
    one-sided F test of the two variances (the one-step residual, unlike the free-run error, has
    nearly independent samples), Bonferroni-corrected for the ``n / window`` windows the search
    looked at. ``significant`` compares it with the analysis' ``alpha``.
    """

    start: int
    end: int
    start_time: float
    end_time: float
    rms: float
    ratio: float
    p_value: float = math.nan
    significant: bool = False


@dataclass(frozen=True, eq=False)
class SignalBins:
    """RMS of the one-step residual binned by the value of one signal.

    Attributes
    ----------
    signal : str
        Signal name (an input at ``t − nk``, the output ``y(t−1)``, its rate ``d<y>`` =
        (y(t−1) − y(t−2)) / ts, or an extra signal at t).
    edges : ndarray of shape (n_bins + 1,)
    centers, rms, mean, counts : ndarray of shape (n_bins,)
        Bin centres, residual RMS, residual mean and sample count per bin.
    ratio : float
        Largest bin RMS over the overall RMS (1 = the error does not depend on this signal).
    p_value : float
        Probability that bins this different arise by chance when the error does not depend on
        the signal: Bonferroni combination of a Kruskal–Wallis test on the squared residual (the
        error size differs) and a one-way ANOVA on the residual (a bias differs between bins).
    """

    signal: str
    edges: np.ndarray
    centers: np.ndarray
    rms: np.ndarray
    mean: np.ndarray
    counts: np.ndarray
    ratio: float
    p_value: float


@dataclass(frozen=True, eq=False)
class FailureAnalysis:
    """Where in time and at which operating points a model's error is large.

    Attributes
    ----------
    time : ndarray of shape (n_samples,)
    error : ndarray of shape (n_samples,)
        ``y − prediction`` at ``horizon`` (None: free run).
    residual : ndarray of shape (n_samples,)
        One-step residual (used for the binning, where samples are close to independent).
    rolling_rms : ndarray of shape (n_samples,)
        RMS of ``error`` over a centred window of ``window`` samples.
    window : int
    rms : float
        RMS of ``error`` over the record.
    worst_segments : tuple of WorstSegment
        Non-overlapping windows with the largest error, worst first.
    by_signal : tuple of SignalBins
        Sorted by p-value (most significant first).
    horizon : int or None
    alpha : float
    """

    time: np.ndarray
    error: np.ndarray
    residual: np.ndarray
    rolling_rms: np.ndarray
    window: int
    rms: float
    worst_segments: tuple
    by_signal: tuple
    horizon: int | None
    alpha: float = 0.01
    model_name: str = ""

    @property
    def significant_signals(self) -> tuple[str, ...]:
        """Signals whose binned residual differs significantly (p < alpha, Bonferroni over signals)."""
        k = max(len(self.by_signal), 1)
        return tuple(b.signal for b in self.by_signal if b.p_value * k < self.alpha)

    def bins(self, signal: str) -> SignalBins:
        """The binned one-step residual of one signal.

        Parameters
        ----------
        signal : str
            Name as in ``by_signal`` (e.g. ``u1``, ``y``, ``dy``).

        Returns
        -------
        SignalBins

        Raises
        ------
        ArxidError
            When ``signal`` was not binned.
        """
        for b in self.by_signal:
            if b.signal == signal:
                return b
        raise ArxidError(f"no binned signal {signal!r}; have {[b.signal for b in self.by_signal]}")

    def __str__(self) -> str:
        lines = [
            f"where {self.model_name or 'the model'} fails ({horizon_label(self.horizon)} error, rms {self.rms:.4g})",
            f"worst segments (window {self.window} samples):",
        ]
        lines.append(
            text_table(
                ["from [s]", "to [s]", "rms", "× overall", "p-value", "significant"],
                [
                    (s.start_time, s.end_time, s.rms, s.ratio, s.p_value, "yes" if s.significant else "")
                    for s in self.worst_segments
                ],
            )
        )
        k = max(len(self.by_signal), 1)
        lines.append("one-step residual binned by signal (Bonferroni over signals):")
        rows = []
        for b in self.by_signal:
            i = int(np.nanargmax(b.rms))
            rows.append(
                (
                    b.signal,
                    b.ratio,
                    f"{b.edges[i]:.4g}..{b.edges[i + 1]:.4g}",
                    b.p_value,
                    "yes" if b.p_value * k < self.alpha else "",
                )
            )
        lines.append(text_table(["signal", "max/overall", "worst bin", "p-value", "significant"], rows, digits=3))
        return "\n".join(lines)

    def to_pandas(self):
        """One row per (signal, bin): edges, centre, count, residual RMS and mean, p-value.

        Returns
        -------
        pandas.DataFrame
            Columns ``signal``, ``low``, ``high``, ``center``, ``count``, ``rms``, ``mean``, ``p_value``.
        """
        pd = require_pandas()
        rows = []
        for b in self.by_signal:
            for i in range(len(b.centers)):
                rows.append(
                    {
                        "signal": b.signal,
                        "low": b.edges[i],
                        "high": b.edges[i + 1],
                        "center": b.centers[i],
                        "count": int(b.counts[i]),
                        "rms": b.rms[i],
                        "mean": b.mean[i],
                        "p_value": b.p_value,
                    }
                )
        return pd.DataFrame(rows)

    def to_dict(self) -> dict:
        """JSON-ready dict: overall RMS, the worst segments and the binned residual per signal.

        Returns
        -------
        dict
            ``horizon``, ``rms``, ``window``, ``worst_segments``, ``by_signal`` and
            ``significant_signals``; NaN becomes None.
        """
        return {
            "horizon": self.horizon,
            "rms": finite_or_none(self.rms),
            "window": self.window,
            "worst_segments": [
                {
                    "start_time": s.start_time,
                    "end_time": s.end_time,
                    "start": s.start,
                    "end": s.end,
                    "rms": s.rms,
                    "ratio": s.ratio,
                    "p_value": finite_or_none(s.p_value),
                    "significant": s.significant,
                }
                for s in self.worst_segments
            ],
            "by_signal": [
                {
                    "signal": b.signal,
                    "ratio": b.ratio,
                    "p_value": b.p_value,
                    "edges": b.edges.tolist(),
                    "rms": [finite_or_none(x) for x in b.rms],
                    "counts": b.counts.tolist(),
                }
                for b in self.by_signal
            ],
            "significant_signals": list(self.significant_signals),
        }

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None
            Indentation of the JSON; None writes one line.

        Returns
        -------
        str
        """
        return json.dumps(self.to_dict(), indent=indent)

    def plot(self, ax: Any = None) -> Any:
        """Rolling RMS of the error in time, worst segments shaded.

        Parameters
        ----------
        ax : Axes, optional

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_failures

        return plot_failures(self, ax=ax)


def _argsort_nonnegative(v: np.ndarray) -> np.ndarray:
    """An order that sorts ``v`` (finite, >= 0) ascending; equal values in any order.

    A vectorised sort of one 64-bit key per sample (the value's bits, which order non-negative
    floats as integers, with the low bits replaced by the sample's index) is several times faster
    than ``np.argsort``; values equal in all but those low bits are then sorted among themselves.
    """
    n = len(v)
    k = max(1, (n - 1).bit_length())
    if n < 2 or k > 32:
        return np.argsort(v)
    low = np.uint64((1 << k) - 1)
    key = (v.view(np.uint64) & ~low) | np.arange(n, dtype=np.uint64)
    key.sort()
    order = (key & low).astype(np.intp)
    high = key >> np.uint64(k)
    del key
    same = high[1:] == high[:-1]  # neighbours whose truncated keys tie: sort them by value
    if same.any():
        run = np.cumsum(np.r_[True, ~same])
        tied = np.zeros(n, dtype=bool)
        tied[:-1] |= same
        tied[1:] |= same
        at = np.flatnonzero(tied)
        sub = order[at]
        order[at] = sub[np.lexsort((v[sub], run[at]))]
    return order


class _SquaredRanks:
    """The ranks of the squared one-step residual over its finite samples, shared by every binned
    signal (the Kruskal–Wallis test needs one sort, not one per signal; ranks are whole or half
    numbers, so their sums per bin are exact in any order).

    ``order`` sorts e² over the finite samples (positions in the record), ``ranks`` holds the
    midrank of each finite sample in record order and ``ties`` the tie correction Σ (t³ − t).
    """

    def __init__(self, e: np.ndarray):
        #: Where the residual is finite, its finite samples and their squares (record order).
        self.mask = np.isfinite(e)
        finite = np.flatnonzero(self.mask)
        self.finite = finite
        self.values = e[finite]
        self.squared = squared = self.values**2
        self._centred: tuple[np.ndarray, float, float] | None = None
        #: :func:`metrics.rms` of the finite residuals (NaN when there are none).
        with np.errstate(over="ignore"):
            self.rms = math.sqrt(float(np.mean(squared))) if len(squared) else math.nan
        self._sort = _argsort_nonnegative(squared)  # the order among equal values changes no rank and no sum
        v = squared[self._sort]
        n = len(v)
        self.smallest, self.largest = (float(v[0]), float(v[-1])) if n else (math.nan, math.nan)
        ranks = np.empty(n)
        distinct = v[1:] != v[:-1]
        if distinct.all():  # no ties (the usual residual): the ranks are 1..n
            ranks[self._sort] = np.arange(1.0, n + 1.0)
            self.ranks, self.ties = ranks, 0.0
            return
        starts = np.flatnonzero(np.r_[True, distinct])
        ties = np.diff(np.r_[starts, n]).astype(float)
        ranks[self._sort] = np.repeat(starts + (ties + 1.0) / 2.0, ties.astype(np.intp))
        self.ranks, self.ties = ranks, float(np.sum(ties**3 - ties))

    @property
    def order(self) -> np.ndarray:
        """The finite samples' positions in the record, by ascending e²."""
        return self.finite[self._sort]

    def centred(self) -> tuple[np.ndarray, float, float]:
        """:func:`_centred` of the finite residuals (computed once)."""
        if self._centred is None:
            self._centred = _centred(self.values)
        return self._centred


def _sorted_quantiles(ordered: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``np.quantile(x, q)`` (its default, linear method, and its rounding) of the values
    ``ordered``, sorted: the order statistics are read instead of partitioned for."""
    n = len(ordered)
    virtual = (n - 1) * q
    below = np.floor(virtual)
    t = virtual - below
    i = below.astype(np.intp)
    a, b = ordered[i], ordered[np.minimum(i + 1, n - 1)]
    d = b - a
    return np.where(t >= 0.5, b - d * (1 - t), a + d * t)


def _bin_index(xs: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Bin edges of ``xs`` (its quantiles; for a signal with at most ``n_bins`` values, the midpoints
    between them) and the bin of each sample; None for a signal with a single value."""
    # One sort (a vectorised sort is faster than np.quantile's partition) gives the quantiles and,
    # for a signal with few values, its values; the quantile edges are all distinct for a signal
    # with more than n_bins values.
    ordered = np.sort(xs)
    edges = _sorted_quantiles(ordered, np.linspace(0, 1, n_bins + 1))
    values = ordered[np.r_[True, ordered[1:] != ordered[:-1]]] if len(np.unique(edges)) <= n_bins else None
    if values is not None and len(values) < 2:
        return None
    if values is not None and len(values) <= n_bins:
        mids = (values[1:] + values[:-1]) / 2
        return np.concatenate([[values[0]], mids, [values[-1]]]), np.searchsorted(values, xs)
    edges = np.unique(edges)
    if len(edges) > 256:
        return edges, np.clip(np.searchsorted(edges, xs, side="right") - 1, 0, len(edges) - 2)
    # searchsorted(edges, x, "right") − 1 clipped to the bins: the inner edges at or below x
    # (edges[0] is the smallest sample, the last edge the largest, which falls in the last bin).
    where = np.zeros(len(xs), dtype=np.uint8)
    for edge in edges[1:-1]:
        where += xs >= edge
    return edges, where


#: Per IOData (weakly held: an entry goes with its data): the bins of each operating-point signal
#: over the samples used, (signal, shift, bins, samples) → (source array, edges, bin of each sample
#: as uint8). Where it fails is asked of several models on the same validation data; their bins
#: are the same when their residuals exist on the same samples (2 MB per signal at 2M samples).
_BINS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
#: Most binned signals kept per IOData (the oldest go first).
_MAX_BINNED = 16


def _signal_bins(x: np.ndarray, ok: np.ndarray, n_bins: int, memo: dict | None, tag: tuple) -> tuple | None:
    """:func:`_bin_index` of ``x[ok]`` (the signal on the samples ``ok``), from ``memo`` when the same
    signal (``tag``: name, shift and the data's array it comes from) was binned on the same samples."""
    if memo is None:
        return _bin_index(x[ok], n_bins)
    key = (tag[:-1], n_bins, hashlib.blake2b(np.packbits(ok).tobytes(), digest_size=16).digest())
    hit = memo.get(key)
    if hit is None or hit[0] is not tag[-1]:
        binned = _bin_index(x[ok], n_bins)
        if binned is not None and len(binned[0]) <= 256:
            binned = (binned[0], binned[1].astype(np.uint8))
        hit = memo[key] = (tag[-1], binned)
        while len(memo) > _MAX_BINNED:  # bounded: a long series of structures keeps only the latest
            memo.pop(next(iter(memo)))
    return None if hit[1] is None else (hit[1][0].copy(), hit[1][1])


def _centred(es: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``es`` less its mean, (Σ of that)² / n and the total sum of squares, as f_oneway has them."""
    d = es - float(np.mean(es))
    normalized = float(np.sum(d)) ** 2 / len(es)
    return d, normalized, float(np.einsum("i,i->", d, d)) - normalized


def _anova_p(
    es: np.ndarray, where: np.ndarray, counts: np.ndarray, centred: tuple | None = None, sums: np.ndarray | None = None
) -> float:
    """One-way ANOVA p-value of ``es`` between the groups ``where`` (every group with >= 2 samples
    and not constant), from per-group sums: scipy.stats.f_oneway's formula (sums of squares about
    the overall mean) without splitting the samples into groups. ``centred``: :func:`_centred` of
    ``es`` when known; ``sums``: its centred values summed per group, when known."""
    from scipy import stats

    nb, have = len(counts), counts > 0
    k, n = int(np.count_nonzero(have)), len(es)
    d, normalized, sstot = _centred(es) if centred is None else centred
    sums = (np.bincount(where, weights=d, minlength=nb) if sums is None else sums)[have]
    ssbn = float(np.sum(sums**2 / counts[have])) - normalized
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (ssbn / (k - 1)) / ((sstot - ssbn) / (n - k))
    return float(stats.f.sf(f, k - 1, n - k))


def _varies(es: np.ndarray, where: np.ndarray, counts: np.ndarray) -> bool:
    """Whether every non-empty group of ``es`` holds two different values (each sample compared
    with its group's first). The first samples usually settle it: the whole record is read only
    for the groups they leave undecided."""
    filled = np.flatnonzero(counts)
    first = np.zeros(len(counts), dtype=np.intp)
    head = where[: 1 << 14]  # the first sample of each group is usually near the start
    for g in filled:
        at = head == g
        first[g] = int(np.argmax(at)) if at.any() else int(np.argmax(where == g))
    ref = es[first]
    differs = np.bincount(head, weights=es[: len(head)] != ref[head], minlength=len(counts))
    if np.all(differs[filled] > 0):
        return True
    differs = np.bincount(where, weights=es != ref[where], minlength=len(counts))
    return bool(np.all(differs[filled] > 0))


def _grouped(es: np.ndarray, where: np.ndarray, counts: np.ndarray):
    """RMS and mean of ``es`` per group (NaN for an empty one) and the groups with >= 2 samples, in
    record order (one stable sort by group)."""
    nb = len(counts)
    by_bin = es[np.argsort(where.astype(np.uint8 if nb < 256 else np.intp), kind="stable")]
    groups = np.split(by_bin, np.cumsum(counts)[:-1])
    rms = metrics.rms_of_groups(by_bin, counts)
    mean = np.array([np.mean(g) if len(g) else np.nan for g in groups])
    return rms, mean, [g for g in groups if len(g) >= 2]


class _BinSums:
    """Per bin, in one pass over the binned samples (Rust core, numpy's bincount sums to the bit),
    of every finite residual: the count, the sums of the residual, of its square, of its ranks and
    of its centred values, and whether each non-empty bin holds two different residuals."""

    def __init__(self, where: np.ndarray, nb: int, ranked: _SquaredRanks):
        d = ranked.centred()[0]
        counts, sums, varies = _core.group_sums(where, nb, [ranked.values, ranked.squared, ranked.ranks, d])
        self.counts = counts.astype(np.intp)
        self.values, self.squares, self.ranks, self.centred = sums
        self.varies = bool(np.all(varies[counts > 0]))


def _bin_signal(
    name: str, x: np.ndarray, e: np.ndarray, n_bins: int, ranked: _SquaredRanks, memo: dict | None, tag: tuple
) -> SignalBins | None:
    """The residual ``e`` binned by the quantiles of ``x``; ``ranked`` holds the ranks of e² (shared
    by every signal); ``memo`` and ``tag`` as in :func:`_signal_bins`.

    When every non-empty bin holds two samples or more (the usual case) the per-bin statistics come
    from sums per bin (bincount), in one pass each; otherwise from the bins' samples split out."""
    from scipy import stats

    ok = np.isfinite(x) & ranked.mask
    n_ok = int(np.count_nonzero(ok))
    if n_ok < 4 * n_bins:
        return None
    full = n_ok == len(ranked.finite)  # every finite residual (the signal exists wherever it does)
    es = ranked.values if full else e[ok]
    binned = _signal_bins(x, ok, n_bins, memo, tag)
    if binned is None:
        return None
    edges, where = binned
    nb = len(edges) - 1
    shared = _BinSums(where, nb, ranked) if full and where.dtype == np.uint8 else None
    counts = np.bincount(where, minlength=nb) if shared is None else shared.counts
    every = not np.any(counts == 1)  # every sample in a group of two or more
    whole = every and full
    overall = ranked.rms if whole else metrics.rms(es)
    if every:
        with np.errstate(divide="ignore", invalid="ignore"):
            if shared is not None:
                mean, rms = shared.values / counts, np.sqrt(shared.squares / counts)
            else:
                mean = np.bincount(where, weights=es, minlength=nb) / counts
                rms = np.sqrt(np.bincount(where, weights=ranked.squared if full else es * es, minlength=nb) / counts)
        n_used, used = int(np.count_nonzero(counts)), None
    else:
        rms, mean, used = _grouped(es, where, counts)
        n_used = len(used)
    if n_used < 2 or overall == 0:
        return None
    if whole:  # the shared range of e²
        spread = ranked.largest - ranked.smallest
    else:  # max and min of e² are those of |e|, squared (rounding is monotone)
        size = np.abs(es) if used is None else np.concatenate([np.abs(g) for g in used])
        largest, smallest = float(size.max()), float(size.min())
        spread = largest * largest - smallest * smallest
    if spread <= 0:
        p_kw = 1.0
    elif used is None:  # every sample in a group of two or more: the shared ranks
        p_kw = _kruskal(ok, where, nb, e, ranked, shared)
    else:
        p_kw = float(stats.kruskal(*[g**2 for g in used]).pvalue)
    if used is None and shared is not None:
        p_an = _anova_p(es, where, counts, ranked.centred(), shared.centred) if shared.varies else 1.0
    elif used is None:
        p_an = _anova_p(es, where, counts, ranked.centred() if full else None) if _varies(es, where, counts) else 1.0
    else:
        p_an = float(stats.f_oneway(*used).pvalue) if all(np.ptp(g) > 0 for g in used) else 1.0
    p_kw = 1.0 if not math.isfinite(p_kw) else p_kw
    p_an = 1.0 if not math.isfinite(p_an) else p_an
    p = min(1.0, 2 * min(p_kw, p_an))
    centers = (edges[1:] + edges[:-1]) / 2
    return SignalBins(name, edges, centers, rms, mean, counts, float(np.nanmax(rms) / overall), p)


def _kruskal(
    ok: np.ndarray, where: np.ndarray, nb: int, e: np.ndarray, ranked: _SquaredRanks, shared: _BinSums | None = None
) -> float:
    """Kruskal–Wallis p-value of e² between the bins ``where`` of the samples ``ok``: from the shared
    ranks when ``ok`` holds every finite residual (their sums per bin from ``shared`` when given),
    else from the ranks of those samples."""
    from scipy import stats

    if len(where) == len(ranked.finite):  # the same samples: the ranks are the shared ones
        n = len(where)
        if shared is None:
            sums, sizes = np.bincount(where, weights=ranked.ranks, minlength=nb), np.bincount(where, minlength=nb)
        else:
            sums, sizes = shared.ranks, shared.counts
        sizes = sizes.astype(float)
        have = sizes > 0
        h = 12.0 / (n * (n + 1.0)) * float(np.sum(sums[have] ** 2 / sizes[have])) - 3.0 * (n + 1.0)
        h /= 1.0 - ranked.ties / (float(n) ** 3 - n)
        return float(stats.chi2.sf(h, int(np.count_nonzero(have)) - 1))
    idx = np.zeros(len(e), dtype=np.intp)
    idx[ok] = where
    sub = ranked.order[ok[ranked.order]]
    return _kruskal_sorted(e[sub] ** 2, idx[sub], nb)


def _kruskal_sorted(v: np.ndarray, group: np.ndarray, n_groups: int) -> float:
    """Kruskal–Wallis p-value of values ``v`` given in ascending order with their groups (as
    ``scipy.stats.kruskal`` on the groups: midranks for ties, tie-corrected H, χ² with k − 1
    degrees of freedom); linear in n once sorted."""
    from scipy import stats

    n = len(v)
    starts = np.flatnonzero(np.r_[True, v[1:] != v[:-1]])
    ties = np.diff(np.r_[starts, n]).astype(float)
    ranks = np.repeat(starts + (ties + 1.0) / 2.0, ties.astype(np.intp))
    sums = np.bincount(group, weights=ranks, minlength=n_groups)
    sizes = np.bincount(group, minlength=n_groups).astype(float)
    have = sizes > 0
    h = 12.0 / (n * (n + 1.0)) * float(np.sum(sums[have] ** 2 / sizes[have])) - 3.0 * (n + 1.0)
    h /= 1.0 - float(np.sum(ties**3 - ties)) / (float(n) ** 3 - n)
    return float(stats.chi2.sf(h, int(np.count_nonzero(have)) - 1))


def _segment_p_value(res: np.ndarray, lo: int, hi: int, n_windows: int, total: tuple[int, float]) -> float:
    """One-sided F test: is the one-step residual variance in [lo, hi) larger than outside it?
    ``total``: the count and the sum of squares of the finite residuals (the outside's are the
    total's less the inside's)."""
    from scipy import stats

    inside = res[lo:hi]
    inside = inside[np.isfinite(inside)]
    n_out = total[0] - inside.size
    if inside.size < 2 or n_out < 2:
        return math.nan
    with np.errstate(over="ignore"):
        sq_in = float(np.einsum("i,i->", inside, inside))
    v_out = max(total[1] - sq_in, 0.0) / n_out
    if v_out == 0:
        return math.nan
    f = (sq_in / inside.size) / v_out
    return float(min(1.0, stats.f.sf(f, inside.size, n_out) * n_windows))


def where_it_fails(
    model: ArxModel,
    data: IOData,
    horizon: int | None = None,
    *,
    window: int | None = None,
    n_worst: int = 3,
    n_bins: int = 8,
    alpha: float = 0.01,
    initial: str = "zero",
) -> FailureAnalysis:
    """Locate a model's error in time and by operating point.

    Parameters
    ----------
    model : ArxModel
    data : IOData
        Preferably validation data.
    horizon : int or None
        Error used in time: None (default) free-run simulation, k k-step prediction.
    window : int, optional
        Rolling-RMS window in samples (default: 1/50 of the record, at least 10).
    n_worst : int
        Number of worst segments to report.
    n_bins : int
        Quantile bins per signal.
    alpha : float
        Level for calling a signal significant (Bonferroni over the signals).
    initial : {"zero", "estimate"}
        Initial conditions of the error in time (see :func:`compare`).

    Returns
    -------
    FailureAnalysis
        ``worst_segments`` with their time ranges and ``by_signal``: residual RMS binned by each
        input (at t − nk), the output (at t − 1), the output rate and each extra signal, with a
        p-value, most significant first. ``.plot()`` and ``.to_pandas()`` give figure and table.
    """
    model = check_model(model)
    data = check_data(data)
    horizon = check_horizon(horizon)
    n = data.n_samples
    window = max(10, n // 50) if window is None else int(window)
    if window < 2 or window > n:
        raise ArxidError(f"window must be between 2 and the number of samples ({n}), got {window}")
    _, err, diverged = prediction_error(model, data, horizon, initial)
    if diverged:
        err = np.where(np.isfinite(err), err, np.nan)
    _, res, _ = prediction_error(model, data, 1)
    t = np.arange(n) * data.ts
    roll = np.full(n, np.nan)
    for a, b in data.segments:
        if b - a >= 2:
            roll[a:b] = metrics.rolling_rms(err[a:b], min(window, b - a))
    overall = metrics.rms(err)
    # Greedy non-overlapping picks of the largest rolling RMS.
    worst = []
    r = roll.copy()
    half = window // 2
    finite_res = res[np.isfinite(res)]
    # einsum, not dot: a multithreaded BLAS dot leaves threads spinning on the cores others need
    with np.errstate(over="ignore"):
        total = (finite_res.size, float(np.einsum("i,i->", finite_res, finite_res)))
    del finite_res
    for _ in range(int(n_worst)):
        if not np.isfinite(r).any():
            break
        i = int(np.nanargmax(r))
        lo, hi = max(0, i - half), min(n, i - half + window)
        rms = metrics.rms(err[lo:hi])
        p = _segment_p_value(res, lo, hi, max(1, n // window), total)
        worst.append(
            WorstSegment(
                lo,
                hi,
                float(t[lo]),
                float(t[hi - 1] + data.ts),
                rms,
                rms / overall if overall > 0 else math.nan,
                p,
                bool(p < alpha),
            )
        )
        r[max(0, lo - half) : min(n, hi + half)] = np.nan
    # Operating points: (name, samples, (name, shift, the data's array they come from)).
    signals = []
    for i, name in enumerate(data.input_names):
        x = np.full(n, np.nan)
        k = model.nk_[i]
        for a, b in data.segments:
            if b - a > k:
                x[a + k : b] = data.u[a : b - k, i]
        signals.append((name, x, (name, k, data.u)))
    y1 = np.full(n, np.nan)
    dy1 = np.full(n, np.nan)
    for a, b in data.segments:
        y1[a + 1 : b] = data.y[a : b - 1]
        dy1[a + 2 : b] = (data.y[a + 1 : b - 1] - data.y[a : b - 2]) / data.ts
    signals.append((data.output_name, y1, (data.output_name, 1, data.y)))
    signals.append((f"d{data.output_name}", dy1, (f"d{data.output_name}", 1, data.y)))
    signals += [(k, np.asarray(v, dtype=float), (k, 0, v)) for k, v in data.extra.items()]
    ranked = _SquaredRanks(res)
    memo = _BINS.setdefault(data, {})
    bins = [b for b in (_bin_signal(nm, x, res, n_bins, ranked, memo, tag) for nm, x, tag in signals) if b is not None]
    bins.sort(key=lambda b: (b.p_value, -b.ratio))
    return FailureAnalysis(
        t, err, res, roll, window, overall, tuple(worst), tuple(bins), horizon, alpha, model.structure_name()
    )
