"""Bounded memory: prediction-error fits (OE, ARMAX, BJ) of data with thousands of NaN gaps or
thousands of short experiments, with ``initial="zero"`` and ``"estimate"``, run in a subprocess
under an address-space limit (``RLIMIT_AS``) and need no more memory than on data without gaps."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

# 100,000 samples of a known OE/ARMAX/BJ system; its copies with ~4,000 NaN gaps (runs of 11-39
# samples; every seventh gap also in the input) and split into ~3,000 experiments of 15-59
# samples. After the data are built the process may map only 512 MiB more: the core's thread pool
# (the matrix-product kernel keeps a 64 MiB buffer per thread) and the fits must fit in that.
_UNDER_LIMIT = textwrap.dedent(
    """
    import json, resource, sys
    import numpy as np
    from scipy.signal import lfilter
    import arxid
    rng = np.random.default_rng(1)
    n = 100_000
    u = rng.standard_normal(n)
    y = lfilter([0, 0.5, 0.25], [1, -1.2, 0.5], u) + lfilter([1, 0.3], [1, -0.6], 0.05 * rng.standard_normal(n))
    gaps = np.cumsum(rng.integers(12, 40, n // 12))
    gaps = gaps[gaps < n]
    y_gaps, u_gaps = y.copy(), u.copy()
    y_gaps[gaps] = np.nan
    u_gaps[gaps[::7] + 3] = np.nan
    starts = np.r_[0, np.cumsum(rng.integers(15, 60, n // 15))]
    starts = tuple(int(s) for s in starts[starts < n - 20])
    cases = {
        "whole": arxid.IOData(y, u, ts=0.01),
        "gaps": arxid.IOData(y_gaps, u_gaps, ts=0.01),
        "short experiments": arxid.IOData(y, u, ts=0.01, experiment_starts=starts),
    }
    with open("/proc/self/status") as fh:
        vm = next(int(line.split()[1]) * 1024 for line in fh if line.startswith("VmSize:"))
    limit = vm + 512 * 2**20
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    out = {"gaps": len(gaps), "experiments": len(starts), "fits": []}
    for name, d in cases.items():
        for initial in ("zero", "estimate"):
            for kind, fit in (
                ("oe", lambda: arxid.oe(d, 2, 2, 1, initial=initial, n_threads=2)),
                ("armax", lambda: arxid.armax(d, 2, 2, 1, 1, initial=initial, n_threads=2)),
                ("bj", lambda: arxid.bj(d, 2, 1, 1, 2, 1, initial=initial, n_threads=2)),
            ):
                before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
                m = fit()
                m.predict(d, None, initial=initial)
                m.predict(d, 5, initial=initial)
                grew = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before
                out["fits"].append([name, initial, kind, m.parameters_.tolist(), grew])
    print(json.dumps(out))
    """
)


@pytest.mark.skipif(sys.platform != "linux", reason="RLIMIT_AS and /proc are Linux")
def test_pem_with_thousands_of_gaps_and_short_experiments_stays_within_a_memory_limit():
    proc = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", _UNDER_LIMIT],
        capture_output=True,
        text=True,
        timeout=600,
        env={"OPENBLAS_NUM_THREADS": "1", "PATH": "/usr/bin:/bin", **_pythonpath()},
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["gaps"] > 3500 and out["experiments"] > 2500
    truth = {"oe": [0.5, 0.25, -1.2, 0.5], "armax": [-1.2, 0.5, 0.5, 0.25], "bj": [0.5, 0.25]}
    for name, initial, kind, theta, grew_kib in out["fits"]:
        # the system is found from every kind of data (the B and F / A polynomials; BJ's noise model varies)
        got = theta[: len(truth[kind])] if kind != "bj" else theta[:2]
        assert got == pytest.approx(truth[kind], abs=0.02), (name, initial, kind, theta)
        if kind == "bj":
            assert theta[-2:] == pytest.approx([-1.2, 0.5], abs=0.02), (name, initial, kind, theta)
        # the peak resident memory grows by at most 64 MiB over the process' peak before the fit
        assert grew_kib < 64 * 1024, (name, initial, kind, grew_kib)


def _pythonpath() -> dict:
    import os

    return {"PYTHONPATH": os.environ["PYTHONPATH"]} if "PYTHONPATH" in os.environ else {}
