"""Discrete to continuous time (d2c) of one input's transfer function, exact or refused.

A discrete model ``H(z) = z^-d β(z^-1) / A(z^-1)`` (``A`` of order n, ``β`` with q + 1 coefficients,
``β0 ≠ 0``) is converted by one of three methods:

``"zoh"`` (default)
    The exact inverse of zero-order-hold sampling. ZOH sampling of a strictly proper system of
    order n with an input delay τ = ℓ·ts + δ (0 ≤ δ < ts) gives the numerator
    ``z^-(ℓ+1) (Γ0 + Γ1 z^-1)`` with ``Γ0 = ∫_0^{ts−δ} e^{As} ds B`` and
    ``Γ1 = e^{A(ts−δ)} ∫_0^δ e^{As} ds B`` (the modified z-transform, Åström & Wittenmark,
    *Computer-Controlled Systems*, ch. 2.3). So, with d ≥ 1: q + 1 ≤ n is an integer delay
    ℓ = d − 1 (matrix logarithm of ``[[Φ, Γ], [0, 1]]``); q + 1 = n + 1 (one more numerator
    coefficient than poles, e.g. nb = na + 1) is a fractional delay δ, found as the root of
    ``det [K(δ) | β] = 0`` where ``β = K(δ) B``; a longer numerator has poles at z = 0 that no
    ZOH-sampled system has and is refused. d = 0 (direct feedthrough) splits off ``D = β0`` and
    needs q ≤ n. Poles on the negative real axis have no real logarithm: refused, naming the
    other methods.
``"tustin"``
    The inverse of the bilinear map ``z = (1 + s·ts/2) / (1 − s·ts/2)`` applied to the biproper
    part ``z^r H(z)`` (r = relative degree; the r samples are the dead time). Equals
    python-control's ``sample_system(..., method="tustin")`` backwards.
``"matched"``
    Poles and zeros mapped by ``s = log(z) / ts``, the gain matched at DC; zeros at z = 0 are the
    dead time. The inverse of python-control's ``sample_system(..., method="matched")``.

Every returned model samples back to the discrete one (with its dead time) to rounding error;
anything else raises :class:`~arxid.exceptions.ConversionError` saying why and what to try.

The other way, :func:`c2d` samples a continuous model with a zero-order hold exactly, a fractional
dead time included (the same modified z-transform, from :func:`zoh_matrices`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import ConversionError

__all__ = ["METHODS", "ContinuousModel", "d2c", "c2d", "zoh_matrices", "split_delay"]

METHODS = ("zoh", "tustin", "matched")

_OTHER = "method='tustin' or method='matched' (approximate d2c methods, as MATLAB's d2c offers)"


@dataclass(frozen=True)
class ContinuousModel:
    """A continuous transfer function ``num(s) / den(s) · e^{-s·dead_time}`` (descending powers of s).

    Attributes
    ----------
    num, den : ndarray
        Polynomial coefficients in descending powers of s.
    dead_time : float
        Input delay in seconds (may be a fraction of the sampling time for ``"zoh"``).
    method : str
        The d2c method that produced it.
    """

    num: np.ndarray
    den: np.ndarray
    dead_time: float
    method: str


def _trimmed(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, int, np.ndarray]:
    """``A`` without trailing zeros; the delay d (leading zeros of the numerator) and ``β``."""
    a = np.trim_zeros(np.asarray(a, dtype=float), "b")
    b = np.asarray(b, dtype=float)
    nz = np.flatnonzero(b)
    if not nz.size:
        return a, 0, np.zeros(1)
    return a, int(nz[0]), b[nz[0] : nz[-1] + 1]


def d2c(a: np.ndarray, b: np.ndarray, ts: float, method: str = "zoh") -> ContinuousModel:
    """Continuous model of ``H(z) = B(z^-1) / A(z^-1)`` (both in ascending powers of z^-1).

    Parameters
    ----------
    a : array_like
        ``[1, a1, ..., a_na]``.
    b : array_like
        Numerator in powers of z^-1, the delay as leading zeros.
    ts : float
        Sampling time in seconds.
    method : {"zoh", "tustin", "matched"}
        See the module docstring.

    Returns
    -------
    ContinuousModel

    Raises
    ------
    ConversionError
        When no continuous model of the requested kind samples back to ``H`` exactly.
    """
    if method not in METHODS:
        raise ConversionError(f"method must be one of {METHODS}, got {method!r}")
    a, d, beta = _trimmed(a, b)
    if not beta.any():
        return ContinuousModel(np.zeros(1), np.ones(1), 0.0, method)
    if method == "zoh":
        return _zoh(a, d, beta, ts)
    if method == "tustin":
        return _tustin(a, d, beta, ts)
    return _matched(a, d, beta, ts)


# ------------------------------------------------------------------------------------------- zoh
def _companion(a: np.ndarray) -> np.ndarray:
    """Observable canonical form: with C = e1 and D = 0 its input vector is the numerator of
    z^-1 (g1 + g2 z^-1 + ...) / A, so Γ is the numerator itself."""
    n = len(a) - 1
    phi = np.zeros((n, n))
    phi[:, 0] = -a[1:]
    phi[: n - 1, 1:] = np.eye(n - 1)
    return phi


def _real_log(m: np.ndarray) -> np.ndarray:
    """Principal matrix logarithm, real; by eigen-decomposition when it is well conditioned (scipy's
    ``logm`` on small matrices mostly waits for BLAS threads), else ``logm``."""
    eig, v = np.linalg.eig(m)
    if np.any((np.abs(eig.imag) <= 1e-12 * np.abs(eig)) & (eig.real < 0)):
        raise ConversionError(
            "the model has a pole on the negative real axis (z < 0): no continuous system sampled with a "
            f"zero-order hold has one, so the exact inverse does not exist; use {_OTHER}, or a structure "
            "without such a pole"
        )
    if np.any(np.abs(eig) == 0):
        raise ConversionError(
            "the model has a pole at z = 0, which no zero-order-hold sample of a continuous system has"
        )
    if np.linalg.cond(v) < 1e6:
        return np.real((v * np.log(eig.astype(complex))) @ np.linalg.inv(v))
    with np.errstate(all="ignore"):
        from scipy.linalg import logm  # scipy.linalg on first use: importing arxid stays light

        lg = logm(m)
    return np.real(lg)


def _zoh(a: np.ndarray, d: int, beta: np.ndarray, ts: float) -> ContinuousModel:
    n = len(a) - 1
    q = len(beta) - 1
    if n == 0:  # a static gain, possibly delayed
        if q:
            raise ConversionError(_too_long(d, q, n))
        return ContinuousModel(np.array([beta[0]]), np.ones(1), d * ts, "zoh")
    feedthrough = 0.0
    if d == 0:
        if q > n:
            raise ConversionError(_too_long(d, q, n))
        # Split off the direct feedthrough: H − D = z^-1 (...) / A.
        feedthrough = beta[0]
        rest = np.concatenate([beta, np.zeros(n - q)]) - feedthrough * a
        gamma, delay = rest[1:], 0.0
    elif q + 1 <= n:
        gamma, delay = np.concatenate([beta, np.zeros(n - q - 1)]), float(d - 1)
    elif q == n:
        return _zoh_fractional(a, d, beta, ts)
    else:
        raise ConversionError(_too_long(d, q, n))
    # Φ = e^{Ac ts}, Γ = ∫_0^ts e^{Ac s} ds Bc.
    prop = _Propagator(_real_log(_companion(a)) / ts)
    bc = np.linalg.solve(prop(ts)[1], gamma)
    return _from_state_space(prop.ac, bc, feedthrough, delay * ts, ts)


def _too_long(d: int, q: int, n: int) -> str:
    return (
        f"the numerator has {q + 1} coefficients after the delay of {d} samples but the model has only {n} poles: "
        f"that means poles at z = 0, which no zero-order-hold sample of a continuous system has (it has at most "
        f"{n + 1}); use a structure with nb <= na + 1, or {_OTHER}"
    )


class _Propagator:
    """``e^{Ac t}`` and ``∫_0^t e^{Ac s} ds`` for many t: by the eigen-decomposition of Ac when it
    is well conditioned (``(e^{λt} − 1)/λ``, t at λ = 0), else Van Loan's block exponential."""

    def __init__(self, ac: np.ndarray, fast: bool = True):
        self.ac = ac
        lam, v = np.linalg.eig(ac)
        self.diagonal = fast and np.linalg.cond(v) < 1e6
        if self.diagonal:
            self.lam, self.v, self.v_inv = lam, v, np.linalg.inv(v)

    def __call__(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        if self.diagonal:
            lam = self.lam
            e = np.exp(lam * t)
            small = np.abs(lam * t) < 1e-8
            with np.errstate(all="ignore"):
                m = np.where(small, t * (1 + lam * t / 2), (e - 1) / np.where(small, 1.0, lam))
            return (
                np.real((self.v * e) @ self.v_inv),
                np.real((self.v * m) @ self.v_inv),
            )
        n = self.ac.shape[0]
        big = np.zeros((2 * n, 2 * n))
        big[:n, :n], big[:n, n:] = self.ac, np.eye(n)
        from scipy.linalg import expm

        e = expm(big * t)
        return e[:n, :n], e[:n, n:]


def _k_matrix(prop: _Propagator, ts: float, delta: float) -> np.ndarray:
    """Numerator coefficients (n + 1) per unit of each entry of B for a fractional delay δ."""
    e_rest, m_rest = prop(ts - delta)
    _, m_delta = prop(delta)
    n = e_rest.shape[0]
    k = np.zeros((n + 1, n))
    k[:n] += m_rest
    k[1:] += e_rest @ m_delta
    return k


def _zoh_fractional(a: np.ndarray, d: int, beta: np.ndarray, ts: float) -> ContinuousModel:
    """The delay δ is where β lies in the range of K(δ), a root of det [K(δ) | β]. A simple root
    changes sign (bisection); a continuous system of relative degree >= 2 makes it a double root
    (a small change of delay is then, to first order, a change of B), found as the minimum of the
    least-squares residual."""
    from scipy.optimize import brentq, minimize_scalar

    n = len(a) - 1
    prop = _Propagator(_real_log(_companion(a)) / ts)
    unit = beta / np.linalg.norm(beta)

    def signed(delta: float) -> float:
        k = _k_matrix(prop, ts, delta)
        return float(np.linalg.det(np.column_stack([k / np.linalg.norm(k), unit])))

    def residual(delta: float) -> float:
        k = _k_matrix(prop, ts, delta)
        x, *_ = np.linalg.lstsq(k, unit, rcond=None)
        return float(np.linalg.norm(k @ x - unit))

    grid = np.linspace(0.0, ts, 65)
    vals = np.array([signed(x) for x in grid])
    candidates = [
        brentq(signed, lo, hi, xtol=1e-15 * ts, rtol=4 * np.finfo(float).eps)
        for lo, hi, flo, fhi in zip(grid[:-1], grid[1:], vals[:-1], vals[1:])
        if flo * fhi < 0
    ]
    for i in np.argsort(np.abs(vals))[:2]:
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        candidates.append(
            float(minimize_scalar(residual, bounds=(lo, hi), method="bounded", options={"xatol": 1e-14 * ts}).x)
        )
    for delta in candidates:
        if residual(delta) <= 1e-11:
            k = _k_matrix(prop, ts, delta)
            bc, *_ = np.linalg.lstsq(k, beta, rcond=None)
            return _from_state_space(prop.ac, bc, 0.0, (d - 1) * ts + delta, ts)
    raise ConversionError(
        f"the numerator has one coefficient more than the model has poles ({n + 1} after the delay of {d} samples): "
        f"a zero-order-hold sample has that only with a fractional input delay, and no delay between 0 and one "
        f"sample reproduces this numerator; use a structure with nb <= na, or {_OTHER}"
    )


def _from_state_space(ac: np.ndarray, bc: np.ndarray, dc: float, dead_time: float, ts: float) -> ContinuousModel:
    from scipy.signal import ss2tf

    n = ac.shape[0]
    c = np.zeros((1, n))
    c[0, 0] = 1.0
    num, den = ss2tf(ac, bc.reshape(n, 1), c, np.array([[dc]]))
    return ContinuousModel(_clean(num[0], ts), np.asarray(den, dtype=float), float(dead_time), "zoh")


def _clean(num: np.ndarray, ts: float) -> np.ndarray:
    """Drop leading coefficients that are rounding error of an exact zero, judged by what each
    term contributes at the sampling frequency (s = 1/ts), not by the raw coefficient."""
    num = np.asarray(num, dtype=float)
    size = np.abs(num) * (1.0 / ts) ** np.arange(len(num) - 1, -1, -1)
    tol = 1e-14 * max(size.max(), 1e-300)
    k = 0
    while k < len(num) - 1 and size[k] <= tol:
        k += 1
    return num[k:]


# ------------------------------------------------------------------------------------ sampling
def split_delay(dead_time: float, ts: float) -> tuple[int, float]:
    """A dead time τ as whole samples ℓ and a fraction δ: τ = ℓ·ts + δ with 0 <= δ < ts.

    Parameters
    ----------
    dead_time : float
        Seconds, >= 0.
    ts : float
        Sampling time in seconds.

    Returns
    -------
    whole : int
    fraction : float
        Seconds.
    """
    whole = int(np.floor(dead_time / ts + 1e-9))
    fraction = max(dead_time - whole * ts, 0.0)
    return whole, (0.0 if fraction < 1e-9 * ts else fraction)


def zoh_matrices(ac: np.ndarray, bc: np.ndarray, ts: float, fraction: float = 0.0) -> tuple[np.ndarray, ...]:
    """Exact zero-order-hold discretisation with a fractional input delay δ (0 <= δ < ts):
    ``x(k+1) = Φ x(k) + Γ0 v(k) + Γ1 v(k−1)`` with ``Γ0 = ∫_0^{ts−δ} e^{As} ds B`` and
    ``Γ1 = e^{A(ts−δ)} ∫_0^δ e^{As} ds B`` (the modified z-transform).

    Parameters
    ----------
    ac : ndarray of shape (n, n)
    bc : ndarray of shape (n,)
    ts : float
        Sampling time in seconds.
    fraction : float
        δ in seconds.

    Returns
    -------
    phi, gamma0, gamma1 : ndarray
    """
    prop = _Propagator(np.asarray(ac, dtype=float))
    e_rest, m_rest = prop(ts - fraction)
    _, m_delta = prop(fraction)
    phi = prop(ts)[0]
    bc = np.asarray(bc, dtype=float)
    return phi, m_rest @ bc, e_rest @ (m_delta @ bc)


def controllable_form(den: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``Ac, Bc`` of ``1 / den(s)`` (den monic, descending powers) in controllable canonical form,
    whose states are the output and its first n − 1 derivatives."""
    den = np.asarray(den, dtype=float)
    n = len(den) - 1
    ac = np.zeros((n, n))
    ac[: n - 1, 1:] = np.eye(n - 1)
    ac[n - 1, :] = -den[1:][::-1]
    bc = np.zeros(n)
    bc[n - 1] = 1.0
    return ac, bc


def c2d(num: np.ndarray, den: np.ndarray, ts: float, dead_time: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold sampling of ``num(s) / den(s) · e^{-s·dead_time}`` (strictly proper), exact,
    fractional dead time included; the inverse of :func:`d2c` with ``method="zoh"``.

    Parameters
    ----------
    num, den : array_like
        Descending powers of s, ``len(num) < len(den)``.
    ts : float
        Sampling time in seconds.
    dead_time : float
        Input delay in seconds, >= 0.

    Returns
    -------
    a : ndarray
        ``[1, a1, ..., an]`` in powers of z⁻¹.
    b : ndarray
        Numerator in powers of z⁻¹: ``ℓ + 1`` leading zeros (ℓ whole samples of delay), then n + 1
        coefficients (the last is zero when the delay is a whole number of samples).

    Raises
    ------
    ConversionError
        When the model is not strictly proper.
    """
    num = np.atleast_1d(np.asarray(num, dtype=float))
    den = np.atleast_1d(np.asarray(den, dtype=float))
    n = len(den) - 1
    if n < 1 or len(num) > n:
        raise ConversionError(f"c2d needs a strictly proper model (fewer zeros than poles), got num {num}, den {den}")
    num, den = num / den[0], den / den[0]
    whole, fraction = split_delay(float(dead_time), ts)
    ac, bc = controllable_form(den)
    c = np.zeros(n)
    c[: len(num)] = num[::-1]
    phi, g0, g1 = zoh_matrices(ac, bc, ts, fraction)
    a = np.real(np.poly(phi))
    b = np.zeros(whole + n + 2)
    for shift, g in ((1, g0), (2, g1)):
        # C (zI − Φ)^-1 Γ = [det(zI − Φ + Γ C) − det(zI − Φ)] / det(zI − Φ) (matrix determinant lemma).
        part = np.real(np.poly(phi - np.outer(g, c))) - a
        b[whole + shift : whole + shift + n] += part[1:]
    return a, b


# ---------------------------------------------------------------------------------------- tustin
def _descending(a: np.ndarray, beta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``z^d H(z)`` as numerator and denominator of one degree max(n, q), descending powers of z."""
    deg = max(len(a), len(beta)) - 1
    return np.concatenate([beta, np.zeros(deg + 1 - len(beta))]), np.concatenate([a, np.zeros(deg + 1 - len(a))])


def _bilinear(p: np.ndarray, ts: float) -> np.ndarray:
    """``(1 − s ts/2)^m p((1 + s ts/2) / (1 − s ts/2))`` for p of degree m, descending powers of s."""
    m = len(p) - 1
    out = np.zeros(1)
    for k, c in enumerate(p):
        term = np.array([c])
        for _ in range(m - k):
            term = np.polymul(term, [ts / 2, 1.0])
        for _ in range(k):
            term = np.polymul(term, [-ts / 2, 1.0])
        out = np.polyadd(out, term)
    return out


def _tustin(a: np.ndarray, d: int, beta: np.ndarray, ts: float) -> ContinuousModel:
    num, den = _descending(a, beta)
    nc, dc = _clean(_bilinear(num, ts), ts), _clean(_bilinear(den, ts), ts)
    return ContinuousModel(nc / dc[0], dc / dc[0], d * ts, "tustin")


# --------------------------------------------------------------------------------------- matched
def _matched(a: np.ndarray, d: int, beta: np.ndarray, ts: float) -> ContinuousModel:
    n, q = len(a) - 1, len(beta) - 1
    # H = z^-(d + q - n) · β(z)/A(z) in descending powers; python-control's matched sampling gives
    # β(z)/A(z) (relative degree n − q), so the rest must be a delay.
    if d + q - n < 0:
        raise ConversionError(
            f"the model has {n - q - d} zero(s) at z = 0, which pole-zero matching cannot map (s = log 0); "
            f"use method='zoh' or method='tustin'"
        )
    zeros, poles = np.roots(beta), np.roots(a)
    for what, r in (("pole", poles), ("zero", zeros)):
        bad = r[(np.abs(r.imag) <= 1e-12 * np.abs(r)) & (r.real <= 0)]
        if bad.size:
            raise ConversionError(
                f"a {what} at z = {bad[0].real:.4g} (on the negative real axis) has no real image s = log(z)/ts "
                f"under pole-zero matching; use method='tustin'"
            )
    if abs(a.sum()) <= 1e-12 * np.abs(a).sum() or abs(beta.sum()) <= 1e-12 * np.abs(beta).sum():
        raise ConversionError(
            "pole-zero matching matches the gain at DC, which a model with a pole or a zero at z = 1 does not "
            "have; use method='zoh' or method='tustin'"
        )
    num_c = np.real(np.poly(np.log(zeros.astype(complex)) / ts))
    den_c = np.real(np.poly(np.log(poles.astype(complex)) / ts))
    gain = (beta.sum() / a.sum()) * den_c[-1] / num_c[-1]
    return ContinuousModel(gain * num_c, den_c, (d + q - n) * ts, "matched")
