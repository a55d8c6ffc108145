"""The checks' fast kernels against the direct computations they replace, at 2M samples.

Each kernel is timed beside its reference in the same run (median of three calls) and their
answers compared:

- the low-frequency share of the remaining disturbance on a 1,999,997-sample error (19 × 105,263,
  a slow FFT length) against the one-sided periodogram from ``numpy.fft.rfft``;
- the Welch cross-spectral matrix of three signals against ``scipy.signal.csd`` of every pair;
- the order of e² (where it fails: the Kruskal–Wallis ranks) against ``np.argsort``;
- the quantile edges of a signal (one sort) against ``np.quantile``.

    python benches/checks_kernels.py [--n 2000000]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _timing import median_time  # noqa: E402


def _periodogram_share(e: np.ndarray, ts: float, split: float) -> float:
    weight = np.ones(len(e) // 2 + 1)
    weight[1 : (len(e) + 1) // 2] = 2.0
    spec = np.abs(np.fft.rfft(e)) ** 2 * weight
    return float(spec[np.fft.rfftfreq(len(e), ts) <= split].sum() / spec.sum())


def _csd_matrix(x: np.ndarray, nseg: int, ts: float) -> np.ndarray:
    from scipy.signal import csd

    k = 1 + (x.shape[1] - nseg) // (nseg // 2)
    _, s = csd(x[:, None, :], x[None, :, :], fs=1.0 / ts, nperseg=nseg, noverlap=nseg // 2, axis=-1)
    return np.moveaxis(s, -1, 0), k


def main() -> None:
    from arxid._base.order_statistics import sorted_quantiles
    from arxid.checks.binning import _argsort_nonnegative
    from arxid.checks.frequency import spectra
    from arxid.diagnosis.disturbance import _low_share

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2_000_000)
    n = parser.parse_args().n
    rng = np.random.default_rng(0)
    rows = []

    m = n - 3 if n % 19 else n  # 1,999,997 at the default size
    e = 0.3 * rng.standard_normal(m) + np.cumsum(rng.standard_normal(m)) * 1e-3
    new = _low_share(e, [(0, m)], 0.001, 2.0)
    ref = _periodogram_share(e, 0.001, 2.0)
    rows.append(
        (
            f"low-frequency share, {m:,} samples",
            median_time(lambda: _low_share(e, [(0, m)], 0.001, 2.0), 3),
            median_time(lambda: _periodogram_share(e, 0.001, 2.0), 3),
            abs(new - ref) / ref,
        )
    )

    x = np.vstack([rng.standard_normal(n), np.cumsum(rng.standard_normal(n)) * 0.01, rng.standard_normal(n)])
    nseg = 4096
    k = 1 + (n - nseg) // (nseg // 2)
    end = (k - 1) * (nseg // 2) + nseg
    _, s_new, _ = spectra(x, [(0, end)], 0.001, nseg)
    s_ref, _ = _csd_matrix(x[:, :end], nseg, 0.001)
    rows.append(
        (
            f"Welch cross-spectra, 3 signals x {n:,}",
            median_time(lambda: spectra(x, [(0, end)], 0.001, nseg), 3),
            median_time(lambda: _csd_matrix(x[:, :end], nseg, 0.001), 3),
            float(np.max(np.abs(s_new - s_ref)) / np.max(np.abs(s_ref))),
        )
    )

    v = rng.standard_normal(n) ** 2
    same = np.array_equal(v[_argsort_nonnegative(v)], np.sort(v))
    rows.append(
        (
            f"order of e², {n:,} samples",
            median_time(lambda: _argsort_nonnegative(v), 3),
            median_time(lambda: np.argsort(v), 3),
            0.0 if same else float("inf"),
        )
    )

    q = np.linspace(0, 1, 9)
    same = np.array_equal(sorted_quantiles(np.sort(x[0]), q), np.quantile(x[0], q))
    rows.append(
        (
            f"quantile edges, {n:,} samples",
            median_time(lambda: sorted_quantiles(np.sort(x[0]), q), 3),
            median_time(lambda: np.quantile(x[0], q), 3),
            0.0 if same else float("inf"),
        )
    )

    print(f"{'kernel':42s} {'fast':>8s} {'reference':>10s} {'speed-up':>9s} {'rel. difference':>16s}")
    for name, fast, ref_t, diff in rows:
        print(f"{name:42s} {fast:7.3f}s {ref_t:9.3f}s {ref_t / fast:8.1f}x {diff:16.1e}")


if __name__ == "__main__":
    main()
