"""Reports and plots of long records stay light: decimated for display with min/max envelopes (a
one-sample peak is kept), their size bounded independently of the record's length, the statistics
computed on every sample."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.analysis.pipeline import analyse
from arxid.analysis.report import render_html
from arxid.checks.bands import free_run_band
from arxid.plots.data import thin
from arxid.plots.diagnostics import plot_comparison

#: The stated cap of a report (bytes): figures are PNGs of fixed size drawn from at most a few
#: thousand points per curve, the tables have a fixed number of rows.
REPORT_CAP = 3_000_000


def _record(n: int, seed: int, spike_at: float | None = None) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(n))
    vbat = np.linspace(4.2, 3.5, n) + 0.01 * rng.standard_normal(n)
    y = lfilter([0.0, 0.5, 0.25], [1.0, -1.5, 0.7], u * vbat / 4.2) + 0.02 * rng.standard_normal(n)
    if spike_at is not None:
        y[int(spike_at * n)] += 40.0  # one sample far outside everything else
    return arxid.IOData(y, u, 0.01, extra={"vbat": vbat})


@pytest.mark.parametrize("n", [10_001, 1_000_003])
def test_thin_keeps_a_one_sample_peak_and_bounds_the_points(n):
    rng = np.random.default_rng(n)
    t = np.arange(n) * 0.001
    y = rng.standard_normal(n)
    i, j = n - 1, int(rng.integers(0, n - 1))  # one peak in the last, partial bucket
    y[i], y[j] = 50.0, -50.0
    tt, yy = thin(t, y, max_points=1200)
    assert len(tt) == len(yy) <= 1200
    assert yy.max() == 50.0 and yy.min() == -50.0
    # every kept value is a sample of the record, each bucket's extremes are its own
    assert np.isin(yy, y).all()


def _vertices(fig) -> int:
    count = 0
    for ax in fig.axes:
        count += sum(len(line.get_xdata()) for line in ax.lines)
        count += sum(len(p.vertices) for c in ax.collections for p in c.get_paths())
    return count


def test_comparison_plot_of_a_long_record_keeps_the_peak_with_a_bounded_number_of_points():
    import matplotlib.pyplot as plt

    counts = []
    for n in (20_000, 200_000):
        val = _record(n, 2, spike_at=0.37)
        model = arxid.arx(_record(n, 1), 2, 2, 1)
        cmp = arxid.compare({"ARX": model}, val)
        band = free_run_band(model, val)
        fig = plot_comparison(cmp, bands=[band])
        top = fig.axes[0]
        peak = max(float(np.nanmax(p.vertices[:, 1])) for c in top.collections for p in c.get_paths())
        assert peak >= val.y.max() - 1e-9  # the one-sample spike is drawn
        counts.append(_vertices(fig))
        plt.close(fig)
    assert counts[1] <= 1.1 * counts[0] + 100, counts  # 10x the samples, the same drawing
    assert counts[1] < 20_000, counts


def test_report_size_does_not_grow_with_the_record():
    sizes = []
    for n in (4_000, 40_000):  # ten times the samples, the same report
        a = analyse(_record(n, 1), _record(n, 2), orders=(2, 2, 1), max_steps=1)
        assert a.missing_effect == "u1*vbat"
        sizes.append(len(render_html(a).encode()))
    assert max(sizes) < REPORT_CAP, sizes
    assert sizes[1] < 1.3 * sizes[0], sizes
