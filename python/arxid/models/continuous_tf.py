"""A continuous-time transfer function fitted to sampled data: :class:`ContinuousTransferFunction`.

The model is ``y(t) = Σ_i num_i(s) / den_i(s) · e^{-s τ_i} u_i(t) + e(t)`` (descending powers of s),
estimated by :func:`arxid.tfest` or :func:`arxid.procest`. Sampled with the data's zero-order hold
(exactly, a fractional dead time included, :func:`arxid.models.continuous.c2d`) it *is* an
output-error polynomial model ``y = B/F u + e``; the class therefore extends
:class:`~arxid.PolynomialModel` with that exact discrete equivalent, so that prediction, free-run
simulation on any data (several experiments, NaN gaps), :func:`arxid.compare`,
:func:`arxid.residuals`, :func:`arxid.where_it_fails`, the diagnosis and the report use it as they
use any OE model. The continuous parameters, their covariance and names are kept beside it.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from .._base import _core, metrics
from .._base.optional import require
from ..data.iodata import IOData
from .continuous import c2d, split_delay
from .filter_runs import finite_segments
from .polynomial import PolynomialModel

__all__ = ["ContinuousTransferFunction", "pade", "scored_segments"]

#: What maps the continuous parameters to per-input (denominators, numerators, dead times).
Unpack = Callable[[np.ndarray], tuple[list[np.ndarray], list[np.ndarray], list[float]]]


def _discrete(dens: Sequence, nums: Sequence, delays: Sequence[float], ts: float) -> tuple[list, list, list]:
    """Per input: the exact ZOH sample's numerator after its delay, denominator and delay (samples)."""
    bs, fs, nks = [], [], []
    for den, num, tau in zip(dens, nums, delays):
        a, b = c2d(num, den, ts, tau)
        nk = split_delay(tau, ts)[0] + 1
        bs.append(b[nk:])
        fs.append(a[1:])
        nks.append(nk)
    return bs, fs, nks


