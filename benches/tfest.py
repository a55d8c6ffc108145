"""How fast ``arxid.tfest`` (SRIVC, state-variable filtering in the Rust core) identifies a
3-pole continuous-time model from 100,000 samples, and how accurately, against the discrete route
(ARX + d2c) measured in the same run.

The plant is (s + 3) / ((s + 0.5)(s² + 0.6 s + 1)) with a dead time of 0.0137 s (1.37 samples),
sampled at ts = 0.01 s by an exact zero-order hold, a held random binary input and 10 % output
noise. Times are the median of 3 runs after a warm-up (wall clock; the CPU time of one run is
printed too, as other processes on a shared machine inflate the wall clock); the SRIVC iteration count and the largest
relative pole error are printed for both routes.

Target (issue 24): well under a second for SRIVC on 100k samples with 3 poles.

    python benches/tfest.py [--samples 100000]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from scipy.signal import lfilter

import arxid
from arxid.models.continuous import c2d

sys.path.insert(0, str(Path(__file__).parent))
from _timing import median_time  # noqa: E402

NUM, DEN, TS, TAU = [1.0, 3.0], np.polymul([1.0, 0.5], [1.0, 0.6, 1.0]), 0.01, 0.0137


def pole_error(est: np.ndarray) -> float:
    true = np.roots(DEN)
    key = lambda r: (round(r.real, 9), r.imag)  # noqa: E731
    est, true = np.array(sorted(est, key=key)), np.array(sorted(true, key=key))
    return float(np.max(np.abs(est - true) / np.abs(true)))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=int, default=100_000)
    n = parser.parse_args().samples
    rng = np.random.default_rng(0)
    u = np.sign(rng.standard_normal(n // 50 + 1)).repeat(50)[:n]
    a, b = c2d(NUM, DEN, TS, TAU)
    y0 = lfilter(b, a, u)
    data = arxid.IOData(y0 + 0.1 * np.std(y0) * rng.standard_normal(n), u, ts=TS)

    arxid.tfest(data[:2000], 3, 1, delay=TAU)  # warm-up
    t_srivc = median_time(lambda: arxid.tfest(data, 3, 1, delay=TAU), 3)
    cpu = time.process_time()
    m = arxid.tfest(data, 3, 1, delay=TAU)
    cpu = time.process_time() - cpu

    def discrete_route():
        # ARX, then its poles mapped by s = ln(z)/ts (what d2c does to the poles; the exact d2c of
        # a noisy fractional-delay numerator usually does not exist).
        arx = arxid.arx(data, 3, 4, 2)
        return np.log(np.roots(arx.a).astype(complex)) / TS

    t_arx = median_time(discrete_route, 3)
    err_arx = f"{pole_error(discrete_route()):.1%}"
    print(f"tfest (SRIVC) on {n} samples, 3 poles, 1 zero, known dead time")
    print(f"  time {t_srivc:.3f} s (CPU {cpu:.3f} s), {m.iterations_} iterations (converged: {m.converged_})")
    print(f"  largest pole error {pole_error(m.continuous_poles()):.2%}, fit {m.fit_percent_:.1f} %")
    print(f"ARX(3,4,2) + d2c of its poles on the same data: {t_arx:.3f} s, largest pole error {err_arx}")
    print(f"ratio SRIVC / ARX+d2c time: {t_srivc / t_arx:.1f}")
    short = data[:20_000]
    t_delay = median_time(lambda: arxid.tfest(short, 3, 1, delay="estimate", max_delay=0.05), 1)
    found = arxid.tfest(short, 3, 1, delay="estimate", max_delay=0.05).dead_time_
    print(f"dead time searched on 20000 samples: {found:.5f} s (true {TAU}) in {t_delay:.2f} s")


if __name__ == "__main__":
    main()
