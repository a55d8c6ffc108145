"""Process models in MATLAB's ``idproc`` vocabulary: :func:`procest`.

A structure string ``P`` + number of poles (1, 2 or 3) + letters in any order: ``D`` a dead time
``Td``, ``Z`` a zero ``Tz``, ``U`` an underdamped pair ``Tw``, ``Zeta`` (two poles at least), ``I``
an integrator. The transfer function is

.. math::

    G(s) = K \\frac{1 + T_z s}{(1 + T_{p1} s)(1 + T_{p2} s)(1 + T_{p3} s)} e^{-T_d s}
    \\quad\\text{or}\\quad
    K \\frac{1 + T_z s}{(1 + 2 \\zeta T_w s + (T_w s)^2)(1 + T_{p3} s)} e^{-T_d s}

times ``1/s`` with ``I``. Estimation: :func:`arxid.tfest` (SRIVC, dead time searched when ``D``)
gives the start (each input's dead time searched when ``D``), then a bounded prediction-error
refinement of the output error in the Rust core (time constants and ``Tw`` positive, ``Zeta``
positive, ``0 <= Td <= max_delay``; projected Levenberg–Marquardt, each evaluation sampling the
models exactly with their fractional dead times). Several inputs: one process model per input
(one structure string for all, or one per input), fitted jointly on the summed output.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .._base import _core
from .._base.limits import check_order
from ..data.iodata import IOData
from ..exceptions import ArxidError, ArxidWarning, DataError, OrderError
from .continuous_tf import ContinuousTransferFunction, scored_segments
from .tfest import tfest

__all__ = ["ProcessStructure", "parse_process", "procest"]

_FORM = re.compile(r"P(?P<poles>[123])(?P<letters>[DZUI]*)")


@dataclass(frozen=True)
class ProcessStructure:
    """A process model structure: poles, and which of dead time, zero, underdamped pair and
    integrator it has.

    Attributes
    ----------
    n_poles : int
    delay, zero, underdamped, integrator : bool
    """

    n_poles: int
    delay: bool
    zero: bool
    underdamped: bool
    integrator: bool

    @property
    def name(self) -> str:
        """MATLAB's string, letters in the order D, Z, U, I (e.g. ``"P2DU"``)."""
        flags = (("D", self.delay), ("Z", self.zero), ("U", self.underdamped), ("I", self.integrator))
        return f"P{self.n_poles}" + "".join(c for c, on in flags if on)

    @property
    def parameter_names(self) -> list[str]:
        """``K``, then ``Tp1``... or ``Tw``, ``Zeta`` (and ``Tp3``), ``Tz``, ``Td`` as present."""
        names = ["K"]
        if self.underdamped:
            names += ["Tw", "Zeta"] + (["Tp3"] if self.n_poles == 3 else [])
        else:
            names += [f"Tp{i}" for i in range(1, self.n_poles + 1)]
        return names + (["Tz"] if self.zero else []) + (["Td"] if self.delay else [])

    def transfer(self, p: dict[str, float]) -> tuple[np.ndarray, np.ndarray, float]:
        """Numerator, denominator (descending powers of s) and dead time of parameters ``p``.

        Parameters
        ----------
        p : dict
            Values by name (see :attr:`parameter_names`).

        Returns
        -------
        num, den : ndarray
        dead_time : float
        """
        num = p["K"] * (np.array([p["Tz"], 1.0]) if self.zero else np.ones(1))
        if self.underdamped:
            den = np.array([p["Tw"] ** 2, 2.0 * p["Zeta"] * p["Tw"], 1.0])
            den = np.polymul(den, [p["Tp3"], 1.0]) if self.n_poles == 3 else den
        else:
            den = np.ones(1)
            for i in range(1, self.n_poles + 1):
                den = np.polymul(den, [p[f"Tp{i}"], 1.0])
        if self.integrator:
            den = np.polymul(den, [1.0, 0.0])
        return num, den, float(p.get("Td", 0.0))

    def bounds(self, ts: float, max_delay: float) -> tuple[list[float], list[float]]:
        """Default lower and upper bounds per parameter: time constants and Tw above 0, Zeta above 0,
        Td between 0 and ``max_delay`` (the core raises the lower bounds of time constants to
        ``1e-6·ts`` and of Zeta to ``1e-6``).

        Parameters
        ----------
        ts : float
        max_delay : float

        Returns
        -------
        lower, upper : list of float
        """
        lower = [
            0.0 if n in ("Td", "Zeta") or n.startswith("T") and n != "Tz" else -math.inf for n in self.parameter_names
        ]
        upper = [max_delay if n == "Td" else math.inf for n in self.parameter_names]
        return lower, upper

    @property
    def core_spec(self) -> tuple[int, bool, bool, bool, bool]:
        """``(n_poles, zero, underdamped, integrator, delay)`` as the core takes it."""
        return (self.n_poles, self.zero, self.underdamped, self.integrator, self.delay)


