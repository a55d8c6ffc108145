"""Polynomial models A y = B/F u + C/D e (output-error, ARMAX, Box–Jenkins): :class:`PolynomialModel`.

The estimation functions (:func:`arxid.oe`, :func:`arxid.armax`, :func:`arxid.bj`) live in
:mod:`arxid.pem`; this module holds, predicts, simulates and prints the fitted model. Its JSON is in
:mod:`arxid.models.polynomial_files`, the runs of finite samples its filters restart in and their
initial conditions in :mod:`arxid.models.filter_runs`.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base import _core, metrics
from .._base.digital_filter import lfilter
from .._base.formatting import format_polynomial
from .._base.limits import check_order
from ..data.iodata import IOData
from ..exceptions import ArxidWarning, DataError, IdentifiabilityError, NotFittedError, OrderError
from .derived_inputs import DerivedInput, complete_inputs
from .excitation import check_excitation
from .filter_runs import check_initial, check_size, finite_segments, per_input
from .fitted import FittedModel
from .fitted_layout import FittedLayout

__all__ = ["PolynomialModel", "finite_segments", "as_polynomial", "check_initial"]

_POLY_NAMES = ("a", "b", "c", "d", "f")


class PolynomialModel(FittedModel):
    """A polynomial model in MATLAB's form, fitted by prediction-error minimisation.

    Parameters
    ----------
    na, nc, nd : int
        Orders of A (poles shared by input and noise), C (noise zeros) and D (noise poles).
    nb, nf, nk : int or sequence of int
        Per input: numerator coefficients, denominator order of F and delay in samples.

    Notes
    -----
    .. math::

        A(q)\\, y(t) = \\sum_i \\frac{B_i(q)}{F_i(q)} u_i(t - n_{k,i}) + \\frac{C(q)}{D(q)} e(t)

    Output-error (OE) is A = C = D = 1, ARMAX is D = F = 1, Box–Jenkins (BJ) is A = 1; ARX is
    C = D = F = 1 (see :class:`arxid.ArxModel`). ``parameters_`` are ordered as MATLAB's
    ``getpvec``: A, B (each input), C, D, F (each input), without leading ones or delay zeros.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from scipy.signal import lfilter
    >>> rng = np.random.default_rng(0)
    >>> u = np.sign(rng.standard_normal(2000))
    >>> y = lfilter([0, 0.5], [1, -0.8], u) + 0.1 * rng.standard_normal(2000)
    >>> m = arxid.oe(arxid.IOData(y, u, ts=1.0), nb=1, nf=1, nk=1)
    >>> np.round(m.parameters_, 2)
    array([ 0.5, -0.8])
    """

    data_: IOData | None
    derived_inputs_: tuple[DerivedInput, ...]

    def __init__(self, *, na: int = 0, nb: Any = 1, nc: int = 0, nd: int = 0, nf: Any = 0, nk: Any = 1):
        self.na, self.nb, self.nc, self.nd, self.nf, self.nk = na, nb, nc, nd, nf, nk

    # ------------------------------------------------------------------ fitting
    def orders_for(self, data: IOData) -> tuple[int, tuple[int, ...], int, int, tuple[int, ...], tuple[int, ...]]:
        """The checked orders ``(na, nb, nc, nd, nf, nk)`` for ``data``'s inputs.

        Parameters
        ----------
        data : IOData

        Returns
        -------
        tuple
        """
        m = data.n_inputs
        orders = (
            check_order("na", self.na),
            per_input("nb", self.nb, m),
            check_order("nc", self.nc),
            check_order("nd", self.nd),
            per_input("nf", self.nf, m),
            per_input("nk", self.nk, m),
        )
        return orders

    def fit(
        self,
        data: IOData,
        *,
        start: Sequence[float] | None = None,
        max_iterations: int = 100,
        tolerance: float = 1e-6,
        n_threads: int = 0,
        initial: str = "zero",
        warn: bool = True,
    ) -> PolynomialModel:
        """Minimise the sum of squared one-step prediction errors (Gauss–Newton, Levenberg–Marquardt).

        Parameters
        ----------
        data : IOData
            Estimation data; NaN samples split the data into runs (see :func:`finite_segments`).
        start : sequence of float, optional
            Start parameters in ``getpvec`` order (default: ARX, refined instrumental variables for
            B/F and Hannan–Rissanen for C/D).
        max_iterations : int
            Gauss–Newton steps at most.
        tolerance : float
            Stop when a step would improve the loss by less than this fraction.
        n_threads : int
            Threads for the QR of the gradient (0 = all cores).
        initial : {"zero", "estimate"}
            How the filters start in each run of finite samples (MATLAB's ``InitialCondition``).
            ``"zero"``: at rest, and the first ``first_lag_`` samples of each run are not scored
            (they only feed the lags). ``"estimate"``: the initial state of each run is estimated
            with the parameters and every sample is scored; use it when a record starts
            mid-transient. The states are kept in ``initial_states_``.
        warn : bool
            Warn (:class:`ArxidWarning`) when the iterations end before converging. The outcome is
            in ``converged_`` and ``termination_`` either way. Pass ``False`` where many fits are
            judged by their own error: unlike ``warnings.catch_warnings``, which changes the
            process's filters, it is safe when fits run in threads.

        Returns
        -------
        PolynomialModel
            ``self``, fitted.
        """
        if not isinstance(data, IOData):
            raise DataError(
                f"fit needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)"
            )
        orders = self.orders_for(data)
        initial = check_initial(initial)
        lag = int(_core.pem_max_lag(orders)) if initial == "zero" else 0
        segments = finite_segments(data, lag)
        check_size(orders, segments, lag, data)
        check_excitation(data, orders[1])
        st = None if start is None else np.ascontiguousarray(start, dtype=float)
        try:
            res = _core.pem_fit(
                np.ascontiguousarray(data.y),
                np.ascontiguousarray(data.u),
                segments,
                orders,
                start=st,
                max_iterations=check_order("max_iterations", max_iterations),
                tolerance=float(tolerance),
                n_threads=check_order("n_threads", n_threads),
                initial=initial,
            )
        except IdentifiabilityError as exc:
            raise IdentifiabilityError(
                f"{self.structure_name()}: these data cannot determine the parameters ({exc}). The orders may be "
                f"too high (a pole and a zero that cancel), the input may not excite enough frequencies, or a "
                f"noise model (nc, nd) was asked of noise-free data: lower the orders or use richer data"
            ) from None
        self._store(data, orders, lag, res, initial)
        if warn and not res.converged:
            warnings.warn(
                f"{self.structure_name()}: {res.termination} after {res.iterations} iterations; the estimate may be a "
                f"local minimum: try another start or more iterations",
                ArxidWarning,
                stacklevel=2,
            )
        return self

    def _store(self, data: IOData, orders: tuple, lag: int, res: Any, initial: str) -> None:
        """Fitted state from the core's result (constructor arguments stay as given)."""
        self.na_, self.nb_, self.nc_, self.nd_, self.nf_, self.nk_ = orders
        self.ts_ = data.ts
        self.output_name_, self.input_names_ = data.output_name, data.input_names
        self.output_unit_, self.input_units_ = data.output_unit, data.input_units
        self.parameters_ = np.asarray(res.theta)
        self.start_parameters_ = np.asarray(res.start)
        self.rss_, self.n_rows_ = float(res.rss), int(res.n_rows)
        self.n_skipped_ = data.n_samples - self.n_rows_
        self.first_lag_ = lag
        self.iterations_, self.termination_, self.converged_ = (
            int(res.iterations),
            str(res.termination),
            bool(res.converged),
        )
        self.losses_ = np.asarray(res.losses)
        self.covariance_ = self.noise_variance_ * np.asarray(res.inv_gram)
        self.initial_ = initial
        self.initial_states_ = {tuple(seg): np.asarray(x) for seg, x in zip(res.initial_segments, res.initial_states)}
        self.data_ = data
        self.fit_percent_ = metrics.fit_percent(data.y, self.predict(data, horizon=1, initial=initial))

    def check_fitted(self) -> None:
        """Raise :class:`NotFittedError` unless the model is fitted (or loaded from JSON).

        Returns
        -------
        None
        """
        if "parameters_" not in self.__dict__:
            raise NotFittedError("this PolynomialModel is not fitted yet: use arxid.oe, arxid.armax or arxid.bj")

    def __getattr__(self, name: str) -> Any:
        if name.endswith("_") and not name.startswith("__"):
            raise NotFittedError(f"{name} is not available: this PolynomialModel is not fitted yet")
        raise AttributeError(name)

    # ------------------------------------------------------------------ names
    @property
    def derived_inputs(self) -> tuple[DerivedInput, ...]:
        """The inputs computed from the data (effects the diagnosis added), after the measured ones."""
        return tuple(self.__dict__.get("derived_inputs_", ()))

    @property
    def measured_input_names(self) -> tuple[str, ...]:
        """The inputs data must have: all but the derived ones."""
        return self.input_names[: len(self.input_names) - len(self.derived_inputs)]

    @property
    def effects(self) -> tuple[str, ...]:
        """Effect terms added as derived inputs (see :mod:`arxid.derived_inputs`); none for a plain fit."""
        return tuple(d.effect for d in self.derived_inputs)

    @property
    def is_linear(self) -> bool:
        """Always True."""
        return True

    @property
    def layout_(self) -> FittedLayout:
        """Orders and delays per input, in the form the converters read."""
        self.check_fitted()
        m = len(self.input_names_)
        return FittedLayout(tuple(self.nb_), tuple(self.nk_), (), self.input_names, (None,) * m, ())

    def input_labels(self) -> list[str]:
        """Names of the inputs.

        Returns
        -------
        list of str
        """
        return list(self.input_names)

    @property
    def kind(self) -> str:
        """``"OE"``, ``"ARMAX"``, ``"BJ"``, ``"ARX"`` or ``"polynomial"`` from the orders."""
        na, nc, nd, nf = (
            (self.na_, self.nc_, self.nd_, self.nf_)
            if "na_" in self.__dict__
            else (self.na, self.nc, self.nd, _as_tuple(self.nf))
        )
        if na == 0 and nc == 0 and nd == 0:
            return "OE"
        if nd == 0 and not any(nf):
            return "ARMAX" if nc else "ARX"
        return "BJ" if na == 0 else "polynomial"

    # ------------------------------------------------------------------ polynomials
    def polynomials(self) -> dict[str, Any]:
        """A, C, D as arrays and B, F as lists per input, in powers of z⁻¹ (B with nk leading zeros).

        Returns
        -------
        dict
            Keys ``"a"``, ``"b"``, ``"c"``, ``"d"``, ``"f"``.
        """
        self.check_fitted()
        th, at = self.parameters_, 0

        def take(n: int) -> np.ndarray:
            nonlocal at
            at += n
            return th[at - n : at]

        a = np.concatenate([[1.0], take(self.na_)])
        b = [np.concatenate([np.zeros(k), take(n)]) for n, k in zip(self.nb_, self.nk_)]
        c = np.concatenate([[1.0], take(self.nc_)])
        d = np.concatenate([[1.0], take(self.nd_)])
        f = [np.concatenate([[1.0], take(n)]) for n in self.nf_]
        return {"a": a, "b": b, "c": c, "d": d, "f": f}

    @property
    def a(self) -> np.ndarray:
        """A(z⁻¹) = [1, a1, ..., a_na]."""
        return self.polynomials()["a"]

    @property
    def b(self) -> list[np.ndarray]:
        """B_i(z⁻¹) per input with ``nk`` leading zeros (MATLAB's layout)."""
        return self.polynomials()["b"]

    @property
    def c(self) -> np.ndarray:
        """C(z⁻¹) = [1, c1, ..., c_nc], the noise numerator."""
        return self.polynomials()["c"]

    @property
    def d(self) -> np.ndarray:
        """D(z⁻¹) = [1, d1, ..., d_nd], the noise denominator."""
        return self.polynomials()["d"]

    @property
    def f(self) -> list[np.ndarray]:
        """F_i(z⁻¹) = [1, f1, ...] per input."""
        return self.polynomials()["f"]

    def input_transfer(self, input: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Numerator B_i and denominator A·F_i of the transfer function from ``input`` (powers of z⁻¹).

        Parameters
        ----------
        input : int

        Returns
        -------
        numerator, denominator : ndarray
        """
        p = self.polynomials()
        return p["b"][input], np.convolve(p["a"], p["f"][input])

    def common_denominator(self) -> tuple[list[np.ndarray], np.ndarray]:
        """Numerators over one denominator A·ΠF_i (what the converters need; exact for one input).

        Returns
        -------
        numerators : list of ndarray
        denominator : ndarray
        """
        p = self.polynomials()
        den = p["a"]
        for f in p["f"]:
            den = np.convolve(den, f)
        nums = []
        for i, b in enumerate(p["b"]):
            num = b
            for j, f in enumerate(p["f"]):
                num = num if j == i else np.convolve(num, f)
            nums.append(num)
        return nums, den

    def layout_numerators(self) -> list[np.ndarray]:
        """Numerators over :meth:`common_denominator` (one per input).

        Returns
        -------
        list of ndarray
        """
        return self.common_denominator()[0]

    def poles(self) -> np.ndarray:
        """Poles of the input-to-output part: roots of A and of every F_i.

        Returns
        -------
        ndarray of complex
        """
        p = self.polynomials()
        return np.concatenate([np.roots(x) if len(x) > 1 else np.zeros(0) for x in [p["a"], *p["f"]]])

    def zeros(self, input: int = 0) -> np.ndarray:
        """Roots of B of ``input`` (delays excluded).

        Parameters
        ----------
        input : int

        Returns
        -------
        ndarray of complex
        """
        b = np.trim_zeros(self.b[input][self.nk_[input] :], "f")
        return np.roots(b) if len(b) > 1 else np.zeros(0)

    @property
    def is_stable(self) -> bool:
        """All poles strictly inside the unit circle."""
        return bool(np.all(np.abs(self.discrete_poles()) < 1.0))

    def dc_gain(self) -> np.ndarray:
        """Static gain from each input, B_i(1) / (A(1) F_i(1)).

        Returns
        -------
        ndarray of shape (n_inputs,)
        """
        out = []
        for i in range(len(self.input_names_)):
            num, den = self.input_transfer(i)
            out.append(num.sum() / den.sum() if den.sum() != 0 else math.copysign(math.inf, num.sum() or 1.0))
        return np.array(out)

    # ------------------------------------------------------------------ prediction
    def predict(self, data: IOData, horizon: int | None = 1, initial: str = "zero") -> np.ndarray:
        """Predicted output; NaN where no prediction exists.

        Parameters
        ----------
        data : IOData
        horizon : int or None
            1: one-step prediction with the noise model; k: k steps ahead; None: free-run
            simulation (MATLAB ``compare``).
        initial : {"zero", "estimate"}
            ``"zero"``: the filters start at rest in each run of finite samples and its first
            ``first_lag_`` samples are not predicted. ``"estimate"``: each run's initial state is
            fitted to these data first (to the prediction errors for a horizon, to the measured
            output for the free run, as MATLAB's ``compare`` does) and every sample is predicted;
            on the estimation data with a horizon this reproduces the fit's ``initial_states_``.

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        self.check_fitted()
        if not isinstance(data, IOData):
            raise DataError(f"predict needs an arxid.IOData, got {type(data).__name__}")
        if horizon is not None and (isinstance(horizon, bool) or check_order("horizon", horizon) < 1):
            raise OrderError("horizon must be >= 1 (or None for free-run simulation)")
        data = complete_inputs(data, self.input_names_, self.derived_inputs)
        if data.n_inputs != len(self.input_names_):
            raise DataError(f"the model has {len(self.input_names_)} inputs but the data have {data.n_inputs}")
        orders = (self.na_, list(self.nb_), self.nc_, self.nd_, list(self.nf_), list(self.nk_))
        estimate = check_initial(initial) == "estimate"
        lag = 0 if estimate else int(_core.pem_max_lag(orders))
        segments = finite_segments(data, lag, need_output=horizon is not None or estimate)
        if not segments:
            return np.full(data.n_samples, np.nan)
        return np.asarray(
            _core.pem_predict(
                np.ascontiguousarray(data.y),
                np.ascontiguousarray(data.u),
                segments,
                orders,
                np.ascontiguousarray(self.parameters_, dtype=float),
                horizon=None if horizon is None else int(horizon),
                initial=initial,
            )
        )

    def simulate(self, u: Any) -> np.ndarray:
        """Free-run response to ``u`` from rest (noise-free).

        Parameters
        ----------
        u : array_like of shape (N,) or (N, n_inputs)

        Returns
        -------
        ndarray of shape (N,)
        """
        self.check_fitted()
        u = np.asarray(u, dtype=float)
        u = u.reshape(-1, 1) if u.ndim == 1 else u
        if u.ndim != 2 or u.shape[1] != len(self.input_names_):
            raise DataError(f"u must have shape (N, {len(self.input_names_)}), got {u.shape}")
        out = np.zeros(u.shape[0])
        for i in range(u.shape[1]):
            num, den = self.input_transfer(i)
            out += lfilter(num, den, u[:, i])
        return out

    # ------------------------------------------------------------------ export
    def to_control(self, continuous: bool = False, input: int | None = None) -> Any:
        """python-control transfer function(s) of the input-to-output part; see :func:`arxid.convert.to_control`.

        Parameters
        ----------
        continuous : bool
            Invert the zero-order-hold sampling; the dead time is in ``.dead_time``.
        input : int, optional
            Only this input's transfer function.

        Returns
        -------
        control.TransferFunction or list of them
        """
        from . import convert

        return convert.to_control(self, continuous=continuous, input=input)

    def to_scipy(self) -> Any:
        """``scipy.signal.dlti`` of the input-to-output part; see :func:`arxid.convert.to_scipy`.

        Returns
        -------
        scipy.signal.dlti
        """
        from . import convert

        return convert.to_scipy(self)

    def to_dict(self) -> dict:
        """Everything needed to rebuild the fitted model (the JSON content).

        Returns
        -------
        dict
        """
        from . import polynomial_files as polyfile

        return polyfile.model_content(self)

    @classmethod
    def from_arx(cls, model: Any) -> PolynomialModel:
        """The same fitted ARX model as a polynomial model (C = D = F = 1), as MATLAB's ``idpoly(sys)``.

        Parameters
        ----------
        model : ArxModel
            A fitted ARX model without effect terms.

        Returns
        -------
        PolynomialModel
            Same parameters, covariance, loss and names; ``iterations_`` 0.
        """
        from . import polynomial_files as polyfile

        return polyfile.model_of(cls, polyfile.arx_content(model))

    @classmethod
    def from_json(cls, text_or_path: str) -> PolynomialModel:
        """Load a model written by :meth:`to_json`.

        Parameters
        ----------
        text_or_path : str
            A JSON string or a file path.

        Returns
        -------
        PolynomialModel
        """
        from . import polynomial_files as polyfile

        return polyfile.model_from_json(cls, text_or_path)

    # ------------------------------------------------------------------ printing
    def structure_name(self) -> str:
        """``OE(nb,nf,nk)``, ``ARMAX(na,nb,nc,nk)``, ``BJ(nb,nc,nd,nf,nk)`` (per-input lists for several inputs).

        Returns
        -------
        str
        """
        fitted = "parameters_" in self.__dict__
        get = (lambda n: getattr(self, n + "_")) if fitted else (lambda n: getattr(self, n))

        def show(v: Any) -> Any:
            t = _as_tuple(v)
            return t[0] if len(set(t)) == 1 else list(t)

        m = len(_as_tuple(get("nb"))) - len(self.derived_inputs)
        nb, nf, nk = (show(_as_tuple(get(n))[:m]) for n in ("nb", "nf", "nk"))
        added = "".join(f" + {e}" for e in self.effects)
        return self._orders_name(nb, nf, nk, get) + added

    def _orders_name(self, nb: Any, nf: Any, nk: Any, get: Any) -> str:
        kind = self.kind
        if kind == "OE":
            return f"OE({nb},{nf},{nk})"
        if kind in ("ARMAX", "ARX"):
            return f"ARMAX({get('na')},{nb},{get('nc')},{nk})"
        if kind == "BJ":
            return f"BJ({nb},{get('nc')},{get('nd')},{nf},{nk})"
        return f"poly({get('na')},{nb},{get('nc')},{get('nd')},{nf},{nk})"

    def __str__(self) -> str:
        if "parameters_" not in self.__dict__:
            return f"{self.structure_name()} (not fitted)"
        lines = [f"Discrete-time {self.kind} model: {_EQUATIONS.get(self.kind, _EQUATIONS['polynomial'])}"]
        lines += self._polynomial_lines()
        lines.append(f"Sample time: {self.ts:g} seconds")
        lines.append(
            f"Fit to estimation data: {self.fit_percent_:.2f}% (one-step prediction), noise variance "
            f"{self.noise_variance_:.4g}, FPE {self.fpe_:.4g}, {self.n_rows_} samples; {self.termination_} "
            f"({self.iterations_} iterations)"
        )
        return "\n".join(lines)

    def parameter_labels(self) -> list[str]:
        """One label per entry of ``parameters_`` (``getpvec`` order): the polynomial, its input
        when it has one, and the power of z, e.g. ``"F(u1) z^-2"``, ``"C z^-1"``.

        Returns
        -------
        list of str
        """
        p, labels = self.polynomials(), []
        for name in _POLY_NAMES:
            polys = p[name] if isinstance(p[name], list) else [p[name]]
            for i, coefs in enumerate(polys):
                first = self.nk_[i] if name == "b" else 1
                tag = f"({self.input_names[i]})" if name in "bf" else ""
                labels += [f"{name.upper()}{tag} z^-{j}" for j in range(first, len(coefs))]
        return labels

    def _polynomial_lines(self) -> list[str]:
        p, m = self.polynomials(), len(self.input_names_)
        se = self.standard_errors_
        lines, at = [], 0
        for name in _POLY_NAMES:
            polys = p[name] if isinstance(p[name], list) else [p[name]]
            for i, coefs in enumerate(polys):
                n_free = len(coefs) - (self.nk_[i] if name == "b" else 1)
                if n_free <= 0:
                    continue
                label = name.upper() + (str(i + 1) if m > 1 and name in "bf" else "")
                lines.append(f"  {label}(z) = {format_polynomial(list(coefs))}")
                errs = se[at : at + n_free]
                lines.append(" " * (len(label) + 9) + "(± " + ", ".join(f"{e:.3g}" for e in errs) + ")")
                at += n_free
        return lines

    def __repr__(self) -> str:
        if "parameters_" not in self.__dict__:
            return f"PolynomialModel({self.structure_name()})"
        return f"<PolynomialModel {self.structure_name()} ts={self.ts:g} fit={self.fit_percent_:.2f}%>"


_EQUATIONS = {
    "OE": "y(t) = [B(z)/F(z)]u(t) + e(t)",
    "ARMAX": "A(z)y(t) = B(z)u(t) + C(z)e(t)",
    "ARX": "A(z)y(t) = B(z)u(t) + e(t)",
    "BJ": "y(t) = [B(z)/F(z)]u(t) + [C(z)/D(z)]e(t)",
    "polynomial": "A(z)y(t) = [B(z)/F(z)]u(t) + [C(z)/D(z)]e(t)",
}


def _as_tuple(v: Any) -> tuple:
    return tuple(v) if isinstance(v, (list, tuple, np.ndarray)) else (v,)


def as_polynomial(model: Any) -> PolynomialModel:
    """``model`` itself when it is a :class:`PolynomialModel`, else :meth:`PolynomialModel.from_arx`.

    Parameters
    ----------
    model : PolynomialModel or ArxModel

    Returns
    -------
    PolynomialModel
    """
    return model if isinstance(model, PolynomialModel) else PolynomialModel.from_arx(model)
