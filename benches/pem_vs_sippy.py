"""OE and ARMAX fits: arxid against SIPPY (when installed) and plain scipy ``least_squares``.

Same data, same structure, one run; prints time ratios and final losses (mean squared one-step
prediction error on the samples arxid scores). SIPPY is not a dependency: install it in the
benchmark's own environment (``pip install sippy_unipi casadi``); without it only the scipy
reference runs and the table says so. A SIPPY fit runs in a child process and is stopped after
``--sippy-cap`` seconds (its CasADi problem grows with N).

    .venv/bin/python benches/pem_vs_sippy.py [--sizes 10000 200000] [--sippy-cap 600]

``--real DIR`` instead fits OE(2, 2, 1) to two measured data sets read from DIR (the shared data
folder; nothing is copied): the Silverbox circuit (samples 40 650-60 649 of SNLS80mV.csv, as the
real-data test) and the DaISy heating system, with arxid and SIPPY, and prints both losses (mean
squared output error on the samples arxid scores) and the time ratio.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

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
    # SIPPY's delay theta counts the samples before b1 multiplies u(t - theta - 1): MATLAB's nk - 1.
    theta = 2
    if kind == "oe":
        m = system_identification(y, u, "OE", OE_orders=[2, 2, theta])
        return np.r_[np.asarray(m.NUMERATOR[0][0])[theta : theta + 2], np.asarray(m.DENOMINATOR[0][0])[1:3]]
    # "OPT" is SIPPY's prediction-error fit through CasADi (its default "ILLS" is iterated least squares).
    m = system_identification(y, u, "ARMAX", ARMAX_orders=[2, 2, 2, theta], ARMAX_mod="OPT")
    return np.r_[
        np.asarray(m.DENOMINATOR[0][0])[1:3],
        np.asarray(m.NUMERATOR[0][0])[theta : theta + 2],
        np.asarray(m.NUMERATOR_H[0][0])[1:3],
    ]


def fit_sippy_capped(kind: str, d: arxid.IOData, cap: float) -> tuple[np.ndarray | None, float | None]:
    """SIPPY's fit in a child process stopped after ``cap`` seconds; the time is None when it was stopped."""
    return run_capped(fit_sippy, (kind, d), cap)


def run_capped(fit, args: tuple, cap: float):
    """``fit(*args)`` in a child process stopped after ``cap`` seconds; the time is None when it was stopped."""
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(1) as pool:
        t = time.perf_counter()
        job = pool.apply_async(fit, args)
        try:
            return job.get(timeout=cap), time.perf_counter() - t
        except multiprocessing.TimeoutError:
            pool.terminate()
            return np.zeros(0), None


def bench_row(kind: str, n: int, cap: float) -> str:
    """One line of the table: arxid, scipy and (if installed) SIPPY on the same data."""
    d = make(kind, n)
    model, t_a = timed(lambda: fit_arxid(kind, d))
    lag = model.first_lag_

    def loss(th: np.ndarray) -> float:
        return float(np.mean(errors(th, kind, d.y, d.u[:, 0], lag) ** 2))

    th_s, t_s = timed(lambda: fit_scipy(kind, d, lag))
    th_p, t_p = fit_sippy_capped(kind, d, cap)
    if th_p is None:
        sippy = "not installed"
    elif t_p is None:
        sippy = f"stopped after {cap:.0f} s (>{cap / t_a:.0f}x)"
    else:
        sippy = f"{t_p:.1f} s, {t_p / t_a:.0f}x, loss {loss(th_p):.6g}"
    return (
        f"{kind:<8}{n:>8}{t_a:>10.3f}{t_s:>10.3f}{t_s / t_a:>7.0f}x{loss(model.parameters_):>13.6g}"
        f"{loss(th_s):>13.6g}  {sippy}"
    )


def real_sets(folder: Path) -> list[tuple[str, arxid.IOData]]:
    """The two measured data sets, loaded as tests/test_pem.py loads them (means removed)."""
    raw = np.genfromtxt(folder / "silverbox" / "SNLS80mV.csv", delimiter=",", skip_header=1, usecols=(0, 1))
    u, y = raw[40650:60650, 0], raw[40650:60650, 1]
    heat = np.loadtxt(folder / "daisy-heating" / "heating_system.dat")
    return [
        ("Silverbox", arxid.IOData(y - y.mean(), u - u.mean(), 1 / 610.35)),
        ("heating", arxid.IOData(heat[:, 2] - heat[:, 2].mean(), heat[:, 1] - heat[:, 1].mean(), 2.0)),
    ]


def sippy_oe(d: arxid.IOData, nb: int, nf: int, nk: int) -> tuple[np.ndarray, np.ndarray] | None:
    """SIPPY's OE fit as (numerator, denominator) in powers of z^-1; None when SIPPY is not installed."""
    try:
        from sippy_unipi import system_identification  # type: ignore[import-not-found]
    except ImportError:
        return None
    # SIPPY's delay theta is MATLAB's nk - 1; its transfer function is in positive powers of z.
    m = system_identification(d.y.reshape(1, -1), d.u[:, 0].reshape(1, -1), "OE", OE_orders=[nb, nf, nk - 1])
    num, den = np.asarray(m.NUMERATOR[0][0], float), np.asarray(m.DENOMINATOR[0][0], float)
    return np.r_[np.zeros(len(den) - len(num)), num], den


def output_error_loss(d: arxid.IOData, num: np.ndarray, den: np.ndarray, lag: int) -> float:
    """Mean squared output error y - (num/den) u over the samples from ``lag`` on."""
    return float(np.mean((d.y - signal.lfilter(num, den, d.u[:, 0]))[lag:] ** 2))


def real_row(name: str, d: arxid.IOData, cap: float, orders: tuple[int, int, int] = (2, 2, 1)) -> str:
    """One line of the real-data table: OE(nb, nf, nk) by arxid and by SIPPY on the same samples."""
    nb, nf, nk = orders
    model, t_a = timed(lambda: arxid.oe(d, nb, nf, nk))
    th, lag = model.parameters_, model.first_lag_
    ours = output_error_loss(d, np.r_[np.zeros(nk), th[:nb]], np.r_[1, th[nb:]], lag)
    tf, t_p = run_capped(sippy_oe, (d, nb, nf, nk), cap)
    if tf is None:
        sippy = "not installed"
    elif t_p is None:
        sippy = f"stopped after {cap:.0f} s (>{cap / t_a:.0f}x)"
    else:
        sippy = f"{t_p:>8.2f} s {t_p / t_a:>6.0f}x  loss {output_error_loss(d, *tf, lag):.6g}"
    return f"{name:<10}{d.n_samples:>7}  OE{orders}  {t_a:>8.3f} s  loss {ours:.6g}   SIPPY {sippy}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[10_000, 200_000])
    ap.add_argument("--sippy-cap", type=float, default=600.0, help="seconds after which a SIPPY fit is stopped")
    ap.add_argument("--real", type=Path, help="shared data folder: fit the two measured data sets instead")
    args = ap.parse_args()
    if args.real is not None:
        for name, d in real_sets(args.real):
            print(real_row(name, d, args.sippy_cap), flush=True)
        return
    head = f"{'fit':<8}{'N':>8}{'arxid s':>10}{'scipy s':>10}{'ratio':>8}{'arxid loss':>13}{'scipy loss':>13}"
    print(head + "  SIPPY (time, ratio to arxid, loss)")
    for kind in ("oe", "armax"):
        for n in args.sizes:
            print(bench_row(kind, n, args.sippy_cap), flush=True)


if __name__ == "__main__":
    main()