class ContinuousTransferFunction(PolynomialModel):
    """A continuous-time transfer function with dead time per input, fitted to sampled data.

    Built by :func:`arxid.tfest` and :func:`arxid.procest`; not constructed directly.

    Notes
    -----
    .. math::

        y(t) = \\sum_i \\frac{N_i(s)}{D_i(s)} e^{-s \\tau_i} u_i(t) + e(t)

    ``parameters_`` and ``covariance_`` are those of the exact discrete equivalent (an OE model, see
    the module docstring); ``continuous_parameters_``, ``continuous_covariance_`` and
    ``parameter_names_`` are the estimated ones, :meth:`parameter_dict` pairs them with their
    standard deviations. :func:`arxid.procest` adds ``parameters_on_bound_`` (names of the
    parameters that ended on a bound) and ``evaluations_`` (simulations run by its refinement).
    ``n_params`` and the information criteria count the discrete equivalent's parameters (what the
    shared checks index ``covariance_`` by); the continuous model has ``len(continuous_parameters_)``.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(0)
    >>> u = np.sign(rng.standard_normal(600)).repeat(5)
    >>> from scipy.signal import lfilter
    >>> y = lfilter([0, 1 - np.exp(-0.05)], [1, -np.exp(-0.05)], 2 * u)  # 2/(s + 1), ts = 0.05
    >>> m = arxid.tfest(arxid.IOData(y, u, ts=0.05), 1, 0)
    >>> np.round(m.den_, 6), np.round(m.num_, 6)
    (array([1., 1.]), array([2.]))
    """

    dens_: list[np.ndarray]
    nums_: list[np.ndarray]
    delays_: tuple[float, ...]
    continuous_parameters_: np.ndarray
    continuous_covariance_: np.ndarray
    parameter_names_: list[str]
    #: procest only: the parameters that ended on a bound, and the simulations its refinement ran.
    parameters_on_bound_: list[str]
    evaluations_: int
    structure_: str
    method_: str

    @classmethod
    def fitted(
        cls,
        data: IOData,
        theta: np.ndarray,
        covariance: np.ndarray,
        names: Sequence[str],
        unpack: Unpack,
        *,
        structure: str,
        method: str,
        iterations: int,
        converged: bool,
    ) -> ContinuousTransferFunction:
        """The model with continuous parameters ``theta`` (mapped by ``unpack``) on ``data``.

        Parameters
        ----------
        data : IOData
            The estimation data (names, units, sampling time, loss).
        theta : ndarray
            Continuous parameters.
        covariance : ndarray
            Their covariance.
        names : sequence of str
            One name per parameter.
        unpack : callable
            ``theta`` → (denominators, numerators, dead times), one of each per input.
        structure : str
            Name such as ``"tf(2,1)"`` or ``"P1D"``.
        method : str
            How it was estimated, in words.
        iterations : int
        converged : bool

        Returns
        -------
        ContinuousTransferFunction
        """
        self = cls()
        ts, m = data.ts, data.n_inputs
        dens, nums, delays = unpack(theta)
        bs, fs, nks = _discrete(dens, nums, delays, ts)
        orders = (0, tuple(len(b) for b in bs), 0, 0, tuple(len(f) for f in fs), tuple(nks))
        self.na_, self.nb_, self.nc_, self.nd_, self.nf_, self.nk_ = orders
        self.ts_ = ts
        self.output_name_, self.input_names_ = data.output_name, data.input_names
        self.output_unit_, self.input_units_ = data.output_unit, data.input_units
        self.parameters_ = np.concatenate([*bs, *fs])
        self.start_parameters_ = self.parameters_.copy()
        self.dens_, self.nums_ = [np.asarray(d, dtype=float) for d in dens], [np.asarray(n, dtype=float) for n in nums]
        self.delays_ = tuple(float(d) for d in delays)
        self.continuous_parameters_ = np.asarray(theta, dtype=float)
        self.continuous_covariance_ = np.asarray(covariance, dtype=float)
        self.parameter_names_ = list(names)
        self.structure_, self.method_ = structure, method
        self.iterations_, self.converged_ = int(iterations), bool(converged)
        self.termination_ = "converged" if converged else "stopped at the iteration cap"
        self.losses_ = np.zeros(0)
        self.initial_, self.initial_states_ = "zero", {}
        self.first_lag_ = int(_core.pem_max_lag((0, list(orders[1]), 0, 0, list(orders[4]), list(orders[5]))))
        self.data_ = data
        pred = self.predict(data, horizon=1)
        err = data.y - pred
        ok = np.isfinite(err)
        self.rss_, self.n_rows_ = float(np.sum(err[ok] ** 2)), int(ok.sum())
        self.n_skipped_ = data.n_samples - self.n_rows_
        jac = _jacobian(theta, unpack, ts, self.parameters_, m)
        self.covariance_ = jac @ self.continuous_covariance_ @ jac.T
        self.fit_percent_ = metrics.fit_percent(data.y, pred)
        return self

    # ------------------------------------------------------------------ what was estimated
    @property
    def den_(self) -> np.ndarray:
        """Denominator of the first input (descending powers of s, monic for tfest)."""
        return self.dens_[0]

    @property
    def num_(self) -> np.ndarray:
        """Numerator of the first input (descending powers of s)."""
        return self.nums_[0]

    @property
    def dead_time_(self) -> float:
        """Dead time of the first input in seconds."""
        return self.delays_[0]

    def parameter_dict(self, input: int | str | None = None) -> dict[str, tuple[float, float]]:
        """Each estimated parameter's name, value and standard deviation.

        Parameters
        ----------
        input : int or str, optional
            Only this input's (by index or name) parameters (and those all inputs share, such as a common
            denominator), named without the input's tag (``"K"`` rather than ``"K(u1)"``).

        Returns
        -------
        dict
            ``{name: (value, standard deviation)}``.
        """
        self.check_fitted()
        sd = np.sqrt(np.clip(np.diag(self.continuous_covariance_), 0.0, None))
        out = {n: (float(v), float(s)) for n, v, s in zip(self.parameter_names_, self.continuous_parameters_, sd)}
        if input is None:
            return out
        names = list(self.input_names_)
        tag = f"({names[names.index(input) if input in names else self._input_index(input)]})"
        return {n.removesuffix(tag): v for n, v in out.items() if n.endswith(tag) or not n.endswith(")")}

    def poles(self, input: int | None = None) -> np.ndarray:
        """Poles in rad/s (roots of the denominators in s), as python-control's ``poles()``.

        Parameters
        ----------
        input : int, optional
            Only this input's transfer function (default: every input's, a denominator that
            several inputs share counted once).

        Returns
        -------
        ndarray of complex
            :meth:`discrete_poles` gives the poles in z of the exact sampled equivalent.
        """
        self.check_fitted()
        idx = range(len(self.dens_)) if input is None else [self._input_index(input)]
        dens: list[np.ndarray] = []
        for i in idx:
            if not any(np.array_equal(self.dens_[i], d) for d in dens):
                dens.append(self.dens_[i])
        return np.concatenate([np.roots(d).astype(complex) for d in dens])

    def zeros(self, input: int = 0) -> np.ndarray:
        """Zeros in rad/s of ``input``'s transfer function (roots of its numerator in s).

        Parameters
        ----------
        input : int

        Returns
        -------
        ndarray of complex
            :meth:`discrete_zeros` gives the zeros in z of the exact sampled equivalent.
        """
        num = np.trim_zeros(self.nums_[self._input_index(input)], "f")
        return np.roots(num) if len(num) > 1 else np.zeros(0)

    def discrete_poles(self) -> np.ndarray:
        """Poles in z of the exact zero-order-hold equivalent (sample time ``ts``), ``exp(p ts)``
        for each pole p in rad/s, and poles at z = 0 from the dead time.

        Returns
        -------
        ndarray of complex
        """
        return super().poles()

    def discrete_zeros(self, input: int = 0) -> np.ndarray:
        """Zeros in z of the exact zero-order-hold equivalent of ``input``'s transfer function
        (the sampling zeros included).

        Parameters
        ----------
        input : int

        Returns
        -------
        ndarray of complex
        """
        return super().zeros(self._input_index(input))

    def continuous_poles(self, input: int = 0) -> np.ndarray:
        """Deprecated name of :meth:`poles` (one input's poles in rad/s)."""
        _renamed("continuous_poles", "poles")
        return self.poles(input)

    def continuous_zeros(self, input: int = 0) -> np.ndarray:
        """Deprecated name of :meth:`zeros` (in rad/s)."""
        _renamed("continuous_zeros", "zeros")
        return self.zeros(input)

    # ------------------------------------------------------------------ export
    def to_control(self, continuous: bool = True, input: int | None = None, pade_order: int | None = None) -> Any:
        """python-control transfer function(s) in s, the dead time in the attribute ``dead_time``.

        Parameters
        ----------
        continuous : bool
            True (default): the continuous model; False: its exact discrete equivalent (dt = ts).
        input : int, optional
            Only this input's transfer function.
        pade_order : int, optional
            Multiply by a Padé approximation of the dead time of this order (see :func:`pade`).

        Returns
        -------
        control.TransferFunction or list of them
            One per input (several inputs give a list unless ``input`` is given).
        """
        if not continuous:
            return super().to_control(continuous=False, input=input)
        control = require("control", "to_control")
        idx = range(len(self.input_names_)) if input is None else [self._input_index(input)]
        out = []
        for i in idx:
            tf = control.TransferFunction(
                self.nums_[i], self.dens_[i], inputs=[self.input_names_[i]], outputs=[self.output_name_]
            )
            tf.dead_time = self.delays_[i]
            out.append(tf if pade_order is None else pade(tf, pade_order))
        return out[0] if len(out) == 1 else out

    def to_dict(self) -> dict:
        """The discrete equivalent's content (see :meth:`arxid.PolynomialModel.to_dict`) with the
        continuous model under ``"continuous"``; :meth:`~arxid.PolynomialModel.from_json` loads the
        discrete equivalent.

        Returns
        -------
        dict
        """
        out = super().to_dict()
        out["continuous"] = {
            "structure": self.structure_,
            "method": self.method_,
            "numerators": [[float(x) for x in n] for n in self.nums_],
            "denominators": [[float(x) for x in d] for d in self.dens_],
            "dead_times": list(self.delays_),
            "parameters": {k: {"value": v, "std": s} for k, (v, s) in self.parameter_dict().items()},
        }
        return out

    # ------------------------------------------------------------------ printing
    def structure_name(self) -> str:
        """``tf(np,nz)`` for :func:`arxid.tfest`, the process structure (``P1D``...) for :func:`arxid.procest`.

        Returns
        -------
        str
        """
        return str(self.__dict__.get("structure_", "tf"))

    def __str__(self) -> str:
        if "parameters_" not in self.__dict__:
            return "continuous transfer function (not fitted)"
        lines = [f"Continuous-time model {self.structure_} ({self.method_}): y(t) = sum of G_i(s) u_i(t) + e(t)"]
        for i, name in enumerate(self.input_names_):
            lines.append(
                f"  G({name}) = exp(-{self.delays_[i]:.6g} s) * ({_in_s(self.nums_[i])}) / ({_in_s(self.dens_[i])})"
            )
        lines.append("  parameters (± one standard deviation):")
        lines += [f"    {k} = {v:.6g} ± {s:.3g}" for k, (v, s) in self.parameter_dict().items()]
        lines.append(f"Sample time of the data: {self.ts:g} seconds (zero-order hold between samples)")
        lines.append(
            f"Fit to estimation data: {self.fit_percent_:.2f}% (free run), noise variance {self.noise_variance_:.4g}, "
            f"{self.n_rows_} samples; {self.termination_} ({self.iterations_} iterations)"
        )
        return "\n".join(lines)

    def __repr__(self) -> str:
        if "parameters_" not in self.__dict__:
            return "ContinuousTransferFunction()"
        return f"<ContinuousTransferFunction {self.structure_} fit={self.fit_percent_:.2f}%>"


