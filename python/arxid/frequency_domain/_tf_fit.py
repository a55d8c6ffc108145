"""A continuous transfer function fitted to a measured frequency response: :func:`tf_from_frequency`
(MATLAB's ``tfest`` on an ``idfrd``).

1. Sanathanan & Koerner (IEEE TAC 8, 1963): the weighted error w_k |N(s_k)/D(s_k) − Ĥ_k|² is
   made linear by multiplying with D(s_k), and the bias that brings is undone by dividing by the
   previous iteration's D: minimise Σ w_k |D(s_k) Ĥ_k − N(s_k)|² / |D_prev(s_k)|² (real linear
   least squares), until the denominator settles. Frequencies are scaled by their largest value
   so that the powers of s stay of order one.
2. Levenberg–Marquardt-type refinement (``scipy.optimize.least_squares``, trust region) of the
   weighted complex error itself, with the model sampled by the data's zero-order hold (the exact
   discrete equivalent, :func:`arxid.models.continuous.c2d`), so the hold's gain and phase near the
   Nyquist frequency do not bias the poles; and with the dead time when it is estimated.
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._base.limits import check_order
from ..exceptions import ArxidError, ArxidWarning, DataError, OrderError
from ..models.continuous import c2d
from ..models.continuous_tf import ContinuousTransferFunction
from ._response import FrequencyResponse

__all__ = ["tf_from_frequency", "WEIGHTINGS"]

WEIGHTINGS = ("variance", "coherence", "none")

#: Sanathanan–Koerner iterations at most, and the relative change of the denominator that ends them.
_SK_ITERATIONS = 50
_SK_TOLERANCE = 1e-10


def _weights(fr: FrequencyResponse, i: int, weighting: str) -> np.ndarray:
    h = np.abs(fr.response[:, i])
    if weighting == "variance":
        # Exact data (coherence 1) have no variance: a floor of 1e-12 |H|² fits the relative error.
        return 1.0 / np.maximum(fr.variance[:, i], 1e-12 * np.maximum(h, 1e-300) ** 2)
    if weighting == "coherence":
        return fr.coherence.copy()
    return np.ones_like(h)


def _sanathanan_koerner(s: np.ndarray, h: np.ndarray, w: np.ndarray, n: int, m: int) -> tuple[np.ndarray, ...]:
    """Monic denominator and numerator (descending powers of the scaled s) by SK iterations."""
    den = np.concatenate([[1.0], np.zeros(n)])
    cols = np.column_stack([s ** (n - k) * h for k in range(1, n + 1)] + [-(s ** (m - k)) for k in range(m + 1)])
    target = -(s**n) * h
    num = np.zeros(m + 1)
    it = 0
    while it < _SK_ITERATIONS:
        it += 1
        scale = np.sqrt(w) / np.abs(np.polyval(den, s))
        a = cols * scale[:, None]
        b = target * scale
        x, *_ = np.linalg.lstsq(np.vstack([a.real, a.imag]), np.concatenate([b.real, b.imag]), rcond=None)
        new = np.concatenate([[1.0], x[:n]])
        num = x[n:]
        change = np.linalg.norm(new - den) / max(np.linalg.norm(new), 1e-300)
        den = new
        if change < _SK_TOLERANCE:
            break
    return _stable(den), num, np.array(it)


def _stable(den: np.ndarray) -> np.ndarray:
    """The denominator with right-half-plane poles reflected into the left half-plane."""
    p = np.roots(den)
    if np.all(p.real < 0):
        return den
    return np.real(np.poly(np.where(p.real > 0, -p.conj(), p)))


def _unscaled(theta: np.ndarray, n: int, m: int, w0: float) -> tuple[np.ndarray, np.ndarray]:
    """(den, num) in powers of s from the coefficients in powers of s / w0."""
    den = np.concatenate([[1.0], theta[:n] * w0 ** np.arange(1, n + 1)])
    num = theta[n : n + m + 1] * w0 ** (n - m + np.arange(m + 1))
    return den, num


def _model_response(num: np.ndarray, den: np.ndarray, tau: float, omega: np.ndarray, ts: float, zoh: bool):
    if zoh:
        a, b = c2d(num, den, ts, tau)
        zinv = np.exp(-1j * omega * ts)
        return np.polyval(b[::-1], zinv) / np.polyval(a[::-1], zinv)
    s = 1j * omega
    return np.polyval(num, s) / np.polyval(den, s) * np.exp(-s * tau)


def _residual_function(omega, h, w, ts, zoh, n, m, w0, tau):
    """Weighted complex error stacked as [real; imag], of θ = [scaled a, scaled b (, dead time)]."""
    sw = np.sqrt(w)

    def fun(theta: np.ndarray) -> np.ndarray:
        den, num = _unscaled(theta, n, m, w0)
        delay = theta[n + m + 1] if tau is None else tau
        with np.errstate(all="ignore"):
            e = sw * (_model_response(num, den, float(delay), omega, ts, zoh) - h)
        out = np.concatenate([e.real, e.imag])
        return np.where(np.isfinite(out), out, 1e150)

    return fun


def _jacobian(fun: Callable[[np.ndarray], np.ndarray], x: np.ndarray) -> np.ndarray:
    f0 = fun(x)
    jac = np.empty((f0.size, x.size))
    for k in range(x.size):
        step = 1e-7 * max(abs(x[k]), 1e-3)
        xk = x.copy()
        xk[k] += step
        jac[:, k] = (fun(xk) - f0) / step
    return jac


def _covariance(fun: Callable, theta: np.ndarray, n_params: int, jac: np.ndarray | None) -> np.ndarray:
    """s² (JᵀJ)⁻¹ of the first ``n_params`` parameters, s² = RSS / (rows − parameters)."""
    j = _jacobian(fun, theta) if jac is None else jac
    r = fun(theta)
    dof = max(r.size - theta.size, 1)
    cov = float(r @ r) / dof * np.linalg.pinv(j.T @ j)
    return cov[:n_params, :n_params]


def _delay_argument(delay: Any) -> float | None:
    if delay is None:
        return 0.0
    if isinstance(delay, str):
        if delay != "estimate":
            raise ArxidError(f"delay must be seconds >= 0 or 'estimate', got {delay!r}")
        return None
    if isinstance(delay, bool) or not isinstance(delay, numbers.Real) or not math.isfinite(delay) or delay < 0:
        raise ArxidError(f"a dead time is a number of seconds >= 0, got {delay!r}")
    return float(delay)


def _input_index(fr: FrequencyResponse, input: int | str) -> int:
    if isinstance(input, str):
        if input not in fr.input_names:
            raise DataError(f"no input named {input!r}; the frequency response has {list(fr.input_names)}")
        return fr.input_names.index(input)
    if isinstance(input, bool) or not isinstance(input, numbers.Integral) or not 0 <= input < fr.n_inputs:
        raise DataError(f"input must be a name or an index below {fr.n_inputs}, got {input!r}")
    return int(input)


def _selected(fr: FrequencyResponse, i: int, frequency_range: Sequence[float] | None) -> np.ndarray:
    f = fr.frequency
    keep = np.isfinite(fr.response[:, i]) & (np.abs(fr.response[:, i]) > 0)
    if frequency_range is not None:
        lo, hi = (float(v) for v in frequency_range)
        keep &= (f >= lo) & (f <= hi)
    return keep


def _start(omega, h, w, n, m, ts, zoh, w0, tau, max_delay):
    """SK start at the given dead time, or the best of whole samples 0 .. max_delay (with a hold:
    on the frequencies below fs/8, where the hold is nearly a half-sample lag)."""
    taus = [tau] if tau is not None else [k * ts for k in range(int(max_delay / ts + 1e-9) + 1)]
    low = omega * ts < np.pi / 4  # below fs/8 a half-sample lag is the hold's effect, to within 3 %
    if zoh and low.sum() >= n + m + 2:
        omega, h, w = omega[low], h[low], w[low]
    best: tuple[float, np.ndarray, float, int] | None = None
    for t in taus:
        # the hold's half-sample lag taken off the data for the linear start (the refinement is exact)
        hc = h * np.exp(1j * omega * (t + (0.5 * ts if zoh else 0.0)))
        den, num, it = _sanathanan_koerner(1j * omega / w0, hc, w, n, m)
        theta = np.concatenate([den[1:], num])
        r = _residual_function(omega, h, w, ts, zoh, n, m, w0, t)(theta)
        cost = float(r @ r)
        if best is None or cost < best[0]:
            best = (cost, theta, t, int(it))
    assert best is not None
    return best[1], best[2], best[3]


def tf_from_frequency(
    frequency_response: FrequencyResponse,
    n_poles: int,
    n_zeros: int | None = None,
    delay: float | str | None = None,
    *,
    input: int | str = 0,
    weighting: str = "variance",
    frequency_range: Sequence[float] | None = None,
    intersample: str = "zoh",
    refine: bool = True,
    max_delay: float | None = None,
) -> ContinuousTransferFunction:
    """Continuous transfer function fitted to a frequency response (MATLAB ``tfest`` on an ``idfrd``).

    Parameters
    ----------
    frequency_response : FrequencyResponse
        From :func:`arxid.frf` (open or closed loop).
    n_poles : int
        Poles (>= 1).
    n_zeros : int, optional
        Zeros, fewer than the poles (default ``n_poles - 1``).
    delay : float or "estimate", optional
        Dead time in seconds (default 0); ``"estimate"`` tries whole samples up to ``max_delay`` and
        refines the best as a parameter.
    input : int or str
        Which input's response to fit.
    weighting : {"variance", "coherence", "none"}
        Weight of each frequency's squared complex error: the inverse of the estimate's variance
        (default; the maximum-likelihood weight, which fits relative errors where the coherence is
        high and ignores frequencies where it is low), the coherence γ², or none.
    frequency_range : (float, float), optional
        Only frequencies in [low, high] Hz.
    intersample : {"zoh", "continuous"}
        ``"zoh"`` (default, the data's inputs held between samples): the refinement compares the
        model's exact zero-order-hold discrete response with the data; ``"continuous"``: N(jω)/D(jω)
        itself.
    refine : bool
        Refine the Sanathanan–Koerner fit by minimising the weighted error (default True).
    max_delay : float, optional
        With ``delay="estimate"``: longest dead time tried, seconds (default 20 samples).

    Returns
    -------
    ContinuousTransferFunction
        As :func:`arxid.tfest` returns: ``den_``, ``num_``, ``poles()`` (rad/s),
        ``parameter_dict()`` (standard deviations from the weighted fit's Jacobian, scaled by its
        residual variance); it predicts, simulates and compares on the frequency response's data.

    Raises
    ------
    DataError
        When the argument is not a FrequencyResponse, or fewer frequencies than parameters remain.
    OrderError
        For orders a continuous model cannot have.

    Notes
    -----
    .. math::

        \\min_{N, D} \\sum_k w_k \\left| \\frac{N(j\\omega_k)}{D(j\\omega_k)} e^{-j\\omega_k\\tau}
        - \\hat H_k \\right|^2

    The module docstring describes the two stages.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> ts = 0.01
    >>> u = rng.standard_normal(40000)
    >>> a, b = arxid.models.continuous.c2d([100.0], [1.0, 4.0, 100.0], ts)  # 10 rad/s, damping 0.2
    >>> y = lfilter(b, a, u) + 0.01 * rng.standard_normal(40000)
    >>> fr = arxid.frf(arxid.IOData(y, u, ts=ts), segment_length=1024)
    >>> m = arxid.tf_from_frequency(fr, 2, 0)
    >>> np.round(np.sort_complex(m.poles()), 1)
    array([-2.-9.8j, -2.+9.8j])
    """
    fr = frequency_response
    if not isinstance(fr, FrequencyResponse):
        raise DataError(
            f"tf_from_frequency needs an arxid.FrequencyResponse (from arxid.frf), got {type(fr).__name__}; "
            "for time-domain data use arxid.tfest"
        )
    n = check_order("n_poles", n_poles)
    m = check_order("n_zeros", n - 1 if n_zeros is None else n_zeros)
    if n < 1 or m >= n:
        raise OrderError(f"need n_poles >= 1 and n_zeros < n_poles (a strictly proper model), got {n} and {m}")
    if weighting not in WEIGHTINGS:
        raise ArxidError(f"weighting must be one of {WEIGHTINGS}, got {weighting!r}")
    if intersample not in ("zoh", "continuous"):
        raise ArxidError(f"intersample must be 'zoh' or 'continuous', got {intersample!r}")
    tau = _delay_argument(delay)
    i = _input_index(fr, input)
    keep = _selected(fr, i, frequency_range)
    n_params = n + m + 1 + (tau is None)
    if 2 * keep.sum() <= n_params:
        raise DataError(
            f"{int(keep.sum())} frequencies are too few for {n_params} parameters; widen frequency_range or "
            "use a longer frequency response (more frequencies)"
        )
    omega, h = 2 * np.pi * fr.frequency[keep], fr.response[keep, i]
    w = _weights(fr, i, weighting)[keep]
    w = w / np.max(w)
    w0, zoh, ts = float(omega.max()), intersample == "zoh", fr.ts
    theta, tau0, iterations = _start(omega, h, w, n, m, ts, zoh, w0, tau, 20 * ts if max_delay is None else max_delay)
    x0 = theta if tau is not None else np.append(theta, tau0)
    fun = _residual_function(omega, h, w, ts, zoh, n, m, w0, tau)
    converged, jac = True, None
    x = x0
    if refine:
        x, converged, jac, extra = _refined(fun, x0, tau is None)
        iterations += extra
        if np.any(np.roots(_unscaled(x, n, m, w0)[0]).real >= 0):
            warnings.warn(
                "tf_from_frequency: the refinement ended at unstable poles; the Sanathanan–Koerner fit is returned. "
                f"{n} poles and {m} zeros may not describe this response: try other orders or a frequency_range",
                ArxidWarning,
                stacklevel=2,
            )
            x, converged, jac = x0, False, None
    delay_s = float(x[-1]) if tau is None else float(tau)
    den, num = _unscaled(x, n, m, w0)
    scale = np.concatenate([w0 ** np.arange(1, n + 1), w0 ** (n - m + np.arange(m + 1))])
    cov = _covariance(fun, x, n + m + 1, jac) * np.outer(scale, scale)
    return _build(fr, i, den, num, delay_s, cov, n, m, weighting, iterations, converged)


def _refined(fun: Callable, x0: np.ndarray, free_delay: bool) -> tuple[np.ndarray, bool, np.ndarray, int]:
    from scipy.optimize import least_squares

    lower = np.full(x0.size, -np.inf)
    if free_delay:
        lower[-1] = 0.0
    res = least_squares(fun, x0, bounds=(lower, np.inf), method="trf", x_scale="jac", xtol=1e-12, ftol=1e-12)
    c0, c1 = float(fun(x0) @ fun(x0)), float(res.fun @ res.fun)
    if not (c1 <= c0):
        return x0, False, None, int(res.nfev)  # type: ignore[return-value]
    if not res.success:
        warnings.warn(
            "tf_from_frequency: the refinement stopped before converging; check the orders or pass refine=False",
            ArxidWarning,
            stacklevel=3,
        )
    return res.x, bool(res.success), res.jac, int(res.nfev)


def _build(fr, i, den, num, delay_s, cov, n, m, weighting, iterations, converged) -> ContinuousTransferFunction:
    data = fr.data.with_signals(u=fr.data.u[:, [i]], input_names=[fr.input_names[i]], input_units=[fr.input_units[i]])
    names = [f"a{k}" for k in range(1, n + 1)] + [f"b{k}" for k in range(m + 1)]

    def unpack(theta: np.ndarray) -> tuple[list, list, list]:
        return [np.concatenate([[1.0], theta[:n]])], [theta[n:]], [delay_s]

    theta = np.concatenate([den[1:], num])
    return ContinuousTransferFunction.fitted(
        data,
        theta,
        cov,
        names,
        unpack,
        structure=f"tf({n},{m})",
        method=f"Sanathanan–Koerner on the frequency response ({weighting} weighting)",
        iterations=iterations,
        converged=converged,
    )
