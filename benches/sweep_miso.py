"""Two-stage MISO sweep against a vectorised numpy arxstruc, printed as ratios from one run.

Three inputs, na 1..6, nb 1..4 and nk 0..8 per input: 279,936 structures on 50,000 estimation +
50,000 validation samples (issue 28's configuration, target >= 20x) and on 200,000 + 200,000. arxid
ranks every structure by its one-step validation error (stage 1) and fits and simulates the best
1,000 in free run (stage 2), as ``arxid.sweep(..., top=1000)``.

Baseline: MATLAB's ``arxstruc`` in vectorised numpy, the one-step ranking alone: one Gram matrix of
the largest regressor on each data set, then per structure a Cholesky solve and a validation
quadratic form (``arxid.selection.baseline``, shared with ``arxid bench``). Its per-structure part
is timed on a random subset of structures and extrapolated (the Gram matrices are timed in full).
Also a row for a grid of over a million structures, and the default sweep (the integrator verdict
decides the measure: its unit-root test and the settling evidence of its best free-run structures)
against the same sweep with ``expect="stable"`` (no verdict) on 200,000 + 200,000 samples (issue 42:
at most 1.15x), as the median of paired ratios: the two run in turn, several times.

Run with ``make bench`` (or ``python benches/sweep_miso.py [--quick]``). Timings are medians.
"""

from __future__ import annotations

import argparse
import os

import numpy as np
from scipy.signal import lfilter

import arxid
from _timing import median_time
from arxid.selection.baseline import ArxGrid, arxstruc

NA, NB = range(1, 7), range(1, 5)


def make_data(n: int, seed: int) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((n, 3))
    a = [1, -1.5, 0.7]
    y = lfilter([0, 0, 0.5, 0.25], a, u[:, 0]) + lfilter([0, 0.3], a, u[:, 1])
    y += lfilter([0, 0, 0, 0, -0.2], a, u[:, 2]) + lfilter([1], a, 0.05 * rng.standard_normal(n))
    return arxid.IOData(y, u, ts=0.01)


def grid_of(nk_max: int) -> ArxGrid:
    """The envelope of the bench's grid (arxid's shared numpy reference, ``arxid.selection.baseline``)."""
    return ArxGrid(na_max=max(NA), span=nk_max + max(NB), lag=nk_max + max(NB) - 1, n_inputs=3)


def random_structures(nk_max: int, count: int, seed: int):
    rng = np.random.default_rng(seed)
    na = rng.integers(min(NA), max(NA) + 1, count)
    nb = rng.integers(min(NB), max(NB) + 1, (count, 3))
    nk = rng.integers(0, nk_max + 1, (count, 3))
    return [(int(a), tuple(map(int, b)), tuple(map(int, k))) for a, b, k in zip(na, nb, nk)]


def run_row(est, val, nk_max: int, subset: int, rep: int) -> tuple:
    n_structures = len(NA) * len(NB) ** 3 * (nk_max + 1) ** 3

    def sweep():
        return arxid.sweep(
            est,
            na=NA,
            nb=NB,
            nk=range(0, nk_max + 1),
            validation=val,
            top=1000,
            progress=False,
            simulate_estimation=False,
            expect="stable",  # known stable: no integrator test (the baseline does none)
        )

    res = sweep()
    t_arxid = median_time(sweep, rep)
    grid = grid_of(nk_max)
    t_gram = median_time(lambda: [grid.gram(d.y, d.u) for d in (est, val)], rep)
    g, gv = grid.gram(est.y, est.u), grid.gram(val.y, val.u)
    sample = random_structures(nk_max, subset, 7)
    t_sub = median_time(lambda: arxstruc(g, gv, grid, sample), max(1, rep - 2))
    t_numpy = t_gram + t_sub / subset * n_structures
    # Agreement of the one-step validation errors on the subset.
    lookup = {
        (int(res.na[i]), tuple(map(int, res.nb[i])), tuple(map(int, res.nk[i]))): res.rms_val_one_step[i]
        for i in range(len(res))
    }
    ref = arxstruc(g, gv, grid, sample[:200])[1] / (val.n_samples - grid.lag)
    ours = np.array([lookup[s] ** 2 for s in sample[:200]])
    agree = float(np.max(np.abs(ours - ref) / ref))
    return n_structures, t_arxid, t_numpy, t_sub / subset, agree, res


