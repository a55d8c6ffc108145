"""The analysis of a fleet on a Dask LocalCluster against the in-process analysis of the merged logs.

The fleet: ``.npz`` logs in a temporary folder, each a second-order plant; in every other log the
input is scaled by a sagging battery (``u * vbat / 4.2``, as in ``analyse_scale.py``), the others
have a constant gain; vbat and a decoy are logged in every log. The last 30 % of each log validates.
Same data, same orders (ARX(2,2,1)), same candidate list, one run each:

- in process: the logs read and merged as experiments of one IOData (``arxid.data.logs.merged_parts``),
  then ``arxid.analyse(est, val, orders=..., candidates=...)`` (which also compares, locates the
  failures, checks the frequency response and the bands: the fleet analysis does not);
- fleet: ``arxid.analyse(paths, client=..., orders=..., candidates=...)`` on a
  ``LocalCluster(n_workers=2, threads_per_worker=1)`` (started before the clock), the workers reading
  their own logs; the diagnosis and the ladder run on sufficient statistics where the logs are.

It prints both times, their ratio (the overhead of the fleet form), the in-process time of the
diagnosis and ladder alone, and the agreement: the missing effect, the largest relative difference
of the suspects' scores and of the ladder's validation errors, and the logs named as showing the
effect against those simulated with it.

Run with ``make bench`` (or ``python benches/analyse_fleet.py [--quick]``).
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time

import numpy as np
from scipy.signal import lfilter

import arxid
from arxid.data.logs import merged_parts

CANDIDATES = ["u1*vbat", "vbat", "decoy", "u1^2", "u1^3", "const", "time", "na+1", "nb+1", "nk-1", "nk+1"]


def write_logs(folder: str, n_logs: int, n: int) -> tuple[list[str], list[str]]:
    """The logs as ``.npz`` files; and the names of those with the battery effect."""
    paths, with_effect = [], []
    for i in range(n_logs):
        rng = np.random.default_rng(i)
        u = np.sign(rng.standard_normal(n)) * 0.5 + 0.5 * rng.standard_normal(n)
        sag = np.linspace(0.0, 1.0, n)
        vbat = 4.2 - 0.9 * sag + 0.01 * rng.standard_normal(n)
        decoy = 20.0 + 0.05 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n / 4000)
        battery = i % 2 == 0
        a = [1.0, -1.5, 0.7]
        y = lfilter([0.0, 0.5, 0.25], a, u * vbat / 4.2 if battery else 0.9 * u)
        y += lfilter([1.0], a, 0.02 * rng.standard_normal(n))
        path = os.path.join(folder, f"flight{i:03d}.npz")
        np.savez(path, y=y, u=u.reshape(-1, 1), ts=0.001, extra_vbat=vbat, extra_decoy=decoy)
        paths.append(path)
        if battery:
            with_effect.append(os.path.basename(path))
    return paths, with_effect


def read_log(path: str) -> arxid.IOData:
    """A log with its logged signals (pickled to the workers by value)."""
    with np.load(path) as z:
        extra = {"vbat": z["extra_vbat"], "decoy": z["extra_decoy"]}
        return arxid.IOData(z["y"], z["u"], float(z["ts"]), extra=extra)


def _rel(a: np.ndarray, b: np.ndarray) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b) & (b != 0)
    return float(np.max(np.abs(a[ok] - b[ok]) / np.abs(b[ok]))) if ok.any() else 0.0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="8 logs of 20,000 samples")
    args = ap.parse_args()
    from dask.distributed import Client, LocalCluster

    n_logs, n = (8, 20_000) if args.quick else (16, 100_000)
    orders = (2, 2, 1)
    with tempfile.TemporaryDirectory() as folder:
        paths, with_effect = write_logs(folder, n_logs, n)
        print(
            f"arxid fleet analysis: {n_logs} logs x {n:,} samples from files (battery effect in {len(with_effect)}), "
            f"30 % of each validates, ARX{orders}, {len(CANDIDATES)} candidates, {os.cpu_count()} cores; one run each"
        )
        t = time.perf_counter()
        est, val = merged_parts(paths, read_log, 0.3)
        local = arxid.analyse(est, val, orders=orders, candidates=CANDIDATES)
        t_local = time.perf_counter() - t
        with LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=":0") as cluster, Client(cluster) as c:
            t = time.perf_counter()
            fleet = arxid.analyse(paths, client=c, read=read_log, orders=orders, candidates=CANDIDATES)
            t_fleet = time.perf_counter() - t
        stage = "diagnosis and ladder"
        print(f"  in process (read, merge, analyse):  {t_local:8.2f} s  ({stage} {local.timings['diagnose']:.2f} s)")
        print(f"  fleet on a LocalCluster:            {t_fleet:8.2f} s  ({stage} {fleet.timings['diagnose']:.2f} s)")
        print(f"  overhead (fleet / in process):      {t_fleet / t_local:8.2f} x")
        scores = _rel([s.score for s in fleet.diagnosis.suspects], [s.score for s in local.diagnosis.suspects])
        same_order = [s.effect for s in fleet.diagnosis.suspects] == [s.effect for s in local.diagnosis.suspects]
        print(
            f"  agreement: missing effect {fleet.missing_effect} (in process {local.missing_effect}), suspects in the "
            f"same order: {same_order}, scores within {scores:.1e}, ladder errors within "
            f"{_rel(fleet.ladder.errors, local.ladder.errors):.1e} (relative)"
        )
        named = list(fleet.logs_with_effect)
        print(f"  logs named: {len(named)}, exactly those with the effect: {named == with_effect}")


if __name__ == "__main__":
    main()