def _renamed(old: str, new: str) -> None:
    warnings.warn(
        f"ContinuousTransferFunction.{old}() is now {new}() (in rad/s; discrete_{new}() gives the sampled "
        "equivalent's, in z); the old name will be removed in the next release",
        DeprecationWarning,
        stacklevel=3,
    )


def _in_s(coefs: np.ndarray) -> str:
    """``2 s^2 + 0.5 s + 1`` from coefficients in descending powers of s."""
    n, parts = len(coefs) - 1, []
    for i, c in enumerate(coefs):
        if c == 0 and len(coefs) > 1:
            continue
        p = n - i
        mag = f"{abs(c):.6g}"
        term = mag if p == 0 else (("" if mag == "1" else mag + " ") + ("s" if p == 1 else f"s^{p}"))
        parts.append(("-" if c < 0 else "+", term))
    if not parts:
        return "0"
    out = ("-" if parts[0][0] == "-" else "") + parts[0][1]
    return out + "".join(f" {sign} {term}" for sign, term in parts[1:])


def _jacobian(theta: np.ndarray, unpack: Unpack, ts: float, ref: np.ndarray, m: int) -> np.ndarray:
    """∂(discrete parameters)/∂(continuous parameters) by central differences (the delay's whole
    samples held, as the discrete structure is)."""
    theta = np.asarray(theta, dtype=float)
    jac = np.zeros((len(ref), len(theta)))
    for j in range(len(theta)):
        h = 1e-6 * max(abs(theta[j]), 1e-3)
        cols = []
        for sign in (1.0, -1.0):
            t = theta.copy()
            t[j] += sign * h
            bs, fs, _ = _discrete(*unpack(t), ts)
            v = np.concatenate([*bs, *fs])
            cols.append(v if len(v) == len(ref) else ref)
        jac[:, j] = (cols[0] - cols[1]) / (2 * h)
    return jac


def pade(tf: Any, order: int) -> Any:
    """``tf`` times a Padé approximation of its ``dead_time`` (python-control's ``pade``).

    Parameters
    ----------
    tf : control.TransferFunction
        Continuous, with a ``dead_time`` attribute in seconds (as :meth:`ContinuousTransferFunction.to_control`
        and :func:`arxid.to_control` with ``continuous=True`` give).
    order : int
        Order of the approximation.

    Returns
    -------
    control.TransferFunction
        Rational, without the attribute ``dead_time``.
    """
    control = require("control", "pade")
    tau = float(getattr(tf, "dead_time", 0.0))
    if tau == 0.0:
        return tf
    num, den = control.pade(tau, int(order))
    return tf * control.TransferFunction(num, den)


def scored_segments(data: IOData) -> list[tuple[int, int]]:
    """Runs of finite samples (output and inputs) the estimators use.

    Parameters
    ----------
    data : IOData

    Returns
    -------
    list of (start, end)
    """
    return finite_segments(data, 0)