def parse_process(text: str) -> ProcessStructure:
    """Read a structure string such as ``"P1D"``, ``"P2DU"``, ``"P1DI"``, ``"P3Z"``.

    Parameters
    ----------
    text : str

    Returns
    -------
    ProcessStructure

    Raises
    ------
    OrderError
        For anything else, with the form to write.
    """
    form = "'P' + 1, 2 or 3 poles + any of D (dead time), Z (zero), U (underdamped), I (integrator), e.g. 'P1D', 'P2DU'"
    mt = _FORM.fullmatch(text.strip().upper()) if isinstance(text, str) else None
    if mt is None or len(set(mt["letters"])) != len(mt["letters"]):
        raise OrderError(f"cannot read the process model {text!r}: write {form}")
    n, letters = int(mt["poles"]), mt["letters"]
    if "U" in letters and n < 2:
        raise OrderError(f"{text!r}: an underdamped pair (U) needs two poles at least, e.g. 'P2U'")
    return ProcessStructure(n, "D" in letters, "Z" in letters, "U" in letters, "I" in letters)


def _from_tf(num: np.ndarray, den: np.ndarray, tau: float, st: ProcessStructure) -> dict[str, float]:
    """Process parameters of one input's transfer function (the integrator as its pole nearest 0)."""
    poles = np.roots(den)
    gain_den = den
    p: dict[str, float] = {}
    if st.integrator:
        k = int(np.argmin(np.abs(poles)))
        poles = np.delete(poles, k)
        gain_den = np.real(np.poly(poles))
    dc = gain_den[-1] if gain_den[-1] != 0 else 1e-12
    p["K"] = float(num[-1] / dc)
    if st.zero:
        p["Tz"] = float(num[0] / num[-1]) if num[-1] != 0 else 0.0
    poles = poles[np.argsort(np.abs(poles))]
    if st.underdamped:
        pair = poles[:2]
        w = math.sqrt(abs(pair[0] * pair[1]))
        p["Tw"] = 1.0 / max(w, 1e-12)
        p["Zeta"] = float(max(-np.sum(pair).real / (2 * max(w, 1e-12)), 1e-3))
        if st.n_poles == 3:
            p["Tp3"] = 1.0 / max(abs(poles[2]), 1e-12)
    else:
        for i, s in enumerate(poles, start=1):
            p[f"Tp{i}"] = 1.0 / max(abs(s.real) if abs(s.imag) < 1e-9 else abs(s), 1e-12)
    if st.delay:
        p["Td"] = float(tau)
    return p


def _start(data: IOData, sts: list[ProcessStructure], max_delay: float) -> list[dict[str, float]]:
    """Process parameters per input from a tfest fit of the same orders (the integrator as one more
    pole; one denominator per input, each input's dead time searched when it has one)."""
    ns = [st.n_poles + st.integrator for st in sts]
    nz = [1 if st.zero else 0 for st in sts]
    delay: Any = ["estimate" if st.delay else 0.0 for st in sts]
    if len(sts) == 1:
        m = tfest(data, ns[0], nz[0], delay[0] if sts[0].delay else None, max_delay=max_delay)
    else:
        m = tfest(data, ns, nz, delay, denominator="independent", max_delay=max_delay)
    return [_from_tf(m.nums_[i], m.dens_[i], m.delays_[i], st) for i, st in enumerate(sts)]


