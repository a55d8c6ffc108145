"""Process models in MATLAB's ``idproc`` vocabulary: :func:`procest`.

A structure string ``P`` + number of poles (1, 2 or 3) + letters in any order: ``D`` a dead time
``Td``, ``Z`` a zero ``Tz``, ``U`` an underdamped pair ``Tw``, ``Zeta`` (two poles at least), ``I``
an integrator. The transfer function is

.. math::

    G(s) = K \\frac{1 + T_z s}{(1 + T_{p1} s)(1 + T_{p2} s)(1 + T_{p3} s)} e^{-T_d s}
    \\quad\\text{or}\\quad
    K \\frac{1 + T_z s}{(1 + 2 \\zeta T_w s + (T_w s)^2)(1 + T_{p3} s)} e^{-T_d s}

times ``1/s`` with ``I``. Estimation: :func:`arxid.tfest` (SRIVC, dead time searched when ``D``)
gives the start, then a bounded prediction-error refinement of the output error (time constants
and ``Tw`` positive, ``Zeta`` positive, ``Td`` >= 0) by ``scipy.optimize.least_squares``, each
residual evaluation filtering in the Rust core.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from .continuous_tf import ContinuousTransferFunction, scored_segments
from .srivc import output_error
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
        """Lower and upper bounds per parameter: time constants and Tw above 0, Zeta above 0, Td
        between 0 and ``max_delay``.

        Parameters
        ----------
        ts : float
        max_delay : float

        Returns
        -------
        lower, upper : list of float
        """
        pairs = []
        for n in self.parameter_names:
            if n in ("K", "Tz"):
                pairs.append((-math.inf, math.inf))
            elif n == "Td":
                pairs.append((0.0, max_delay))
            elif n == "Zeta":
                pairs.append((1e-6, math.inf))
            else:
                pairs.append((1e-6 * ts, math.inf))
        return [p[0] for p in pairs], [p[1] for p in pairs]


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


def _start(data: IOData, st: ProcessStructure, max_delay: float | None) -> dict[str, float]:
    """Process parameters from a tfest fit of the same orders (the integrator as one more pole)."""
    n = st.n_poles + st.integrator
    m = tfest(data, n, 1 if st.zero else 0, "estimate" if st.delay else None, max_delay=max_delay)
    poles = m.continuous_poles()
    num, gain_den = m.num_, m.den_
    p: dict[str, float] = {}
    if st.integrator:
        k = int(np.argmin(np.abs(poles)))
        poles = np.delete(poles, k)
        gain_den = np.real(np.poly(poles))
    dc = gain_den[-1] if gain_den[-1] != 0 else 1e-12
    p["K"] = float(num[-1] / dc)
    if st.zero:
        p["Tz"] = float(num[0] / num[-1]) if num[-1] != 0 else 0.0
    order = np.argsort(np.abs(poles))
    poles = poles[order]
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
        p["Td"] = m.dead_time_
    return p


def procest(data: IOData, structure: str, *, max_delay: float | None = None, max_iterations: int = 200):
    """Process model (gain, time constants, dead time) from sampled data, as MATLAB's ``procest``.

    Parameters
    ----------
    data : IOData
        Single-input estimation data (zero-order hold); several experiments and NaN gaps allowed.
    structure : str
        ``"P1"``, ``"P1D"``, ``"P2DU"``, ``"P1DI"``, ``"P3Z"``... (see the module docstring).
    max_delay : float, optional
        Longest dead time considered, seconds (default 20 samples).
    max_iterations : int
        Cap on the refinement's function evaluations (in units of the parameter count).

    Returns
    -------
    ContinuousTransferFunction
        ``parameter_dict()`` gives ``{"K": (value, std), "Tp1": ..., "Td": ...}``; the model
        predicts, simulates and compares like any arxid model.

    Raises
    ------
    OrderError
        For an unreadable structure.
    DataError
        For data with several inputs (select one) or no finite samples.

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
    from scipy.optimize import least_squares

    if not isinstance(data, IOData):
        raise DataError(f"procest needs an arxid.IOData, got {type(data).__name__}")
    st = parse_process(structure)
    if data.n_inputs != 1:
        raise DataError(
            f"procest fits one input's process model; the data have {data.n_inputs} inputs {list(data.input_names)}: "
            "select one (data.with_signals or IOData of that input)"
        )
    seg = scored_segments(data)
    if not seg:
        raise DataError("the data have no sample where the output and the input are finite")
    top = 20 * data.ts if max_delay is None else float(max_delay)
    names = st.parameter_names
    p0 = _start(data, st, top)
    lo, hi = st.bounds(data.ts, top)
    x0 = np.clip([p0[n] for n in names], np.array(lo) + 1e-12, hi)

    def resid(x: np.ndarray) -> np.ndarray:
        num, den, tau = st.transfer(dict(zip(names, x)))
        err, _ = output_error(data.y, data.u, data.ts, [den], [num], [tau], seg)
        return np.nan_to_num(err[np.isfinite(err)], nan=0.0, posinf=1e150, neginf=-1e150)

    res = least_squares(resid, x0, bounds=(lo, hi), x_scale="jac", max_nfev=max_iterations * len(names))
    if not np.all(np.isfinite(res.x)):  # pragma: no cover - least_squares keeps finite iterates
        raise ArxidError("the process-model refinement failed; try another structure")
    dof = max(res.fun.size - len(names), 1)
    sigma2 = float(res.fun @ res.fun / dof)
    cov = sigma2 * np.linalg.pinv(res.jac.T @ res.jac)

    def unpack(x: np.ndarray) -> tuple[list, list, list]:
        num, den, tau = st.transfer(dict(zip(names, x)))
        return [den / den[0]], [num / den[0]], [tau]

    return ContinuousTransferFunction.fitted(
        data,
        res.x,
        cov,
        names,
        unpack,
        structure=st.name,
        method="SRIVC start, bounded prediction-error refinement",
        iterations=int(res.nfev),
        converged=bool(res.status > 0),
    )
