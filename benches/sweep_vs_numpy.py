"""arxid.sweep against numpy baselines on the issue-3 grid, printed as ratios from one run.

Grid na 1..10, nb 1..10, nk 0..10 (1,100 structures), SISO, 200,000 estimation + 200,000
validation samples, every structure fitted and simulated (free run) on the validation data.

(a) naive: per structure, build the regressor with numpy, numpy.linalg.lstsq, simulate with
    scipy.signal.lfilter (timed on an evenly spaced subset of structures and extrapolated);
(b) vectorised numpy: one Gram matrix of [Phi_max | y], a Cholesky solve per structure, lfilter
    simulation (all structures): ``arxid.selection.baseline``, which ``arxid bench`` uses too.

Also: the fit part alone against one Gram pass, peak memory, and scaling in N.
``expect="stable"``: the plant is known to be stable, so arxid skips its integrator test (five
refits of the best structures), which the baselines do not do either. Every structure is simulated
(``top=None``). The machine's limit for the free run is measured in the same run: the multiply-adds
the simulations need, at the FMA throughput of all cores (``_core.fma_limit``).

Run with ``make bench`` (or ``python benches/sweep_vs_numpy.py [--quick]``). Timings are medians.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from scipy.signal import lfilter, lfiltic

import arxid
from _timing import median_time
from arxid._base import _core
from arxid.selection.baseline import ArxGrid, numpy_sweep

NA, NB, NK = range(1, 11), range(1, 11), range(0, 11)
_GRID = ArxGrid(na_max=max(NA), span=max(NK) + max(NB), lag=max(max(NA), max(NK) + max(NB) - 1), n_inputs=1)


def make_data(n: int, seed: int):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    e = 0.05 * rng.standard_normal(n)
    a = [1, -1.5, 0.7]
    y = lfilter([0, 0, 0, 0.5, 0.25], a, u) + lfilter([1], a, e)
    return y, u


def grid():
    return [(a, b, k) for a in NA for b in NB for k in NK]


def regressor(y, u, na, nb, nk, lag):
    rows = np.arange(lag, len(y))
    cols = [-y[rows - i] for i in range(1, na + 1)] + [u[rows - nk - j] for j in range(nb)]
    return np.column_stack(cols), y[rows]


def simulate(theta, na, nb, nk, yv, uv, lag):
    """Free run from measured initial outputs at `lag` (same start as arxid), RMS over the rest."""
    a = np.concatenate([[1.0], theta[:na]])
    b = np.concatenate([np.zeros(nk), theta[na:]])
    zi = lfiltic(b, a, yv[lag - 1 :: -1][:na], uv[lag - 1 :: -1][: len(b) - 1])
    with np.errstate(all="ignore"):
        sim, _ = lfilter(b, a, uv[lag:], zi=zi)
        return float(np.sqrt(np.mean((yv[lag:] - sim) ** 2)))


def naive(y, u, yv, uv, structures, lag):
    out = []
    for na, nb, nk in structures:
        phi, yy = regressor(y, u, na, nb, nk, lag)
        theta, *_ = np.linalg.lstsq(phi, yy, rcond=None)
        out.append(simulate(theta, na, nb, nk, yv, uv, lag))
    return out


def envelope(y, u, lag):
    return _GRID.matrix(y, u.reshape(-1, 1))


def gram_pass(y, u, lag):
    return _GRID.gram(y, u.reshape(-1, 1))


def vectorised(y, u, yv, uv, structures, lag):
    """arxid's shared numpy reference (`arxid.selection.baseline`): Gram + Cholesky + lfilter."""
    est, val = arxid.IOData(y, u, ts=0.01), arxid.IOData(yv, uv, ts=0.01)
    return list(numpy_sweep(est, val, [(a, (b,), (k,)) for a, b, k in structures]).rms_free_run)


