"""The simplified refined instrumental-variable iteration for continuous-time models (SRIVC).

Young & Jakeman (1980), Int. J. Control 31(4); Garnier & Wang (eds.), *Identification of
Continuous-time Models from Sampled Data* (Springer 2008), ch. 4. For the model

.. math::

    y(t) = \\sum_i \\frac{B_i(p)}{A(p)} u_i(t - \\tau_i) + e(t), \\qquad
    A(p) = p^n + a_1 p^{n-1} + \\dots + a_n

each iteration

1. filters y, every input and the current model's noise-free output x̂ by ``1/Â(s)`` (the
   *state-variable filter*, its states are the filtered signal and its first n − 1 derivatives),
   discretised exactly: a zero-order hold with the input's fractional delay for the inputs (the
   data's inter-sample behaviour), a first-order hold (linear interpolation) for the output and x̂,
   which are smooth; the filtering runs in the Rust core (``srivc_filter``);
2. solves the instrumental-variable equations with instruments built from x̂;
3. stops when the parameters change by less than ``tolerance`` (relative), or after
   ``max_iterations``.

Time is rescaled internally so that the poles are of order one (poles at 500 times the sampling
rate and at a tenth of it give the same conditioning), and an iterate's unstable poles are mirrored
into the left half-plane for its filter and instruments. The covariance is Young's
``σ² (Σ ζ ζᵀ)⁻¹`` with ζ the noise-free regressors and σ² the output-error variance.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._base import _core
from ..exceptions import ConvergenceError, IdentifiabilityError
from .continuous import controllable_form, split_delay, zoh_matrices

__all__ = ["SrivcFit", "srivc", "output_error", "pole_scale", "input_states", "segment_rows"]


@dataclass(frozen=True)
class SrivcFit:
    """What one SRIVC run found (descending powers of s, A monic).

    Attributes
    ----------
    dens : list of ndarray
        One denominator per input (all the same object for a common denominator).
    nums : list of ndarray
        One numerator per input.
    covariance : ndarray
        Of ``theta``: the free denominator coefficients (one block per distinct denominator), then
        every input's numerator.
    theta : ndarray
    iterations : int
    converged : bool
    error : ndarray of shape (n_samples,)
        Output error ``y − x̂`` (NaN outside the segments).
    reflected : bool
        The iterations ended at unstable poles, reflected into the left half-plane (the
        structure likely does not fit the data).
    """

    dens: list[np.ndarray]
    nums: list[np.ndarray]
    covariance: np.ndarray
    theta: np.ndarray
    iterations: int
    converged: bool
    error: np.ndarray
    reflected: bool = False


def pole_scale(den: np.ndarray, ts: float) -> float:
    """A frequency (rad/s) of the order of the poles: their geometric mean, the poles at 0 left out
    (1 / (10 ts) when all are at 0)."""
    r = np.abs(np.roots(den))
    r = r[r > 1e-9 * max(r.max(initial=0.0), 1.0 / ts)]
    return float(np.exp(np.mean(np.log(r)))) if r.size else 0.1 / ts


def _stable(den: np.ndarray) -> np.ndarray:
    """``den`` with its right half-plane roots mirrored into the left half-plane."""
    r = np.roots(den)
    if not np.any(r.real > 0):
        return den
    return np.real(np.poly(np.where(r.real > 0, -r.real + 1j * r.imag, r)))


def _foh_taps(den: np.ndarray, ts: float) -> tuple[np.ndarray, ...]:
    """Φ and the taps of a linearly interpolated signal: ``x(k+1) = Φ x + (Γ − Λ) v(k) + Λ v(k+1)``."""
    from scipy.linalg import expm

    ac, bc = controllable_form(den)
    n = len(bc)
    big = np.zeros((n + 2, n + 2))
    big[:n, :n], big[:n, n], big[n, n + 1] = ac * ts, bc * ts, 1.0
    e = expm(big)
    return e[:n, :n], e[:n, n], e[:n, n + 1]


def _states(signal: np.ndarray, segments: list, phi, prev, cur, nxt, shift: int = 0) -> np.ndarray:
    return np.asarray(
        _core.srivc_filter(
            np.ascontiguousarray(signal, dtype=float),
            segments,
            np.ascontiguousarray(phi),
            np.ascontiguousarray(prev),
            np.ascontiguousarray(cur),
            np.ascontiguousarray(nxt),
            shift=int(shift),
        )
    )


def input_states(u: np.ndarray, den: np.ndarray, ts: float, delay: float, segments: list) -> np.ndarray:
    """The input held between samples and delayed by ``delay``, through ``1/den``: its filtered
    value and first n − 1 derivatives at the sampling instants."""
    whole, fraction = split_delay(delay, ts)
    ac, bc = controllable_form(den)
    phi, g0, g1 = zoh_matrices(ac, bc, ts, fraction)
    return _states(u, segments, phi, g1, g0, np.zeros_like(g0), whole)


def _smooth_states(x: np.ndarray, den: np.ndarray, ts: float, segments: list) -> np.ndarray:
    """States of a smooth signal (linear between samples) through ``1/den``, and its n-th
    derivative as the last column."""
    phi, gamma, lam = _foh_taps(den, ts)
    st = _states(x, segments, phi, np.zeros_like(gamma), gamma - lam, lam)
    top = x - st @ den[1:][::-1]
    return np.column_stack([st, top])


def output_error(
    y: np.ndarray, u: np.ndarray, ts: float, dens: Sequence, nums: Sequence, delays: Sequence[float], segments: list
) -> tuple[np.ndarray, list[np.ndarray]]:
    """``y`` minus the model's free run (from rest in each segment), and each input's contribution.

    Parameters
    ----------
    y : ndarray of shape (n_samples,)
    u : ndarray of shape (n_samples, n_inputs)
    ts : float
    dens, nums : sequences of ndarray
        Per input, descending powers of s (strictly proper).
    delays : sequence of float
        Per input, seconds.
    segments : list of (start, end)

    Returns
    -------
    error : ndarray of shape (n_samples,)
    parts : list of ndarray
    """
    parts = []
    for i in range(u.shape[1]):
        den = np.asarray(dens[i], dtype=float)
        st = input_states(u[:, i], den / den[0], ts, delays[i], segments)
        parts.append(st[:, : len(nums[i])] @ (np.asarray(nums[i], dtype=float)[::-1] / den[0]))
    return y - np.sum(parts, axis=0), parts


def segment_rows(segments: list) -> np.ndarray:
    """Indices of the samples inside the segments (the rows of the IV equations)."""
    return np.concatenate([np.arange(a, b) for a, b in segments]) if segments else np.zeros(0, dtype=int)


def _regressors(out_states: np.ndarray, in_states: list, n: int, n_zeros: Sequence[int]) -> np.ndarray:
    """``[−x^(n−1), ..., −x, u1^(m1), ..., u1, u2^(m2), ...]`` on the given rows."""
    cols = n + sum(m + 1 for m in n_zeros)
    phi = np.empty((out_states.shape[0], cols))
    phi[:, :n] = -out_states[:, n - 1 :: -1][:, :n]
    at = n
    for st, m in zip(in_states, n_zeros):
        phi[:, at : at + m + 1] = st[:, m::-1]
        at += m + 1
    return phi


def _iv_step(
    y: np.ndarray, u: np.ndarray, ts: float, den: np.ndarray, nums: list, n_zeros: Sequence[int], delays, segments
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One refined IV step for a common denominator: (theta, Σζζᵀ, output error of the model given)."""
    n = len(den) - 1
    # An unstable iterate would give unbounded instruments: its mirror image filters and simulates.
    filt = _stable(den)
    ust = [input_states(u[:, i], filt, ts, delays[i], segments) for i in range(u.shape[1])]
    xhat = sum(st[:, : len(b)] @ np.asarray(b, dtype=float)[::-1] for st, b in zip(ust, nums))
    err = y - xhat
    rows = segment_rows(segments)
    yf = _smooth_states(y, filt, ts, segments)[rows]
    xf = _smooth_states(xhat, filt, ts, segments)[rows]
    ur = [st[rows] for st in ust]
    phi, zeta = _regressors(yf, ur, n, n_zeros), _regressors(xf, ur, n, n_zeros)
    lhs, rhs = zeta.T @ phi, zeta.T @ yf[:, n]
    try:
        theta = np.linalg.solve(lhs, rhs)
    except np.linalg.LinAlgError:
        raise IdentifiabilityError(
            "the instrumental-variable equations are singular: the input does not excite the model's orders; "
            "lower the number of poles or zeros, or use richer data"
        ) from None
    return theta, zeta.T @ zeta, err


