"""A sweep over a fleet of logs read from files: in process against a Dask LocalCluster.

64 logs of 200,000 samples each (one input, ``.npz`` files in a temporary folder), the last 30 % of
each log validates; the default grid (na 1..4, nb 1..3, nk 0..5). In process: ``arxid.sweep(paths)``
reads the logs and sweeps them merged. Dask: the same call with ``client=`` on a
``LocalCluster(n_workers=2, threads_per_worker=1)``, the workers reading their own logs and sending
back R factors and scores. Both include reading the files.

Then one ARX(2,2,3) model fitted to all the logs, ``arxid.arx(paths, 2, 2, 3)``: in process (the
logs read and merged) against the same call with ``client=`` (each worker reduces its own logs to a
5 × 5 factor, the factors are combined by QR in a tree; the samples never leave the workers).

Run with ``make bench`` (or ``python benches/fleet.py [--quick]``). Timings are medians.
"""

from __future__ import annotations

import argparse
import os
import tempfile

import numpy as np
from scipy.signal import lfilter

import arxid
from _timing import median_time


def write_logs(folder: str, n_logs: int, n: int) -> list[str]:
    paths = []
    for i in range(n_logs):
        rng = np.random.default_rng(i)
        u = rng.standard_normal(n)
        a = [1, -1.5, 0.7]
        y = lfilter([0, 0, 0, 0.5, 0.25], a, u) + lfilter([1], a, 0.05 * rng.standard_normal(n))
        path = os.path.join(folder, f"flight{i:03d}.npz")
        np.savez(path, y=y, u=u.reshape(-1, 1), ts=0.01)
        paths.append(path)
    return paths


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="16 logs, fewer repeats")
    args = ap.parse_args()
    from dask.distributed import Client, LocalCluster

    n_logs, n, rep = (16, 200_000, 2) if args.quick else (64, 200_000, 3)
    with tempfile.TemporaryDirectory() as folder:
        paths = write_logs(folder, n_logs, n)
        print(
            f"arxid fleet sweep: {n_logs} logs x {n:,} samples from files, 30 % of each validates, "
            f"default grid (72 structures), {os.cpu_count()} cores; medians"
        )
        kw = dict(validation=0.3, progress=False, expect="stable", auto_extend=False)  # the default grid as it is
        ref = arxid.sweep(paths, **kw)
        t_local = median_time(lambda: arxid.sweep(paths, **kw), rep)
        with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=":0") as cluster, Client(cluster) as c:
            got = arxid.sweep(paths, **kw, client=c)
            t_dask = median_time(lambda: arxid.sweep(paths, **kw, client=c), rep)
            model = arxid.arx(paths, 2, 2, 3, client=c)
            t_arx_dask = median_time(lambda: arxid.arx(paths, 2, 2, 3, client=c), rep)
        diff = float(np.nanmax(np.abs(got.rms_val - ref.rms_val) / ref.rms_val))
        ref_model = arxid.arx(paths, 2, 2, 3)
        t_arx_local = median_time(lambda: arxid.arx(paths, 2, 2, 3), rep)
        arx_diff = float(np.max(np.abs(model.parameters_ - ref_model.parameters_) / np.abs(ref_model.parameters_)))
    print()
    print(f"  in process (2 threads)                  {t_local:8.3f} s")
    print(f"  Dask LocalCluster (2 workers x 1 thread) {t_dask:8.3f} s")
    print(
        f"  Dask / in process: {t_dask / t_local:.2f}  (overhead {100 * (t_dask / t_local - 1):+.0f} %, target < 30 %)"
    )
    print(f"  validation RMS, Dask vs in process: max rel. diff {diff:.1e}; best {got.structure_name(0)}")
    print()
    print(f"  one ARX(2,2,3) over all {n_logs} logs, arxid.arx(paths, 2, 2, 3):")
    print(f"  in process (read, merge, fit)            {t_arx_local:8.3f} s")
    print(f"  Dask LocalCluster, client=               {t_arx_dask:8.3f} s")
    print(f"  Dask / in process: {t_arx_dask / t_arx_local:.2f}")
    print(f"  parameters, Dask vs in process: max rel. diff {arx_diff:.1e}")


if __name__ == "__main__":
    main()
