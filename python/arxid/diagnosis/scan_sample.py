"""The estimation samples a parameter scan reads: on a long record, contiguous blocks spread evenly
over it, each its own experiment (no regressor straddles two blocks).

A scan (a dead zone's width, a saturation's levels, an exponent, a sensor's level) refits the model
once per value it tries, so its cost grows with the record; its answer does not: the parameter
is pinned long before 100k samples. Blocks spread over the whole record see every operating point
(a battery that sags over a flight, a staircase that visits its levels late) where a prefix sees the
first minutes only. The winner is then scored (its F-test, its refit, its validation) on every
sample, so the evidence the diagnosis reports is the full record's.

A free run restarts at each block from the measured outputs, a start the full record makes once:
its error counts only after the block's warm-up (:meth:`ScanSample.settled`).
"""

from __future__ import annotations

import math

import numpy as np

from .._base.records import record
from ..data.iodata import IOData

__all__ = ["SCAN_SAMPLES", "SCAN_BLOCKS", "ScanSample", "scan_sample"]

#: A scan reads at most this many estimation samples. On seeded plants the sample's value and the
#: full record's agree to well within the estimate's own spread (tests/test_scan_sample.py); each
#: value tried then costs a few milliseconds, and a diagnosis tries a few hundred.
SCAN_SAMPLES = 100_000
#: Blocks the capped sample is cut into: long enough that a free run settles in a small share of
#: each, many enough to spread over the record.
SCAN_BLOCKS = 20
#: A block's free run counts once its start's transient has decayed below this share.
_SETTLED = 1e-6


@record
class ScanSample:
    """The samples a scan reads.

    Attributes
    ----------
    data : IOData
        The record itself, or its blocks one after the other (each an experiment).
    block : int
        Samples per block (0 when ``data`` is the whole record).
    """

    data: IOData
    block: int = 0

    def settled(self, a: np.ndarray) -> np.ndarray | None:
        """Where a free run of the dynamics ``a`` (A(z⁻¹), leading 1) counts: every sample but each
        later block's warm-up, until its start's transient has decayed by :data:`_SETTLED` (at most
        half the block); None for the whole record (every sample counts).

        Parameters
        ----------
        a : ndarray
            Denominator of the free run's dynamics.

        Returns
        -------
        ndarray of bool of shape (n_samples,), or None
        """
        if not self.block:
            return None
        radius = float(np.max(np.abs(np.roots(a)))) if np.size(a) > 1 else 0.0
        warm = self.block // 2 if radius >= 1 else math.ceil(math.log(_SETTLED) / math.log(max(radius, 1e-3)))
        counts = np.ones(self.data.n_samples, dtype=bool)
        for start in range(self.block, self.data.n_samples, self.block):
            counts[start : start + min(warm + len(a), self.block // 2)] = False
        return counts


def scan_sample(data: IOData, cap: int | None = None, blocks: int | None = None) -> ScanSample:
    """``data`` itself when it holds at most ``cap`` samples, else ``blocks`` contiguous blocks of
    ``cap / blocks`` samples each, evenly spaced from its start to its end, as experiments.

    Parameters
    ----------
    data : IOData
        Estimation data.
    cap : int, optional
        At most this many samples (default :data:`SCAN_SAMPLES`).
    blocks : int, optional
        Number of blocks (default :data:`SCAN_BLOCKS`).

    Returns
    -------
    ScanSample
        Deterministic: the same data give the same sample. A block keeps the record's own
        experiment boundaries inside it.
    """
    cap = SCAN_SAMPLES if cap is None else int(cap)
    blocks = SCAN_BLOCKS if blocks is None else int(blocks)
    n = data.n_samples
    if n <= cap or blocks < 2:
        return ScanSample(data)
    length = cap // blocks
    step = (n - length) / (blocks - 1)
    return ScanSample(IOData.merge([data[round(k * step) : round(k * step) + length] for k in range(blocks)]), length)
