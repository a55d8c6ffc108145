"""The whole analysis against the sweep it starts from, as the data grow: time ratio and memory.

The plant (issue 28): a second-order plant whose input is scaled by a sagging battery voltage
(``y = G(q) [u * vbat / 4.2] + noise``, vbat drains from 4.2 V to about 3.5 V over each record),
with one decoy signal (a random walk) logged next to vbat. Estimation and validation are separate
records of equal size (two seeds). For N = 40k, 400k and 4M samples in total (estimation +
validation; ``--quick``: 20k, 200k, 2M) it prints:

- the time of ``arxid.analyse(est, val)`` with defaults (one call: sweep, grid growth, diagnosis,
  ladder, comparison, where it fails, frequency checks and bands);
- the time of the default sweep alone on the same data, ``arxid.sweep(est, validation=val)``
  (median of 3);
- their ratio, and the growth of each from one N to the next (target, issue 42: analyse grows at
  most 11x for 10x the data, and at the largest N takes at most 12x the sweep);
- the peak memory ``analyse`` adds above the data: each N runs in its own subprocess, which builds
  the data, resets the kernel's peak-RSS counter (``/proc/self/clear_refs``, Linux) and reads the
  peak (``VmHWM`` of ``/proc/self/status``) after ``analyse`` minus the resident size before it
  (target at 4M: at most 0.75 GiB). Without ``clear_refs`` it falls back to ``ru_maxrss`` against
  the resident size after building the data, which overstates nothing but may understate by the
  data-building peak; the output says which was used;
- the missing effect found (it should be the battery, ``u1*vbat``).

``--plant two-inputs`` runs a plant of two inputs whose output term (``y(t-1)^3``) is the missing
effect; ``--plant gaps`` the battery plant with 200 NaN gaps per record.

``--blas-threads K`` runs each subprocess with K BLAS threads (``OPENBLAS_NUM_THREADS``,
``OMP_NUM_THREADS``, ``MKL_NUM_THREADS``): on a machine whose cores are busy with other work, a
threaded BLAS spends milliseconds waking its threads for each small product, which can swamp the
analysis' many small matrix operations; the sweep's own threads are not affected.

With ``--report`` each subprocess also renders the HTML report of the analysis
(``arxid.report.render_html``) and prints its time and size (the size has a cap independent of N).

With ``--profile`` each subprocess also prints the top entries of a cProfile of ``analyse``
(cumulative time), which slows it down.

Run with ``make bench`` (or ``python benches/analyse_scale.py [--quick] [--profile]``).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

GIB = 2**30


def make_record(n: int, seed: int):
    """One flight of ``n`` samples: battery-scaled second-order plant, vbat and a decoy logged."""
    from scipy.signal import lfilter

    import arxid

    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(n)) * 0.5 + 0.5 * rng.standard_normal(n)
    sag = np.linspace(0.0, 1.0, n)
    vbat = 4.2 - 0.5 * sag - 0.2 * sag**4 + 0.01 * rng.standard_normal(n)
    decoy = 20.0 + 0.05 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n / 4000)
    a = [1.0, -1.5, 0.7]
    y = lfilter([0.0, 0.5, 0.25], a, u * vbat / 4.2) + lfilter([1.0], a, 0.05 * rng.standard_normal(n))
    return arxid.IOData(y, u, 0.001, extra={"vbat": vbat, "decoy": decoy})


def make_two_inputs(n: int, seed: int):
    """Two inputs and an output term: y(t) = 1.5 y(t-1) - 0.7 y(t-2) + 0.5 u1(t-1) + 0.3 u2(t-2)
    - 0.004 y(t-1)^3, with the battery's sag and the decoy logged as in :func:`make_record`."""
    import arxid

    rng = np.random.default_rng(seed)
    u1 = np.sign(rng.standard_normal(n)) * 0.5 + 0.5 * rng.standard_normal(n)
    u2 = np.repeat(rng.uniform(-1.0, 1.0, n // 20 + 1), 20)[:n]
    sag = np.linspace(0.0, 1.0, n)
    vbat = 4.2 - 0.5 * sag - 0.2 * sag**4 + 0.01 * rng.standard_normal(n)
    decoy = 20.0 + 0.05 * np.cumsum(rng.standard_normal(n)) / np.sqrt(n / 4000)
    e = 0.05 * rng.standard_normal(n)
    y = np.zeros(n)
    for t in range(2, n):  # the output term makes the plant nonlinear: no filter does it
        y[t] = 1.5 * y[t - 1] - 0.7 * y[t - 2] + 0.5 * u1[t - 1] + 0.3 * u2[t - 2] - 0.004 * y[t - 1] ** 3 + e[t]
    return arxid.IOData(y, np.column_stack([u1, u2]), 0.001, extra={"vbat": vbat, "decoy": decoy})


def make_gaps(n: int, seed: int):
    """:func:`make_record` with the logger's dropouts: 200 gaps of 1 to 50 samples (NaN in every signal)."""
    import arxid

    d = make_record(n, seed)
    rng = np.random.default_rng(seed + 100)
    y, u, extra = d.y.copy(), d.u.copy(), {k: v.copy() for k, v in d.extra.items()}
    for start in rng.integers(0, n - 50, 200):
        gap = slice(start, start + int(rng.integers(1, 51)))
        for x in (y, u, *extra.values()):
            x[gap] = np.nan
    return arxid.IOData(y, u, d.ts, extra=extra)


PLANTS = {"battery": make_record, "two-inputs": make_two_inputs, "gaps": make_gaps}


def _status_kib(field: str) -> int | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    try:
        with open("/proc/self/clear_refs", "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def child(n_total: int, profile: bool, report: bool = False, plant: str = "battery") -> None:
    """Run in a subprocess: build the data, time analyse (memory measured) and the sweep."""
    import gc
    import resource

    import arxid

    est = PLANTS[plant](n_total // 2, 1)
    val = PLANTS[plant](n_total // 2, 2)
    gc.collect()
    rss0 = _status_kib("VmRSS")
    how = "VmHWM after clear_refs" if (_reset_peak() and rss0 is not None) else "ru_maxrss"
    base = rss0 if how != "ru_maxrss" else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    t = time.perf_counter()
    a = arxid.analyse(est, val)
    t_analyse = time.perf_counter() - t
    peak = _status_kib("VmHWM") if how != "ru_maxrss" else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    sweeps = []
    for _ in range(3):
        t = time.perf_counter()
        arxid.sweep(est, validation=val)
        sweeps.append(time.perf_counter() - t)
    out = {
        "n": n_total,
        "analyse": t_analyse,
        "sweep": float(np.median(sweeps)),
        "added_gib": (peak - base) * 1024 / GIB,
        "data_gib": sum(d.y.nbytes + d.u.nbytes + sum(x.nbytes for x in d.extra.values()) for d in (est, val)) / GIB,
        "how": how,
        "missing": a.missing_effect,
        "structure": a.model.structure_name(),
        "stages": a.timings,
    }
    if report:
        from arxid.analysis.report import render_html

        t = time.perf_counter()
        page = render_html(a)
        out["report_s"], out["report_bytes"] = time.perf_counter() - t, len(page.encode())
    if profile:
        import cProfile
        import io
        import pstats

        pr = cProfile.Profile()
        pr.enable()
        arxid.analyse(est, val)
        pr.disable()
        s = io.StringIO()
        pstats.Stats(pr, stream=s).sort_stats("cumulative").print_stats(25)
        s.write("\n")
        pstats.Stats(pr, stream=s).sort_stats("tottime").print_stats(15)
        out["profile"] = s.getvalue()
    print("RESULT " + json.dumps(out))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 20k, 200k, 2M")
    ap.add_argument("--profile", action="store_true", help="also print a cProfile of analyse per N")
    ap.add_argument("--sizes", type=str, default="", help="comma-separated total sample counts")
    ap.add_argument("--report", action="store_true", help="also time the HTML report and give its size")
    ap.add_argument("--blas-threads", type=int, default=0, help="BLAS threads of each run (default: BLAS's own)")
    ap.add_argument("--plant", choices=sorted(PLANTS), default="battery", help="the plant (default: battery)")
    ap.add_argument("--child", type=int, default=0, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.profile, args.report, args.plant)
        return
    sizes = [20_000, 200_000, 2_000_000] if args.quick else [40_000, 400_000, 4_000_000]
    if args.sizes:
        sizes = [int(float(s)) for s in args.sizes.split(",")]
    env = dict(os.environ)
    if args.blas_threads > 0:
        for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
            env[var] = str(args.blas_threads)
    blas = f"{args.blas_threads} BLAS thread(s)" if args.blas_threads > 0 else "BLAS threads as set"
    print(
        f"arxid analyse at scale: the {args.plant} plant, estimation = validation size, "
        f"defaults, {os.cpu_count()} cores, {blas}; each N in its own process"
    )
    rows = []
    for n in sizes:
        cmd = [sys.executable, __file__, "--child", str(n), "--plant", args.plant]
        cmd += ["--profile"] if args.profile else []
        cmd += ["--report"] if args.report else []
        done = subprocess.run(cmd, capture_output=True, text=True, check=False, env=env)
        line = next((s for s in done.stdout.splitlines() if s.startswith("RESULT ")), None)
        if line is None:
            print(f"  N={n:,}: the run failed\n{done.stderr[-3000:]}")
            continue
        r = json.loads(line[len("RESULT ") :])
        rows.append(r)
        print(
            f"  done N={n:,}: analyse {r['analyse']:.2f} s, sweep {r['sweep']:.3f} s, "
            f"memory added {r['added_gib']:.3f} GiB",
            flush=True,
        )
        if args.profile:
            print(f"\n--- profile of analyse at N={n:,} ---\n{r['profile']}")
    print()
    print(f"  {'samples':>10} {'analyse':>9} {'sweep':>8} {'ratio':>7} {'mem added':>10} {'data':>7}  missing effect")
    for r in rows:
        print(
            f"  {r['n']:>10,} {r['analyse']:8.2f}s {r['sweep']:7.3f}s {r['analyse'] / r['sweep']:6.0f}x "
            f"{r['added_gib']:8.3f}GiB {r['data_gib']:6.3f}G  {r['missing']} ({r['structure']})"
        )
    for r in rows:
        if "report_bytes" in r:
            print(f"  HTML report at {r['n']:,}: {r['report_s']:.1f} s to render, {r['report_bytes'] / 1e6:.2f} MB")
    for r in rows:
        stages = ", ".join(f"{k} {v:.2f} s" for k, v in r["stages"].items())
        print(f"  stages at {r['n']:,}: {stages}")
    for prev, r in zip(rows, rows[1:]):
        f = r["n"] / prev["n"]
        print(
            f"  {prev['n']:,} -> {r['n']:,} ({f:.0f}x data): analyse {r['analyse'] / prev['analyse']:.1f}x "
            f"(target <= {1.1 * f:.1f}x), sweep {r['sweep'] / prev['sweep']:.1f}x"
        )
    if rows:
        last = rows[-1]
        print(
            f"  at {last['n']:,}: analyse / sweep {last['analyse'] / last['sweep']:.1f}x (target <= 12x), "
            f"memory added {last['added_gib']:.2f} GiB (target <= 0.75 GiB; measured as {last['how']})"
        )


if __name__ == "__main__":
    main()
