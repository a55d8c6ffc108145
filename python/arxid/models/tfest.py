"""Continuous-time transfer functions from sampled data: :func:`tfest` (MATLAB's ``tfest``, by SRIVC).

The iteration itself is in :mod:`arxid.models.srivc`; this module checks the arguments, finds the
starting filter (a discrete ARX model's poles mapped by ``s = ln(z) / ts``, the ``d2c`` of its
poles), searches the dead time when asked, handles several inputs (one common denominator, or one
per input fitted in turn against the others' simulated outputs) and builds the
:class:`~arxid.models.continuous_tf.ContinuousTransferFunction`.
"""

from __future__ import annotations

import math
import numbers
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base.limits import check_order
from ..data.iodata import IOData
from ..exceptions import ArxidError, ArxidWarning, DataError, OrderError
from .arx_model import arx
from .continuous_tf import ContinuousTransferFunction, scored_segments
from .srivc import SrivcFit, output_error, srivc

__all__ = ["tfest", "start_denominator", "search_delay"]

#: Golden ratio step of the dead-time search.
_GOLD = (math.sqrt(5.0) - 1.0) / 2.0


def start_denominator(data: IOData, n_poles: int, whole_delay: int = 0) -> np.ndarray:
    """The first filter: the poles of ARX(n, n, ℓ + 1) mapped by ``s = ln(z) / ts`` (poles on the
    negative real axis by ``ln |z|``), or ``(s + λ)^n`` with λ a tenth of the sampling rate (rad/s)
    when ARX cannot be fitted.

    Parameters
    ----------
    data : IOData
    n_poles : int
    whole_delay : int
        Whole samples of dead time.

    Returns
    -------
    ndarray
        Monic, descending powers of s.
    """
    ts = data.ts
    try:
        z = np.roots(arx(data, n_poles, [n_poles] * data.n_inputs, [whole_delay + 1] * data.n_inputs).a)
    except ArxidError:
        z = np.zeros(0)
    if z.size != n_poles or not np.all(np.isfinite(z)) or np.any(np.abs(z) < 1e-6):
        return np.real(np.poly(np.full(n_poles, -0.1 * 2 * np.pi / ts)))
    on_axis = (np.abs(z.imag) <= 1e-12 * np.abs(z)) & (z.real < 0)
    s = np.where(on_axis, np.log(np.abs(z)), np.log(z.astype(complex))) / ts
    return np.real(np.poly(s))


def _per_input(name: str, value: Any, m: int) -> list[int]:
    vals = list(value) if isinstance(value, (list, tuple, np.ndarray)) else [value] * m
    if len(vals) != m:
        raise OrderError(f"{name} has {len(vals)} entries but the data have {m} inputs; give one per input")
    return [check_order(f"{name}", v) for v in vals]


def _delays(delay: Any, m: int) -> list[float] | None:
    """Dead times per input in seconds, or None for "estimate"."""
    if isinstance(delay, str):
        if delay != "estimate":
            raise ArxidError(f"delay must be seconds, a list of them, or 'estimate', got {delay!r}")
        return None
    vals = (
        [0.0] * m if delay is None else (list(delay) if isinstance(delay, (list, tuple, np.ndarray)) else [delay] * m)
    )
    if len(vals) != m:
        raise OrderError(f"delay has {len(vals)} entries but the data have {m} inputs; give one per input")
    for v in vals:
        if isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or v < 0:
            raise ArxidError(f"a dead time is a number of seconds >= 0, got {v!r}")
    return [float(v) for v in vals]


