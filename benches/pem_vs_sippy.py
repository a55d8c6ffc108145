"""OE and ARMAX fits: arxid against SIPPY (when installed) and plain scipy ``least_squares``.

Same data, same structure, one run; prints time ratios and final losses (mean squared one-step
prediction error on the samples arxid scores). SIPPY is not a dependency: install it in the
benchmark's own environment (``pip install sippy_unipi casadi``); without it only the scipy
reference runs and the table says so.

    .venv/bin/python benches/pem_vs_sippy.py [--sizes 10000 200000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy import signal
from scipy.optimize import least_squares

import arxid

A, B, C = [1, -1.5, 0.7], [0, 0, 0, 0.5, 0.3], [1, -0.8, 0.2]


def make(kind: str, n: int, seed: int = 0) -> arxid.IOData:
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(n))
    x = signal.lfilter(B, A, u)
    if kind == "oe":
        y = x + 0.2 * np.std(x) * rng.standard_normal(n)
    else:
        y = x + signal.lfilter(C, A, 0.5 * rng.standard_normal(n))
    return arxid.IOData(y, u, ts=1.0)


def errors(th: np.ndarray, kind: str, y: np.ndarray, u: np.ndarray, lag: int) -> np.ndarray:
    if kind == "oe":
        e = y - signal.lfilter(np.r_[0, 0, 0, th[:2]], np.r_[1, th[2:]], u)
    else:
        a, b, c = np.r_[1, th[:2]], np.r_[0, 0, 0, th[2:4]], np.r_[1, th[4:]]
        e = signal.lfilter(a, c, y) - signal.lfilter(b, c, u)
    return e[lag:]


def timed(f):
    t = time.perf_counter()
    out = f()
    return out, time.perf_counter() - t


def fit_arxid(kind: str, d: arxid.IOData):
    return arxid.oe(d, 2, 2, 3) if kind == "oe" else arxid.armax(d, 2, 2, 2, 3)


def fit_scipy(kind: str, d: arxid.IOData, lag: int) -> np.ndarray:
    start = np.array([0.1, 0.1, -1.0, 0.5]) if kind == "oe" else np.array([-1.0, 0.5, 0.1, 0.1, 0.0, 0.0])
    return least_squares(errors, start, args=(kind, d.y, d.u[:, 0], lag)).x


def fit_sippy(kind: str, d: arxid.IOData) -> np.ndarray | None:
    try:
        from sippy_unipi import system_identification  # type: ignore[import-not-found]
    except ImportError:
        return None
    y, u = d.y.reshape(1, -1), d.u[:, 0].reshape(1, -1)
    if kind == "oe":
        m = system_identification(y, u, "OE", OE_orders=[2, 2, 3])
        return np.r_[np.asarray(m.NUMERATOR[0][0])[3:5], np.asarray(m.DENOMINATOR[0][0])[1:3]]
    m = system_identification(y, u, "ARMAX", ARMAX_orders=[2, 2, 2, 3])
    return np.r_[
        np.asarray(m.DENOMINATOR[0][0])[1:3], np.asarray(m.NUMERATOR[0][0])[3:5], np.asarray(m.NUMERATOR_H[0][0])[1:3]
    ]


def bench_row(kind: str, n: int) -> str:
    """One line of the table: arxid, scipy and (if installed) SIPPY on the same data."""
    d = make(kind, n)
    model, t_a = timed(lambda: fit_arxid(kind, d))
    lag = model.first_lag_

    def loss(th: np.ndarray) -> float:
        return float(np.mean(errors(th, kind, d.y, d.u[:, 0], lag) ** 2))

    th_s, t_s = timed(lambda: fit_scipy(kind, d, lag))
    th_p, t_p = timed(lambda: fit_sippy(kind, d))
    sippy = "not installed" if th_p is None else f"{t_p / t_a:.0f}x, loss {loss(th_p):.6g}"
    return (
        f"{kind:<8}{n:>8}{t_a:>10.3f}{t_s:>10.3f}{t_s / t_a:>7.0f}x{loss(model.parameters_):>13.6g}"
        f"{loss(th_s):>13.6g}{sippy:>22}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 200_000])
    args = ap.parse_args()
    head = f"{'fit':<8}{'N':>8}{'arxid s':>10}{'scipy s':>10}{'ratio':>8}{'arxid loss':>13}{'scipy loss':>13}"
    print(head + f"{'SIPPY':>22}")
    for kind in ("oe", "armax"):
        for n in args.sizes:
            print(bench_row(kind, n))


if __name__ == "__main__":
    main()
