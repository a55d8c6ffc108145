"""A residual binned by an operating-point signal: the bins (quantiles of the signal), the
residual's RMS and mean per bin, and whether the error depends on the bin (Kruskal–Wallis on its
square, one-way ANOVA on it). :func:`arxid.checks.where_it_fails` bins the one-step residual by
each signal with :func:`bin_signal`.

Every statistic comes from sums per bin (one pass over the binned samples, in the Rust core where
every finite residual is binned), not from the bins' samples split out; the ranks of the squared
residual are found once per residual (:class:`SquaredRanks`) and shared by every signal.
"""

from __future__ import annotations

import hashlib
import math

import numpy as np

from .._base import _core, metrics
from .._base.order_statistics import distinct, sorted_quantiles
from .._base.probabilities import chi2_sf, f_sf
from .._base.records import record

__all__ = ["SignalBins", "SquaredRanks", "bin_signal"]


@record(eq=False)
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


class SquaredRanks:
    """The ranks of the squared one-step residual over its finite samples, shared by every binned
    signal (the Kruskal–Wallis test needs one sort, not one per signal; ranks are whole or half
    numbers, so their sums per bin are exact in any order).

    ``order`` sorts e² over the finite samples (positions in the record), ``ranks`` holds the
    midrank of each finite sample in record order and ``ties`` the tie correction Σ (t³ − t).

    Parameters
    ----------
    e : ndarray of shape (n_samples,)
        The residual (NaN where it does not exist).
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
        """The finite residuals less their mean, (Σ of that)² / n and their sum of squares about
        the mean, as ``scipy.stats.f_oneway`` has them (computed once).

        Returns
        -------
        tuple of (ndarray, float, float)
        """
        if self._centred is None:
            self._centred = _centred(self.values)
        return self._centred


def _bin_index(xs: np.ndarray, n_bins: int) -> tuple[np.ndarray, np.ndarray] | None:
    """Bin edges of ``xs`` (its quantiles; for a signal with at most ``n_bins`` values, the midpoints
    between them) and the bin of each sample; None for a signal with a single value."""
    # One sort (a vectorised sort is faster than np.quantile's partition) gives the quantiles and,
    # for a signal with few values, its values; the quantile edges are all distinct for a signal
    # with more than n_bins values.
    ordered = np.sort(xs)
    edges = sorted_quantiles(ordered, np.linspace(0, 1, n_bins + 1))
    values = ordered[np.r_[True, ordered[1:] != ordered[:-1]]] if len(distinct(edges)) <= n_bins else None
    if values is not None and len(values) < 2:
        return None
    if values is not None and len(values) <= n_bins:
        mids = (values[1:] + values[:-1]) / 2
        return np.concatenate([[values[0]], mids, [values[-1]]]), np.searchsorted(values, xs)
    edges = distinct(edges)
    if len(edges) > 256:
        return edges, np.clip(np.searchsorted(edges, xs, side="right") - 1, 0, len(edges) - 2)
    # searchsorted(edges, x, "right") − 1 clipped to the bins: the inner edges at or below x
    # (edges[0] is the smallest sample, the last edge the largest, which falls in the last bin).
    where = np.zeros(len(xs), dtype=np.uint8)
    for edge in edges[1:-1]:
        where += xs >= edge
    return edges, where


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
    nb, have = len(counts), counts > 0
    k, n = int(np.count_nonzero(have)), len(es)
    d, normalized, sstot = _centred(es) if centred is None else centred
    sums = (np.bincount(where, weights=d, minlength=nb) if sums is None else sums)[have]
    ssbn = float(np.sum(sums**2 / counts[have])) - normalized
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (ssbn / (k - 1)) / ((sstot - ssbn) / (n - k))
    return float(f_sf(f, k - 1, n - k))


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

    def __init__(self, where: np.ndarray, nb: int, ranked: SquaredRanks):
        d = ranked.centred()[0]
        counts, sums, varies = _core.group_sums(where, nb, [ranked.values, ranked.squared, ranked.ranks, d])
        self.counts = counts.astype(np.intp)
        self.values, self.squares, self.ranks, self.centred = sums
        self.varies = bool(np.all(varies[counts > 0]))


def bin_signal(
    name: str, x: np.ndarray, e: np.ndarray, n_bins: int, ranked: SquaredRanks, memo: dict | None, tag: tuple
) -> SignalBins | None:
    """The residual ``e`` binned by the quantiles of ``x``.

    When every non-empty bin holds two samples or more (the usual case) the per-bin statistics come
    from sums per bin; otherwise from the bins' samples split out.

    Parameters
    ----------
    name : str
        The signal's name, as the bins report it.
    x : ndarray of shape (n_samples,)
        The signal, aligned with the residual.
    e : ndarray of shape (n_samples,)
        The one-step residual (NaN where it does not exist).
    n_bins : int
        Bins (quantiles of ``x``; fewer for a signal with few values).
    ranked : SquaredRanks
        The ranks of e², shared by every signal.
    memo : dict or None
        Bins kept per data set, reused when the same signal is binned on the same samples.
    tag : tuple
        The signal's name, shift and the data's array it comes from (the key in ``memo``).

    Returns
    -------
    SignalBins or None
        None when too few samples, a single value or a zero residual leave nothing to test.
    """
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
    else:  # a bin of one sample: scipy.stats on the groups (rare; scipy.stats is slow to import)
        from scipy import stats

        p_kw = float(stats.kruskal(*[g**2 for g in used]).pvalue)
    if used is None and shared is not None:
        p_an = _anova_p(es, where, counts, ranked.centred(), shared.centred) if shared.varies else 1.0
    elif used is None:
        p_an = _anova_p(es, where, counts, ranked.centred() if full else None) if _varies(es, where, counts) else 1.0
    else:
        from scipy import stats

        p_an = float(stats.f_oneway(*used).pvalue) if all(np.ptp(g) > 0 for g in used) else 1.0
    p_kw = 1.0 if not math.isfinite(p_kw) else p_kw
    p_an = 1.0 if not math.isfinite(p_an) else p_an
    p = min(1.0, 2 * min(p_kw, p_an))
    centers = (edges[1:] + edges[:-1]) / 2
    return SignalBins(name, edges, centers, rms, mean, counts, float(np.nanmax(rms) / overall), p)


def _kruskal(
    ok: np.ndarray, where: np.ndarray, nb: int, e: np.ndarray, ranked: SquaredRanks, shared: _BinSums | None = None
) -> float:
    """Kruskal–Wallis p-value of e² between the bins ``where`` of the samples ``ok``: from the shared
    ranks when ``ok`` holds every finite residual (their sums per bin from ``shared`` when given),
    else from the ranks of those samples."""
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
        return float(chi2_sf(h, int(np.count_nonzero(have)) - 1))
    idx = np.zeros(len(e), dtype=np.intp)
    idx[ok] = where
    sub = ranked.order[ok[ranked.order]]
    return _kruskal_sorted(e[sub] ** 2, idx[sub], nb)


def _kruskal_sorted(v: np.ndarray, group: np.ndarray, n_groups: int) -> float:
    """Kruskal–Wallis p-value of values ``v`` given in ascending order with their groups (as
    ``scipy.stats.kruskal`` on the groups: midranks for ties, tie-corrected H, χ² with k − 1
    degrees of freedom); linear in n once sorted."""
    n = len(v)
    starts = np.flatnonzero(np.r_[True, v[1:] != v[:-1]])
    ties = np.diff(np.r_[starts, n]).astype(float)
    ranks = np.repeat(starts + (ties + 1.0) / 2.0, ties.astype(np.intp))
    sums = np.bincount(group, weights=ranks, minlength=n_groups)
    sizes = np.bincount(group, minlength=n_groups).astype(float)
    have = sizes > 0
    h = 12.0 / (n * (n + 1.0)) * float(np.sum(sums[have] ** 2 / sizes[have])) - 3.0 * (n + 1.0)
    h /= 1.0 - float(np.sum(ties**3 - ties)) / (float(n) ** 3 - n)
    return float(chi2_sf(h, int(np.count_nonzero(have)) - 1))
