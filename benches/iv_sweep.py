"""Instrumental-variable sweep against the least-squares sweep and a numpy IV, printed as ratios.

Closed-loop data (``arxid.datasets.pi_loop``, 200,000 samples, setpoint as instrument), grid na 1..6,
nb 1..6, nk 0..4 (180 structures), validated in free run on 100,000 other samples.

* ``sweep(method="iv")``: instruments once, one pass of cross moments in the Rust core, each
  structure solved from them, simulated in lanes;
* ``sweep()`` (least squares) on the same grid, the speed IV should keep;
* numpy: the IV normal equations of every structure built from its own lagged columns (one
  structure timed, times the grid size), validation not included.

Run with ``python benches/iv_sweep.py [--quick]``. Timings are medians.
"""

from __future__ import annotations

import argparse

import numpy as np

import arxid
from _timing import median_time
from arxid.datasets import pi_loop
from arxid.models.iv import instrument_signals
from arxid.models.lagged import lagged_columns


def numpy_iv_one(d: arxid.IOData, xy: np.ndarray, xu: np.ndarray, na: int, nb: int, nk: int) -> np.ndarray:
    lag = max(na, nb + nk - 1)
    cols = [(d.y, 0)] + [(d.y, k) for k in range(1, na + 1)] + [(d.u[:, 0], nk + j) for j in range(nb)]
    cols += [(xy, k) for k in range(1, na + 1)] + [(xu[:, 0], nk + j) for j in range(nb)]
    mat, _ = lagged_columns(cols, d.segments, lag)
    p = na + nb
    phi, z = mat[:, 1 : 1 + p], mat[:, 1 + p :]
    return np.linalg.solve(z.T @ phi, z.T @ mat[:, 0])


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--quick", action="store_true", help="20,000 samples")
    args = parser.parse_args()
    n = 20_000 if args.quick else 200_000
    est, val = pi_loop(0, n), pi_loop(1, n // 2)
    grid = dict(na=range(1, 7), nb=range(1, 7), nk=range(0, 5))
    n_structures = 6 * 6 * 5
    kw = dict(validation=val, progress=False, expect="stable", top=None)
    t_iv = median_time(lambda: arxid.sweep(est, **grid, **kw, method="iv", instruments="r"), 3)
    t_ls = median_time(lambda: arxid.sweep(est, **grid, **kw), 3)
    xy, xu = instrument_signals(est, "r")
    t_np = median_time(lambda: numpy_iv_one(est, xy, xu, 3, 3, 2), 3) * n_structures
    print(f"IV sweep, {n_structures} structures, {n:,} + {n // 2:,} samples")
    print(f"  arxid sweep(method='iv')     {t_iv:8.3f} s")
    print(f"  arxid sweep() least squares  {t_ls:8.3f} s   IV / LS = {t_iv / t_ls:.2f}")
    print(f"  numpy IV per structure       {t_np:8.3f} s   numpy / arxid IV = {t_np / t_iv:.1f} (fits only)")


if __name__ == "__main__":
    main()