def verdict_cost(est, val, pairs: int) -> tuple[float, float, float, str]:
    """The default sweep (integrator verdict) against the same with ``expect="stable"``, run in
    turn ``pairs`` times (a drifting or shared machine slows both of a pair alike): the median times
    of each, the median of the per-pair ratios, and the verdict's reason."""

    def sweep(expect):
        return arxid.sweep(
            est, na=NA, nb=NB, nk=range(0, 9), validation=val, top=1000, progress=False, simulate_estimation=False,
            expect=expect,
        )  # fmt: skip

    res = sweep(None)
    sweep("stable")
    times: dict = {None: [], "stable": []}
    for k in range(pairs):
        # Alternate which goes first, so neither always runs on the warmer (or busier) machine.
        for expect in (None, "stable") if k % 2 == 0 else ("stable", None):
            times[expect].append(median_time(lambda e=expect: sweep(e), 1))
    ratio = float(np.median(np.array(times[None]) / np.array(times["stable"])))
    return float(np.median(times[None])), float(np.median(times["stable"])), ratio, res.integrating_reason


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer repeats, skip the million-structure row")
    ap.add_argument("--subset", type=int, default=3000, help="structures timed for the numpy baseline")
    args = ap.parse_args()
    rep = 3 if args.quick else 5
    print(
        f"arxid two-stage MISO sweep: 3 inputs, na 1..6, nb 1..4 per input, estimation and validation records "
        f"of equal length, best 1,000 simulated in free run, {os.cpu_count()} cores; medians"
    )
    print()
    print(
        f"  {'samples (est + val)':>19}  {'grid':>18}  {'structures':>11}  {'arxid':>8}  {'numpy arxstruc':>15}  "
        f"{'per structure':>14}  {'ratio':>7}"
    )
    first = {}
    for n in (50_000, 200_000):
        est, val = make_data(n, 1), make_data(n, 2)
        for nk_max in [8] + ([13] if n == 200_000 and not args.quick else []):
            r = run_row(est, val, nk_max, args.subset, rep if nk_max == 8 else 1)
            n_s, t_a, t_np, per, agree, res = r
            print(
                f"  {f'{n:,} + {n:,}':>19}  {'nk 0..' + str(nk_max) + ' per input':>18}  {n_s:>11,}  {t_a:7.3f}s  "
                f"{t_np:14.2f}s  {per * 1e6:11.1f} us  {t_np / t_a:6.1f}x"
            )
            if nk_max == 8:
                first[n] = (res, t_a, t_np, agree)
    print()
    for n, target in ((50_000, 20), (200_000, 15)):
        res, t_a, t_np, agree = first[n]
        print(
            f"  {n:,} + {n:,} samples: arxid (both stages) {t_np / t_a:.1f} x the numpy one-step ranking alone "
            f"(target >= {target} x); one-step validation errors agree to {agree:.1e} (relative); "
            f"best {res.structure_name(0)}"
        )
    print(f"  numpy per-structure cost timed on {args.subset:,} random structures and extrapolated")
    est, val = make_data(200_000, 1), make_data(200_000, 2)
    pairs = 5 if args.quick else 9
    t_default, t_stable, ratio, reason = verdict_cost(est, val, pairs)
    print()
    print(
        f"  default sweep (integrator verdict) {t_default:.3f} s, with expect='stable' {t_stable:.3f} s "
        f"(medians of {pairs} runs each, in turn): {ratio:.2f} x, the median of the {pairs} paired ratios "
        f"(target <= 1.15 x); 200,000 + 200,000 samples, nk 0..8 per input"
    )
    print(f"  verdict: {reason}")


if __name__ == "__main__":
    main()