_PEAK_CHILD = r"""
import os, sys, threading, time
import numpy as np
sys.path.insert(0, sys.argv[1])
from sweep_vs_numpy import make_data, NA, NB, NK
import arxid
arxid.sweep(arxid.IOData(*make_data(2000, 5), ts=0.01), na=range(1, 3), nb=1, nk=range(0, 2), validation=0.5,
            progress=False)  # imports and thread pool outside the measurement
y, u = make_data(200_000, 1)
yv, uv = make_data(200_000, 2)
est, val = arxid.IOData(y, u, ts=0.01), arxid.IOData(yv, uv, ts=0.01)
page = os.sysconf("SC_PAGE_SIZE")
def rss():
    with open("/proc/self/statm") as fh:
        return int(fh.read().split()[1]) * page
base = rss()
peak = [base]
done = threading.Event()
def sample():
    while not done.is_set():
        peak[0] = max(peak[0], rss())
        time.sleep(0.001)
th = threading.Thread(target=sample)
th.start()
arxid.sweep(est, na=NA, nb=NB, nk=NK, validation=val, progress=False, simulate_estimation=False)
done.set()
th.join()
print(max(peak[0], rss()) - base)
"""


def peak_rss_of_sweep() -> int:
    """Peak resident memory a fresh process gains while running the benchmark sweep (sampled
    every millisecond), or -1 where /proc is not available."""
    import subprocess
    import sys

    if not os.path.exists("/proc/self/statm"):
        return -1
    out = subprocess.run(
        [sys.executable, "-c", _PEAK_CHILD, os.path.dirname(os.path.abspath(__file__))],
        capture_output=True,
        text=True,
        check=True,
    )
    return int(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="smaller repeats, skip the 2,000,000-sample row")
    ap.add_argument("--naive-subset", type=int, default=22, help="structures timed for the naive baseline")
    args = ap.parse_args()
    rep = 3 if args.quick else 5
    n = 200_000
    y, u = make_data(n, 1)
    yv, uv = make_data(n, 2)
    est = arxid.IOData(y, u, ts=0.01)
    val = arxid.IOData(yv, uv, ts=0.01)
    structures = grid()
    lag = max(NA[-1], NB[-1] + NK[-1] - 1)
    print(
        f"arxid sweep benchmark: {len(structures)} structures (na 1..10, nb 1..10, nk 0..10), SISO, "
        f"{n:,} estimation + {n:,} validation samples, {os.cpu_count()} cores; medians"
    )

    def run_arxid():
        return arxid.sweep(
            est,
            na=NA,
            nb=NB,
            nk=NK,
            validation=val,
            progress=False,
            simulate_estimation=False,
            top=None,
            expect="stable",  # the plant is known stable: no integrator test (the baselines do none)
        )

    res = run_arxid()
    t_arxid = median_time(run_arxid, rep)
    # correctness spot check against the baselines
    check = [structures[i] for i in range(0, len(structures), 157)]
    ref_naive = naive(y, u, yv, uv, check, lag)
    ref_vec = vectorised(y, u, yv, uv, check, lag)
    lookup = {(int(res.na[i]), int(res.nb[i, 0]), int(res.nk[i, 0])): res.rms_val[i] for i in range(len(res))}
    worst = max(abs(lookup[s] - r) / r for s, r in zip(check, ref_naive) if np.isfinite(r) and np.isfinite(lookup[s]))
    worst_v = max(abs(lookup[s] - r) / r for s, r in zip(check, ref_vec) if np.isfinite(r) and np.isfinite(lookup[s]))

    subset = structures[:: max(1, len(structures) // args.naive_subset)]
    t_naive_sub = median_time(lambda: naive(y, u, yv, uv, subset, lag), 1 if args.quick else 3)
    t_naive = t_naive_sub * len(structures) / len(subset)
    t_vec = median_time(lambda: vectorised(y, u, yv, uv, structures, lag), 1 if args.quick else 3)

    grid_arr = np.array(structures, dtype=np.int64)
    ua, uva = u.reshape(-1, 1), uv.reshape(-1, 1)
    t_fit = median_time(lambda: _core.sweep(y, ua, [0], grid_arr, [], simulate_estimation=False), rep * 2)
    t_gram = median_time(lambda: gram_pass(y, u, lag), rep * 2)
    t_gram_mm = median_time(lambda a=envelope(y, u, lag): a.T @ a, rep * 2)  # noqa: B008
    t_core = median_time(
        lambda: _core.sweep(y, ua, [0], grid_arr, [], yv=yv, uv=uva, starts_v=[0], simulate_estimation=False), rep
    )
    t_fit_val = median_time(
        lambda: _core.sweep(y, ua, [0], grid_arr, [], yv=yv, uv=uva, starts_v=[0], simulate_estimation=False, top=0),
        rep,
    )

    print()
    print(
        f"  arxid.sweep (fit + validation free run, ranked result) {t_arxid:8.3f} s   (Rust core alone {t_core:.3f} s)"
    )
    print(
        f"  (a) naive numpy: regressor + lstsq + lfilter          {t_naive:8.3f} s   "
        f"(timed on {len(subset)} structures, extrapolated to {len(structures)})"
    )
    print(f"  (b) vectorised numpy: Gram + Cholesky + lfilter       {t_vec:8.3f} s   (all structures)")
    print(f"  ratio vs (a): {t_naive / t_arxid:7.1f} x   (target >= 250 x)")
    print(f"  ratio vs (b): {t_vec / t_arxid:7.1f} x   (target >= 20 x)")
    # The machine's limit for the free-run part: the multiply-adds it needs (each structure's na + nb
    # coefficients and its error, per sample, eight structures per vector) at the FMA throughput.
    n_sim = len(yv) - lag
    vectors = sum(na + nb + 1 for na, nb, _ in structures) * n_sim // 8
    t_limit = median_time(lambda: _core.fma_limit(vectors), rep)
    t_sim = max(t_core - t_fit_val, 1e-9)
    print(
        f"  free-run part {t_sim:.3f} s (core minus fits on both data sets); the same {vectors * 8 / 1e9:.1f} G "
        f"multiply-adds at the FMA throughput {t_limit:.3f} s: {t_sim / t_limit:.1f} x from the limit"
    )
    print(
        f"  validation RMS agreement with the baselines on {len(check)} structures: "
        f"max rel. diff {worst:.1e} (lstsq), {worst_v:.1e} (Cholesky)"
    )
    print()
    print(f"  fit part alone (1,100 parameter vectors + losses, TSQR) {t_fit:8.4f} s")
    print(
        f"  one Gram pass of [Phi_max | y] (build + Phi^T Phi)      {t_gram:8.4f} s   (Phi^T Phi alone {t_gram_mm:.4f} s)"  # noqa: E501
    )
    print(f"  fit / Gram pass: {t_fit / t_gram:5.2f}   (target < 3; vs Phi^T Phi alone {t_fit / t_gram_mm:.2f})")
    print()
    inputs = y.nbytes + u.nbytes + yv.nbytes + uv.nbytes
    peak = peak_rss_of_sweep()
    if peak >= 0:
        print(
            f"  peak memory of arxid.sweep above its inputs (fresh process): {peak / 2**20:.1f} MiB "
            f"(inputs {inputs / 2**20:.1f} MiB; target < 2 x inputs + O(threads N))"
        )
    print()
    print("  scaling (arxid, same grid; 'solve' = fit part minus one TSQR of the largest regressor):")
    print(f"  {'N (est = val)':>14}  {'sweep':>9}  {'fit part':>9}  {'TSQR':>9}  {'solve/structure':>16}")
    env = np.array([[max(NA), max(NB) + max(NK), 0]], dtype=np.int64)
    sizes = [20_000, 200_000] + ([] if args.quick else [2_000_000])
    for nn in sizes:
        y2, u2 = make_data(nn, 3)
        yv2, uv2 = make_data(nn, 4)
        u2c, uv2c = u2.reshape(-1, 1), uv2.reshape(-1, 1)
        r = 1 if nn > 1_000_000 else rep
        t_all = median_time(
            lambda: _core.sweep(y2, u2c, [0], grid_arr, [], yv=yv2, uv=uv2c, starts_v=[0], simulate_estimation=False),  # noqa: B023
            r,  # noqa: B023
        )
        t_f = median_time(lambda: _core.sweep(y2, u2c, [0], grid_arr, [], simulate_estimation=False), r * 2)  # noqa: B023
        t_q = median_time(lambda: _core.sweep(y2, u2c, [0], env, [], simulate_estimation=False), r * 2)  # noqa: B023
        per = max(t_f - t_q, 0.0) / len(structures)
        print(f"  {nn:>14,}  {t_all:8.3f}s  {t_f:8.4f}s  {t_q:8.4f}s  {per * 1e6:13.1f} us")


if __name__ == "__main__":
    main()
