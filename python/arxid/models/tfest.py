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
from .srivc import SrivcFit, input_states, output_error, segment_rows, srivc

__all__ = ["tfest", "start_denominator", "search_delay"]


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


def _delays(delay: Any, m: int) -> list[float | None]:
    """Dead times per input in seconds, None where ``"estimate"`` asks for a search."""
    if isinstance(delay, str) or delay is None or not isinstance(delay, (list, tuple, np.ndarray)):
        delay = [0.0 if delay is None else delay] * m
    vals = list(delay)
    if len(vals) != m:
        raise OrderError(f"delay has {len(vals)} entries but the data have {m} inputs; give one per input")
    out: list[float | None] = []
    for v in vals:
        if isinstance(v, str):
            if v != "estimate":
                raise ArxidError(f"delay must be seconds, a list of them, or 'estimate', got {v!r}")
            out.append(None)
        elif isinstance(v, bool) or not isinstance(v, numbers.Real) or not math.isfinite(v) or v < 0:
            raise ArxidError(f"a dead time is a number of seconds >= 0, got {v!r}")
        else:
            out.append(float(v))
    return out


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


def _numerator_loss(data: IOData, dens: list, nz: list[int], seg: list) -> Any:
    """``loss(taus)``: the mean squared output error with the denominators ``dens`` held and the
    numerators fitted by least squares (columns: each input's filtered, delayed states), the
    criterion of the dead-time search (variable projection over the numerators)."""
    rows = segment_rows(seg)
    y = data.y[rows]
    cache: dict[tuple[int, float], np.ndarray] = {}

    def columns(i: int, tau: float) -> np.ndarray:
        if (i, tau) not in cache:
            den = np.asarray(dens[i], dtype=float)
            st = input_states(data.u[:, i], den / den[0], data.ts, tau, seg)[rows, : nz[i] + 1]
            cache[(i, tau)] = st / np.maximum(np.linalg.norm(st, axis=0), 1e-300)
        return cache[(i, tau)]

    def loss(taus: list[float]) -> float:
        x = np.column_stack([columns(i, t) for i, t in enumerate(taus)])
        with np.errstate(all="ignore"):
            if not np.all(np.isfinite(x)):
                return math.inf
            coef, *_ = np.linalg.lstsq(x, y, rcond=None)
            r = y - x @ coef
        v = float(r @ r) / max(len(y), 1)
        return v if math.isfinite(v) else math.inf

    return loss


def _extrapolated(history: list[list[float]], which: list[int], ceiling: float, ts: float) -> list[float]:
    """Aitken's Δ² step on the last three rounds' dead times: the alternation between the dead
    times and the SRIVC fit converges linearly (the dead time and the poles are correlated), and
    a steady ratio of successive moves gives its limit."""
    a, b, c = history
    out = list(c)
    for i in which:
        d1, d2 = b[i] - a[i], c[i] - b[i]
        if d1 != 0.0 and 0.0 < d2 / d1 < 0.95:
            q = d2 / d1
            out[i] = float(np.clip(c[i] + d2 * q / (1.0 - q), max(c[i] - ts, 0.0), min(c[i] + ts, ceiling)))
    return out


def _search_one(loss: Any, cur: list[float], i: int, ts: float, top: int | None, ceiling: float) -> float:
    """Input ``i``'s dead time minimising ``loss`` with the others at ``cur``: the best whole sample
    0 .. ``top`` (when given), then Brent's bounded search over ±1 sample around it."""
    from scipy.optimize import minimize_scalar

    def at(tau: float) -> list[float]:
        return [tau if j == i else t for j, t in enumerate(cur)]

    best = cur[i] if top is None else ts * min(range(top + 1), key=lambda k: loss(at(k * ts)))
    lo, hi = max(best - ts, 0.0), min(best + ts, ceiling)
    tried = {best: loss(at(best))}
    if hi > lo:
        res = minimize_scalar(
            lambda t: loss(at(float(t))), bounds=(lo, hi), method="bounded", options={"xatol": 1e-4 * ts}
        )
        tried[float(res.x)] = loss(at(float(res.x)))
    return min(tried, key=lambda t: tried[t])