def _structures(structure: str | Sequence[str], m: int) -> list[ProcessStructure]:
    if isinstance(structure, str):
        return [parse_process(structure)] * m
    sts = [parse_process(s) for s in structure]
    if len(sts) != m:
        raise OrderError(
            f"{len(sts)} process structures for data with {m} inputs: give one string for all inputs or one per input"
        )
    return sts


def _bounds(
    sts: list[ProcessStructure], names: list[str], ts: float, top: float, bounds: dict | None
) -> tuple[np.ndarray, np.ndarray]:
    """Default bounds, then the caller's: ``{"Td": (lo, hi)}`` for every input, ``{"Td(u2)": ...}``
    for one."""
    lo, hi = [], []
    for st in sts:
        st_lo, st_hi = st.bounds(ts, top)
        lo += st_lo
        hi += st_hi
    lower, upper = np.array(lo, dtype=float), np.array(hi, dtype=float)
    for key, pair in (bounds or {}).items():
        hits = [j for j, n in enumerate(names) if n == key or n.split("(")[0] == key]
        if not hits:
            raise ArxidError(f"bounds: no parameter {key!r}; the model has {names}")
        try:
            a, b = (float(v) for v in pair)
        except (TypeError, ValueError):
            raise ArxidError(f"bounds[{key!r}] must be a pair (lower, upper), got {pair!r}") from None
        lower[hits], upper[hits] = np.maximum(lower[hits], a), np.minimum(upper[hits], b)
    for n, a, b in zip(names, lower, upper):
        if not a <= b:
            raise ArxidError(
                f"bounds: {n} has no admissible value ({a:g} to {b:g}); give a lower bound below the upper one "
                "(time constants, Tw and Zeta above 0, Td from 0 to max_delay)"
            )
    return lower, upper