def _fit(
    data: IOData, ns: list[int], nz: list[int], delays: list[float], common: bool, den0: Any = None, **kw: Any
) -> SrivcFit:
    y, u, seg = data.y, data.u, scored_segments(data)
    if common or data.n_inputs == 1:
        if den0 is None:
            den0 = start_denominator(data, ns[0], int(min(delays) // data.ts))
        return srivc(y, u, data.ts, den0, nz, delays, seg, **kw)
    if den0 is None:
        den0 = [
            start_denominator(data.with_signals(u=data.u[:, [i]], input_names=[name]), ns[i], int(delays[i] // data.ts))
            for i, name in enumerate(data.input_names)
        ]
    return _independent(data, nz, delays, seg, list(den0), **kw)


def _independent(data, nz, delays, seg, dens, max_iterations=50, tolerance=1e-8) -> SrivcFit:
    """One denominator per input: each input's model refitted (SISO SRIVC) against the output minus
    the other inputs' simulated contributions, until the parameters settle (backfitting)."""
    m = data.n_inputs
    fits: list[SrivcFit | None] = [None] * m
    nums = [np.zeros(k + 1) for k in nz]
    it, converged, last = 0, False, None
    while it < max_iterations:
        it += 1
        for i in range(m):
            _, parts = output_error(data.y, data.u, data.ts, dens, nums, delays, seg)
            rest = data.y - sum(p for j, p in enumerate(parts) if j != i)
            f = srivc(rest, data.u[:, [i]], data.ts, dens[i], [nz[i]], [delays[i]], seg, max_iterations, tolerance)
            fits[i], dens[i], nums[i] = f, f.dens[0], f.nums[0]
        theta = np.concatenate([np.concatenate([d[1:], b]) for d, b in zip(dens, nums)])
        if last is not None and np.linalg.norm(theta - last) <= 1e-7 * np.linalg.norm(theta):
            converged = True
            break
        last = theta
    blocks = [f.covariance for f in fits if f is not None]
    cov = np.zeros((sum(b.shape[0] for b in blocks),) * 2)
    at = 0
    for b in blocks:
        cov[at : at + b.shape[0], at : at + b.shape[0]] = b
        at += b.shape[0]
    err, _ = output_error(data.y, data.u, data.ts, dens, nums, delays, seg)
    return SrivcFit(dens, nums, cov, theta, it, converged, err, any(f.reflected for f in fits if f is not None))


def _loss(fit: SrivcFit) -> float:
    """Mean squared output error; inf for a model whose simulation diverged."""
    if np.isinf(fit.error).any():
        return math.inf
    with np.errstate(all="ignore"):
        e = fit.error[np.isfinite(fit.error)]
        v = float(np.mean(e**2)) if e.size else math.inf
    return v if math.isfinite(v) else math.inf


def search_delay(
    data: IOData, ns: list[int], nz: list[int], common: bool, max_delay: float | None = None, **kw: Any
) -> tuple[float, SrivcFit]:
    """The dead time (one for all inputs) that minimises the output-error loss: whole samples
    0 .. ``max_delay`` first, then a golden-section search over ±1 sample around the best.

    Parameters
    ----------
    data : IOData
    ns : list of int
        Poles per input (all equal with a common denominator).
    nz : list of int
        Zeros per input.
    common : bool
        One denominator for all inputs.
    max_delay : float, optional
        Longest dead time tried, seconds (default 20 samples).
    **kw
        Passed to the SRIVC iteration.

    Returns
    -------
    dead_time : float
    fit : SrivcFit
    """
    ts, m = data.ts, data.n_inputs
    top = 20 if max_delay is None else max(int(max_delay / ts), 0)
    results: dict[float, SrivcFit] = {}
    coarse = {**kw, "max_iterations": min(kw.get("max_iterations", 50), 8)}
    warm: list[Any] = [None]

    def loss(tau: float, options: dict) -> float:
        if tau not in results:
            try:
                with np.errstate(all="ignore"):  # a delay far from the true one may diverge: its loss is inf
                    results[tau] = _fit(data, ns, nz, [tau] * m, common, warm[0], **options)
            except ArxidError:
                return math.inf
        return _loss(results[tau])

    best = min(range(top + 1), key=lambda k: loss(k * ts, coarse))
    if best * ts in results:
        dens = results[best * ts].dens
        warm[0] = dens[0] if common or m == 1 else dens
    results.clear()  # refitted to full convergence below
    lo, hi = max(best - 1, 0) * ts, (best + 1) * ts
    if max_delay is not None:
        hi = min(hi, max_delay)
    c, d = hi - _GOLD * (hi - lo), lo + _GOLD * (hi - lo)
    while hi - lo > 1e-3 * ts:
        if loss(c, kw) < loss(d, kw):
            hi, d = d, c
            c = hi - _GOLD * (hi - lo)
        else:
            lo, c = c, d
            d = lo + _GOLD * (hi - lo)
    tau = min(results, key=lambda t: _loss(results[t]))
    return tau, results[tau]


def tfest(
    data: IOData,
    n_poles: int | Sequence[int],
    n_zeros: int | Sequence[int] | None = None,
    delay: float | Sequence[float] | str | None = None,
    *,
    denominator: str = "common",
    max_delay: float | None = None,
    max_iterations: int = 50,
    tolerance: float = 1e-8,
) -> ContinuousTransferFunction:
    """Continuous-time transfer function from sampled data, by the simplified refined instrumental
    variable method for continuous-time systems (SRIVC), as MATLAB's ``tfest``.

    Parameters
    ----------
    data : IOData
        Estimation data, the inputs held constant between samples (zero-order hold). Several
        experiments and NaN gaps: the filters restart from rest in each run of finite samples.
    n_poles : int or sequence of int
        Poles of each transfer function (>= 1); one per input with ``denominator="independent"``.
    n_zeros : int or sequence of int, optional
        Zeros per input, fewer than the poles (default ``n_poles - 1``).
    delay : float, sequence of float or "estimate", optional
        Dead time in seconds (per input, or one for all; fractions of the sampling time allowed);
        ``"estimate"`` searches one common dead time; default 0.
    denominator : {"common", "independent"}
        Several inputs: one denominator for all (default) or one per input.
    max_delay : float, optional
        With ``delay="estimate"``: the longest dead time tried, seconds (default 20 samples).
    max_iterations : int
        Cap on the SRIVC iterations.
    tolerance : float
        Relative change of the parameters that ends the iterations.

    Returns
    -------
    ContinuousTransferFunction
        ``den_``, ``num_``, ``dead_time_`` (first input; ``dens_``, ``nums_``, ``delays_`` for all),
        ``parameter_dict()`` with standard deviations, ``iterations_``, ``converged_``; predicts,
        simulates and compares like any arxid model.

    Raises
    ------
    OrderError
        For orders a continuous model cannot have (no poles, as many zeros as poles).
    DataError
        When the data are not an IOData or have no finite samples.

    Notes
    -----
    .. math::

        y(t) = \\sum_i \\frac{b_{i,0} s^{m_i} + \\dots + b_{i,m_i}}{s^n + a_1 s^{n-1} + \\dots + a_n}
        e^{-s \\tau_i} u_i(t) + e(t)

    The start is the discrete ARX model's poles converted to continuous time; the iterations
    (:mod:`arxid.models.srivc`) then remove the bias ARX has under output noise.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(1)
    >>> u = np.sign(rng.standard_normal(400)).repeat(5)
    >>> a, b = arxid.models.continuous.c2d([3.0], [1.0, 1.5], 0.1, dead_time=0.23)
    >>> y = lfilter(b, a, u)
    >>> m = arxid.tfest(arxid.IOData(y, u, ts=0.1), 1, 0, delay="estimate")
    >>> round(m.dead_time_, 3), np.round(m.den_, 3), np.round(m.num_, 3)
    (0.23, array([1. , 1.5]), array([3.]))
    """
    if not isinstance(data, IOData):
        raise DataError(
            f"tfest needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)"
        )
    m = data.n_inputs
    ns = _per_input("n_poles", n_poles, m)
    if min(ns) < 1:
        raise OrderError("n_poles must be >= 1: a continuous transfer function needs at least one pole")
    nz = _per_input("n_zeros", [k - 1 for k in ns] if n_zeros is None else n_zeros, m)
    if any(z >= k for z, k in zip(nz, ns)):
        raise OrderError(
            f"n_zeros {nz} must be below n_poles {ns}: tfest fits strictly proper models (no direct feedthrough)"
        )
    if denominator not in ("common", "independent"):
        raise ArxidError(f"denominator must be 'common' or 'independent', got {denominator!r}")
    common = denominator == "common" or m == 1
    if common and len(set(ns)) > 1:
        raise OrderError(f"a common denominator has one number of poles, got {ns}; or use denominator='independent'")
    if not scored_segments(data):
        raise DataError("the data have no sample where the output and every input are finite")
    kw = {"max_iterations": check_order("max_iterations", max_iterations), "tolerance": float(tolerance)}
    delays = _delays(delay, m)
    if delays is None:
        tau, fit = search_delay(data, ns, nz, common, max_delay, **kw)
        delays = [tau] * m
    else:
        fit = _fit(data, ns, nz, delays, common, **kw)
    if fit.reflected:
        warnings.warn(
            f"tfest: the iterations ended at unstable poles, which were reflected into the left half-plane; "
            f"{ns} pole(s) and {nz} zero(s) may not describe these data: try other orders (a zero, one pole more "
            f"or less) and compare them on validation data",
            ArxidWarning,
            stacklevel=2,
        )
    if not fit.converged:
        warnings.warn(
            f"tfest: the parameters still changed after {fit.iterations} iterations (max_iterations); the estimate "
            f"may not be final: raise max_iterations, or check the orders on validation data",
            ArxidWarning,
            stacklevel=2,
        )
    return _model(data, fit, ns, nz, delays, common, estimated_delay=delay == "estimate")


def _model(data, fit: SrivcFit, ns, nz, delays, common, estimated_delay: bool) -> ContinuousTransferFunction:
    m = data.n_inputs
    names: list[str] = []
    tags = [""] if m == 1 else [f"({a})" for a in data.input_names]
    blocks = [0] if common else list(range(m))
    for i in blocks:
        names += [f"a{j}{tags[i] if not common else ''}" for j in range(1, ns[i] + 1)]
        if not common:
            names += [f"b{j}{tags[i]}" for j in range(nz[i] + 1)]
    if common:
        for i in range(m):
            names += [f"b{j}{tags[i]}" for j in range(nz[i] + 1)]
    dens, nums = fit.dens, fit.nums

    def unpack(theta: np.ndarray) -> tuple[list, list, list]:
        at, ds, bs = 0, [], []
        for i in range(m):
            if common and i == 0 or not common:
                den = np.concatenate([[1.0], theta[at : at + ns[i]]])
                at += ns[i]
            if not common:
                bs.append(theta[at : at + nz[i] + 1])
                at += nz[i] + 1
            ds.append(den)
        if common:
            for i in range(m):
                bs.append(theta[at : at + nz[i] + 1])
                at += nz[i] + 1
        return ds, bs, list(delays)

    theta = (
        np.concatenate([dens[0][1:], *nums])
        if common
        else np.concatenate([np.concatenate([d[1:], b]) for d, b in zip(dens, nums)])
    )
    how = "SRIVC" + (", dead time searched" if estimated_delay else "")
    label = "tf" if common else "tf-independent"
    zeros = nz[0] if len(set(nz)) == 1 else list(nz)
    n = ns[0] if len(set(ns)) == 1 else list(ns)
    return ContinuousTransferFunction.fitted(
        data,
        theta,
        fit.covariance,
        names,
        unpack,
        structure=f"{label}({n},{zeros})",
        method=how,
        iterations=fit.iterations,
        converged=fit.converged,
    )