def _unpack(theta: np.ndarray, n: int, n_zeros: Sequence[int]) -> tuple[np.ndarray, list[np.ndarray]]:
    den = np.concatenate([[1.0], theta[:n]])
    nums, at = [], n
    for m in n_zeros:
        nums.append(theta[at : at + m + 1])
        at += m + 1
    return den, nums


def srivc(
    y: np.ndarray,
    u: np.ndarray,
    ts: float,
    den0: np.ndarray,
    n_zeros: Sequence[int],
    delays: Sequence[float],
    segments: list,
    max_iterations: int = 50,
    tolerance: float = 1e-8,
) -> SrivcFit:
    """SRIVC with one denominator common to every input, from the filter ``den0``.

    Parameters
    ----------
    y : ndarray of shape (n_samples,)
    u : ndarray of shape (n_samples, n_inputs)
    ts : float
        Sampling time in seconds.
    den0 : ndarray
        Starting denominator (monic, descending powers of s): the first filter.
    n_zeros : sequence of int
        Zeros per input (< number of poles).
    delays : sequence of float
        Dead time per input in seconds.
    segments : list of (start, end)
        Runs of finite samples; the filters restart from rest in each.
    max_iterations : int
    tolerance : float
        Relative change of the parameters that ends the iteration.

    Returns
    -------
    SrivcFit
    """
    n = len(den0) - 1
    w = pole_scale(den0, ts)
    # Rescaled time t' = w t: poles s' = s / w, coefficients a'_j = a_j / w^j, b'_k = b_k w^(k-n).
    tsw, dw = ts * w, [d * w for d in delays]
    den = np.asarray(den0, dtype=float) / w ** np.arange(n + 1)
    # The first step has no model output yet: least squares on the filtered data (ζ = φ).
    theta, gram, err = _ls_start(y, u, tsw, den, n_zeros, dw, segments)
    converged, it = False, 1
    while it < max_iterations:
        it += 1
        den, nums = _unpack(theta, n, n_zeros)
        new, gram, err = _iv_step(y, u, tsw, den, nums, n_zeros, dw, segments)
        if not np.all(np.isfinite(new)):
            raise ConvergenceError(
                "the refined instrumental-variable iterations diverged; give a better start (initial=...) or "
                "fewer poles"
            )
        change = np.linalg.norm(new - theta) / max(np.linalg.norm(new), 1e-300)
        theta = new
        if change < tolerance:
            converged = True
            break
    den, nums = _unpack(theta, n, n_zeros)
    roots = np.roots(den)
    reflected = bool(np.any(roots.real > 1e-3 * np.abs(roots).max(initial=0.0)))
    if reflected:  # the model the last step filtered and simulated with (a pole near 0 stays as it is)
        den = _stable(den)
        theta = np.concatenate([den[1:], theta[n:]])
    err, _ = output_error(y, u, tsw, [den] * u.shape[1], nums, dw, segments)
    ok = np.isfinite(err)
    sigma2 = float(np.sum(err[ok] ** 2) / max(ok.sum() - len(theta), 1))
    cov = sigma2 * np.linalg.pinv(gram)
    scale = np.concatenate([w ** np.arange(1, n + 1)] + [w ** (n - np.arange(m, -1, -1)) for m in n_zeros])
    theta = theta * scale
    cov = cov * np.outer(scale, scale)
    den, nums = _unpack(theta, n, n_zeros)
    return SrivcFit([den] * u.shape[1], nums, cov, theta, it, converged, err, reflected)


def _ls_start(y, u, ts, den, n_zeros, delays, segments):
    """A least-squares state-variable-filter step: the IV step with the noisy regressors as their own
    instruments (the model output is not known yet)."""
    n = len(den) - 1
    filt = _stable(den)
    rows = segment_rows(segments)
    yf = _smooth_states(y, filt, ts, segments)[rows]
    ur = [input_states(u[:, i], filt, ts, delays[i], segments)[rows] for i in range(u.shape[1])]
    phi = _regressors(yf, ur, n, n_zeros)
    theta, *_ = np.linalg.lstsq(phi, yf[:, n], rcond=None)
    return theta, phi.T @ phi, None