def search_delay(
    data: IOData,
    ns: list[int],
    nz: list[int],
    common: bool,
    max_delay: float | None = None,
    delays: Sequence[float | None] | None = None,
    **kw: Any,
) -> tuple[list[float], SrivcFit]:
    """The dead times (one per input, searched where ``delays`` has None) that minimise the output
    error, alternating with the SRIVC fit.

    Each round holds the current fit's denominators and minimises the output error over the dead
    times, the numerators fitted by least squares at each candidate (cheap: one filtering per
    candidate, no SRIVC iteration): whole samples 0 .. ``max_delay`` (first two rounds), then
    Brent's bounded minimisation (parabolic steps) over ±1 sample around the best, one searched
    input at a time (coordinate descent). SRIVC is then refitted at the new dead times, and the
    rounds stop when no dead time moves by more than 0.001 sample. The rounds converge linearly;
    every third round takes Aitken's extrapolation of the last three.

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
    delays : sequence of float or None, optional
        Per input: a fixed dead time in seconds, or None to search it (default: all searched).
    **kw
        Passed to the SRIVC iteration.

    Returns
    -------
    dead_times : list of float
        Seconds, one per input.
    fit : SrivcFit
    """
    ts, m = data.ts, data.n_inputs
    given = [None] * m if delays is None else list(delays)
    which = [i for i, d in enumerate(given) if d is None]
    cur = [0.0 if d is None else float(d) for d in given]
    top = 20 if max_delay is None else max(int(max_delay / ts + 1e-9), 0)
    ceiling = top * ts if max_delay is None else float(max_delay)
    seg = scored_segments(data)

    def refit(taus: list[float], warm: Any) -> SrivcFit | None:
        try:
            with np.errstate(all="ignore"):  # a delay far from the true one may diverge
                return _fit(data, ns, nz, taus, common, warm, **kw)
        except ArxidError:
            return None

    fit = refit(cur, None)
    dens = fit.dens if fit is not None else [start_denominator(data, k) for k in ns]
    history: list[list[float]] = []
    for rnd in range(12):
        loss = _numerator_loss(data, dens, nz, seg)
        before = list(cur)
        for i in which:
            cur[i] = _search_one(loss, cur, i, ts, top if rnd < 2 else None, ceiling)
        history.append(list(cur))
        if len(history) == 3 and rnd >= 2:
            cur = _extrapolated(history, which, ceiling, ts)
            history.clear()
        warm = (dens[0] if common or m == 1 else list(dens)) if fit is not None else None
        new = refit(cur, warm)
        if new is None:
            break
        fit, dens = new, new.dens
        if rnd >= 1 and max((abs(a - b) for a, b in zip(cur, before)), default=0.0) < 1e-3 * ts:
            break
    if fit is None:
        raise ArxidError(
            "tfest could not fit the model at any dead time up to max_delay; check the orders and the data, or give "
            "the dead time"
        )
    return cur, fit


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
        ``"estimate"`` searches each input's dead time (a list may mix seconds and ``"estimate"``);
        default 0.
    denominator : {"common", "independent"}
        Several inputs: one denominator for all (default) or one per input.
    max_delay : float, optional
        With ``delay="estimate"``: the longest dead time tried, seconds (default 20 samples).
        Several searched inputs are searched in turn (coordinate descent) until their dead times
        settle.
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
    given = _delays(delay, m)
    if any(d is None for d in given):
        delays, fit = search_delay(data, ns, nz, common, max_delay, delays=given, **kw)
    else:
        delays = [float(d) for d in given if d is not None]
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
    return _model(data, fit, ns, nz, delays, common, estimated_delay=any(d is None for d in given))


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
