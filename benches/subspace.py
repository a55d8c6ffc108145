"""How fast ``arxid.ssest`` identifies a 3-input, 3-output, 6-state model from 100,000 samples, and
how well, against SIPPY (``sippy-unipi``: N4SID) and ``nfoursid`` in the same run.

The plant is a seeded random stable system (poles of magnitude 0.5–0.95), driven by random binary
inputs, with white output noise at 20 dB. Every tool gets the order (6) and past/future horizons of
10 samples, and every model is scored the same way: free-run simulation on 20,000 fresh samples,
its initial state estimated by least squares (arxid's ``fit_percent``), fit in percent per output.
Times are the median of ``--repeats`` runs for arxid, one run for each peer: wall clock, and the
CPU time of all the process's threads (other processes on a shared machine inflate the wall clock,
not the CPU time). SIPPY runs twice: with its BLAS on every core (its default), and held to one
BLAS thread (on a loaded machine the one thread can be the faster). nfoursid forms an N × N matrix
and cannot run 100,000 samples (75 GiB), so all three are compared again at 5,000 samples.

Target (issue 44): arxid at least 10x faster than either peer, with an equal or better fit (aimed
at 15x against SIPPY's default, 10x against SIPPY on one BLAS thread). The prediction-error
refinement (``refine=True``) is timed once beside them, with its fit and how much
it lowered the one-step prediction error on the estimation data (white output noise: little to gain;
it pays with coloured noise).

    pip install 'arxid[bench]'   # the peers
    python benches/subspace.py [--samples 100000] [--repeats 3]
"""

from __future__ import annotations

import argparse
import contextlib
import io
import statistics
import sys
import time
from pathlib import Path

import numpy as np

import arxid
from arxid.models.state_space import StateSpaceModel

sys.path.insert(0, str(Path(__file__).parent.parent / "tests"))
from subspace_systems import add_noise, as_data, binary_inputs, random_system  # noqa: E402

ORDER, HORIZON, N_VAL = 6, 10, 20_000


def timed(fn, repeats: int):
    """(median wall time, median CPU time of this process's threads, last result)."""
    walls, cpus, out = [], [], None
    for _ in range(repeats):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return statistics.median(walls), statistics.median(cpus), out


def scored(a, b, c, d, val) -> np.ndarray:
    model = StateSpaceModel(
        a=np.asarray(a, float),
        b=np.asarray(b, float),
        c=np.asarray(c, float),
        d=np.asarray(d, float),
        k=np.zeros((len(a), 3)),
        initial_states=np.zeros((1, len(a))),
        ts=1.0,
        input_names=("u1", "u2", "u3"),
        output_names=("y1", "y2", "y3"),
    )
    return model.fit_percent(val)


def run_sippy(y, u):
    from sippy_unipi import system_identification

    with contextlib.redirect_stdout(io.StringIO()):
        m = system_identification(
            y.T, u.T, "N4SID", SS_fixed_order=ORDER, SS_f=HORIZON, SS_p=HORIZON, SS_D_required=True
        )
    return m.A, m.B, m.C, m.D


def run_sippy_one_thread(y, u):
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return run_sippy(y, u)


def run_nfoursid(y, u):
    import pandas as pd
    from nfoursid.nfoursid import NFourSID

    frame = pd.DataFrame(np.hstack([u, y]), columns=["u1", "u2", "u3", "y1", "y2", "y3"])
    n4 = NFourSID(frame, output_columns=["y1", "y2", "y3"], input_columns=["u1", "u2", "u3"], num_block_rows=HORIZON)
    n4.subspace_identification()
    ss, _ = n4.system_identification(rank=ORDER)
    return ss.a, ss.b, ss.c, ss.d


def compare(n_samples: int, repeats: int, peers) -> None:
    rng = np.random.default_rng(44)
    true = random_system(rng, ORDER, 3, 3)
    u = binary_inputs(rng, n_samples + N_VAL, 3)
    clean = true.simulate(u)
    y = add_noise(rng, clean, 20)
    est_y, est_u = y[:n_samples], u[:n_samples]
    val = as_data(y[n_samples:], u[n_samples:])
    true_fit = np.array([arxid._base.metrics.fit_percent(y[n_samples:, i], clean[n_samples:, i]) for i in range(3)])
    print(f"{n_samples} samples, 3 inputs, 3 outputs, order {ORDER}, horizons {HORIZON}; 20 dB output noise")
    print(f"  true system's validation fit: {np.array2string(true_fit, precision=2)} %")
    data = as_data(est_y, est_u)
    wall, cpu, model = timed(lambda: arxid.ssest(data, order=ORDER, horizon=HORIZON), repeats)
    arxid_fit = model.fit_percent(val)
    print(
        f"  {'arxid.ssest N4SID':19s} {wall:8.3f} s (CPU {cpu:7.2f} s)  fit {np.array2string(arxid_fit, precision=2)} %"
    )
    wall_r, cpu_r, refined = timed(lambda: arxid.ssest(data, order=ORDER, horizon=HORIZON, refine=True), 1)
    print(
        f"  {'  + refine=True':19s} {wall_r:8.3f} s (CPU {cpu_r:7.2f} s)  "
        f"fit {np.array2string(refined.fit_percent(val), precision=2)} %  ({refined.refinement})"
    )
    for name, fn in peers:
        try:
            peer_wall, peer_cpu, matrices = timed(lambda fn=fn: fn(est_y, est_u), 1)
        except Exception as exc:  # a peer that fails is reported, not fatal
            print(f"  {name:19s} failed: {type(exc).__name__}: {str(exc)[:120]}")
            continue
        fit = scored(*matrices, val)
        print(
            f"  {name:19s} {peer_wall:8.3f} s (CPU {peer_cpu:7.2f} s)  fit {np.array2string(fit, precision=2)} %"
            f"  -> arxid {peer_wall / wall:.1f}x faster (CPU {peer_cpu / cpu:.1f}x), "
            f"fit {np.min(arxid_fit - fit):+.2f} points (worst output)"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=100_000)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    peers = (("SIPPY N4SID", run_sippy), ("  one BLAS thread", run_sippy_one_thread), ("nfoursid", run_nfoursid))
    compare(args.samples, args.repeats, peers)
    # nfoursid forms an N × N matrix (75 GiB at 100k samples): compare it where it fits.
    compare(5_000, args.repeats, peers)


if __name__ == "__main__":
    main()