def procest(
    data: IOData,
    structure: str | Sequence[str],
    *,
    max_delay: float | None = None,
    max_iterations: int = 100,
    bounds: dict[str, tuple[float, float]] | None = None,
) -> ContinuousTransferFunction:
    """Process model (gain, time constants, dead time) from sampled data, as MATLAB's ``procest``.

    Parameters
    ----------
    data : IOData
        Estimation data (zero-order hold); several experiments and NaN gaps allowed. Several inputs
        give one process model per input, fitted jointly on the summed output.
    structure : str or sequence of str
        ``"P1"``, ``"P1D"``, ``"P2DU"``, ``"P1DI"``, ``"P3Z"``... (see the module docstring): one
        for every input, or one per input.
    max_delay : float, optional
        Longest dead time considered, seconds (default 20 samples): the upper bound of ``Td``.
    max_iterations : int
        Cap on the Levenberg–Marquardt iterations of the refinement.
    bounds : dict, optional
        Narrower bounds, ``{"Zeta": (0.2, 1.0)}`` (every input's) or ``{"Td(u2)": (0, 0.5)}`` (one
        input's, by its name in :meth:`~ContinuousTransferFunction.parameter_dict`).

    Returns
    -------
    ContinuousTransferFunction
        ``parameter_dict()`` gives ``{"K": (value, std), "Tp1": ..., "Td": ...}`` (several inputs:
        names such as ``"K(u1)"``; ``parameter_dict(input="u1")`` gives one input's with plain
        names); ``parameters_on_bound_`` names the parameters that ended on a bound; the model
        predicts, simulates and compares like any arxid model.

    Raises
    ------
    OrderError
        For an unreadable structure, or a count of structures other than the inputs'.
    DataError
        For data with no finite samples.

    Notes
    -----
    The start is :func:`arxid.tfest` with the same orders (dead times searched per input). The
    refinement minimises the output error's sum of squares over the process parameters inside
    their bounds in the Rust core (projected Levenberg–Marquardt, forward-difference Jacobian,
    each evaluation sampling the models exactly with the fractional dead time); the covariance is
    ``σ² (JᵀJ)⁻¹`` at the optimum.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(2)
    >>> u = np.sign(rng.standard_normal(300)).repeat(10)
    >>> a, b = arxid.models.continuous.c2d([2.0], [4.0, 1.0], 0.1, dead_time=0.37)
    >>> m = arxid.procest(arxid.IOData(lfilter(b, a, u), u, ts=0.1), "P1D")
    >>> {k: round(v, 4) for k, (v, _) in m.parameter_dict().items()}
    {'K': 2.0, 'Tp1': 4.0, 'Td': 0.37}
    """
    if not isinstance(data, IOData):
        raise DataError(f"procest needs an arxid.IOData, got {type(data).__name__}")
    sts = _structures(structure, data.n_inputs)
    seg = scored_segments(data)
    if not seg:
        raise DataError("the data have no sample where the output and the inputs are finite")
    top = 20 * data.ts if max_delay is None else float(max_delay)
    tags = [""] if data.n_inputs == 1 else [f"({n})" for n in data.input_names]
    names = [n + tag for st, tag in zip(sts, tags) for n in st.parameter_names]
    lower, upper = _bounds(sts, names, data.ts, top, bounds)
    starts = _start(data, sts, top)
    x0 = np.clip([p[n] for st, p in zip(sts, starts) for n in st.parameter_names], lower, upper)
    specs = [st.core_spec for st in sts]
    u = np.ascontiguousarray(data.u, dtype=float)
    y = np.ascontiguousarray(data.y, dtype=float)
    x, jtj, resid, iterations, evaluations, converged, on_bound = _core.procest_refine(
        y,
        u,
        seg,
        data.ts,
        specs,
        np.asarray(x0, dtype=float),
        lower,
        upper,
        max_iterations=check_order("max_iterations", max_iterations),
    )
    sigma2 = float(resid @ resid / max(resid.size - len(names), 1))
    cov = sigma2 * np.linalg.pinv(jtj)
    sizes = np.cumsum([len(st.parameter_names) for st in sts])[:-1]

    def unpack(theta: np.ndarray) -> tuple[list, list, list]:
        out: tuple[list, list, list] = ([], [], [])
        for st, part in zip(sts, np.split(np.asarray(theta, dtype=float), sizes)):
            num, den, tau = st.transfer(dict(zip(st.parameter_names, part)))
            out[0].append(den / den[0])
            out[1].append(num / den[0])
            out[2].append(tau)
        return out

    label = sts[0].name if len({st.name for st in sts}) == 1 else ",".join(st.name for st in sts)
    model = ContinuousTransferFunction.fitted(
        data,
        x,
        cov,
        names,
        unpack,
        structure=label,
        method="SRIVC start, bounded prediction-error refinement",
        iterations=iterations,
        converged=converged,
    )
    model.parameters_on_bound_ = [n for n, b in zip(names, on_bound) if b]
    model.evaluations_ = int(evaluations)
    if not converged:
        warnings.warn(
            f"procest: the refinement was still improving after {iterations} iterations (max_iterations); the "
            "estimate may not be final: raise max_iterations, or check the structure on validation data",
            ArxidWarning,
            stacklevel=2,
        )
    # No dead time (Td = 0) is an ordinary answer, not a sign of a bound in the way.
    said = [b and not (n.split("(")[0] == "Td" and v == 0.0) for n, v, b in zip(names, x, on_bound)]
    if any(said):
        warnings.warn(
            f"procest: {', '.join(n for n, b in zip(names, said) if b)} ended on a bound "
            f"({_limits(names, lower, upper, said)}): "
            "the best model inside the bounds is there; widen them (bounds=..., max_delay=...) or try another "
            "structure",
            ArxidWarning,
            stacklevel=2,
        )
    return model


def _limits(names: list[str], lower: np.ndarray, upper: np.ndarray, on_bound: list[bool]) -> str:
    return ", ".join(f"{n} in [{lo:g}, {hi:g}]" for n, lo, hi, b in zip(names, lower, upper, on_bound) if b)
