"""ARX models: :func:`arx` fits one, :class:`ArxModel` holds, simulates and exports it."""

from __future__ import annotations

import json
import math
import numbers
from typing import Sequence

import numpy as np

from . import _core
from .data import IOData
from .effects import EffectLayout, compile_effects
from .exceptions import ArxidError, DataError, IdentifiabilityError, NotFittedError, OrderError
from .regressors import dependent_partners, max_lag, regressor_matrix, regressor_names

__all__ = ["ArxModel", "arx"]

_JSON_FORMAT = "arxid.ArxModel"
_JSON_VERSION = 1
# Same bound as the Rust core: larger orders cannot describe sampled data and would overflow lags.
_MAX_ORDER = 2**40


def _order(name: str, value) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise OrderError(f"{name} must be a non-negative integer, got {value!r}")
    if value < 0:
        raise OrderError(f"{name} must be >= 0, got {value}")
    if value > _MAX_ORDER:
        raise OrderError(f"{name} = {value} is too large (at most {_MAX_ORDER}); orders and delays count samples")
    return int(value)


def _per_input(name: str, value, m: int) -> tuple[int, ...]:
    if isinstance(value, (list, tuple, np.ndarray)):
        vals = tuple(_order(f"{name}[{i}]", v) for i, v in enumerate(value))
        if len(vals) != m:
            raise OrderError(f"{name} has {len(vals)} entries but the data have {m} inputs; give one per input or a single integer")
        return vals
    return (_order(name, value),) * m


def _format_poly(coefs: Sequence[float], var: str = "z", start: int = 0) -> str:
    """``1 - 1.959 z^-1 + 0.9567 z^-2`` from coefficients of z^-start, z^-(start+1), ..."""
    parts = []
    for i, c in enumerate(coefs):
        if c == 0 and len(coefs) > 1:
            continue
        p = start + i
        mag = f"{abs(c):.4g}"
        term = mag if p == 0 else (f"{mag} {var}^-{p}" if mag != "1" else f"{var}^-{p}")
        sign = "-" if c < 0 else "+"
        parts.append((sign, term))
    if not parts:
        return "0"
    first_sign, first = parts[0]
    out = ("-" if first_sign == "-" else "") + first
    for sign, term in parts[1:]:
        out += f" {sign} {term}"
    return out


class ArxModel:
    """An ARX model, possibly with effect terms, in MATLAB's sign convention.

    Parameters
    ----------
    na : int
        Number of poles (output lags).
    nb : int or sequence of int
        Number of input coefficients per input.
    nk : int or sequence of int
        Input delay per input in samples; ``nk = 0`` is direct feedthrough.
    effects : sequence of str
        Effect terms (see :mod:`arxid.effects`), fitted together with the ARX part.

    Notes
    -----
    .. math::

        y(t) + a_1 y(t-1) + \\dots + a_{n_a} y(t-n_a) =
        \\sum_i \\sum_{j=1}^{n_{b,i}} b_{ij} u_i(t-n_{k,i}-j+1) + \\sum_l c_l z_l(t) + e(t)

    Fitted attributes end in an underscore (``parameters_``, ``covariance_``, ...). Parameter order:
    the a's, each input's b's, then the effect terms.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(500)
    >>> y = np.zeros(500)
    >>> for t in range(2, 500):
    ...     y[t] = 0.8 * y[t - 1] + 0.5 * u[t - 2]
    >>> m = arxid.arx(arxid.IOData(y, u, ts=0.1), na=1, nb=1, nk=2)
    >>> np.round(m.parameters_, 6)
    array([-0.8,  0.5])
    """

    def __init__(self, *, na: int, nb, nk, effects: Sequence[str] = ()):
        self.na = na
        self.nb = nb
        self.nk = nk
        self.effects = tuple(effects)

    # ------------------------------------------------------------------ fitting
    def fit(self, data: IOData, *, first_lag: int = 0, n_threads: int = 0, rows_like=None) -> "ArxModel":
        """Least squares by Householder QR in the Rust core. Returns ``self``.

        ``first_lag`` starts the regression rows that far into each experiment (at least the
        model's own largest lag); sweeps use it to compare structures on the same rows.
        ``rows_like = (na, nb, nk)``, orders per column of the effect layout, also leaves out the
        rows where that larger structure's regressors touch a NaN (a sweep passes its grid's
        envelope, so that on data with NaN the refit uses exactly the sweep's rows).
        """
        if not isinstance(data, IOData):
            raise DataError(f"fit needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)")
        m = data.n_inputs
        na = _order("na", self.na)
        nb = _per_input("nb", self.nb, m)
        nk = _per_input("nk", self.nk, m)
        first_lag = _order("first_lag", first_lag)
        layout = compile_effects(self.effects, data, nb, nk)
        # Counted, not listed: orders far beyond the data must fail here, not while naming 10^12 regressors.
        p = na + sum(layout.nb) + len(layout.output_terms)
        if p == 0:
            raise OrderError("the model has no parameters: use na >= 1 or nb >= 1")
        lag = max(first_lag, max_lag(na, layout))
        usable = sum(max(0, b - a - lag) for a, b in data.segments)
        if usable < p + 1:
            raise DataError(
                f"too few samples for the orders: {p} parameters need at least {p + 1} regression rows, "
                f"but {data.n_samples} samples minus the largest lag {lag} per experiment leave {usable}; "
                f"lower na/nb/nk or use more data"
            )
        names = regressor_names(data.output_name, na, layout)
        for i in range(m):
            if nb[i] > 0:
                x = data.u[:, i]
                x = x[np.isfinite(x)]
                if x.size == 0 or np.ptp(x) == 0:
                    raise IdentifiabilityError(
                        f"input {data.input_names[i]!r} is constant ({x[0] if x.size else 'NaN'}): it does not excite the "
                        f"system, so its coefficients cannot be identified; use data where it varies, or set nb=0 for it",
                        (data.input_names[i],),
                    )
        y = np.ascontiguousarray(data.y)
        try:
            res = _core.fit(y, layout.u, list(data.experiment_starts), na, list(layout.nb), list(layout.nk),
                            list(layout.output_terms), first_lag=first_lag, n_threads=_order("n_threads", n_threads),
                            rows_like=rows_like)
        except IdentifiabilityError as exc:
            col = getattr(exc, "column", None)
            if col is None:
                raise
            phi, _, _ = regressor_matrix(data, na, layout, first_lag)
            partners = dependent_partners(phi, col, names)
            raise IdentifiabilityError(
                f"regressor {names[col]} is a linear combination of {', '.join(partners) or 'the regressors before it'} "
                f"on these data (collinear regressors): remove one of them, lower the orders, or use data that excite them "
                f"independently",
                tuple(partners) + (names[col],),
            ) from None
        n, theta = int(res["n_rows"]), np.asarray(res["theta"])
        rss = float(res["rss"])
        self.na, self.nb, self.nk = na, nb, nk
        self.ts = data.ts
        self.output_name = data.output_name
        self.input_names = data.input_names
        self.output_unit = data.output_unit
        self.input_units = data.input_units
        self.parameters_ = theta
        self.regressor_names_ = tuple(names)
        self.n_rows_ = n
        self.n_skipped_ = int(res["n_skipped"])
        self.first_lag_ = first_lag
        self.rss_ = rss
        dof = max(n - p, 1)
        self.noise_variance_ = rss / dof
        self.covariance_ = self.noise_variance_ * np.asarray(res["inv_gram"])
        self.loss_ = rss / n
        self._layout_meta = (layout.nb, layout.nk, layout.output_terms)
        self._data = data
        pred = self.predict(data, horizon=1)
        self.fit_percent_ = self._fit_percent(data.y, pred)
        return self

    def _check_fitted(self):
        if not hasattr(self, "parameters_"):
            raise NotFittedError("this ArxModel is not fitted yet: call .fit(data) or use arxid.arx(data, na, nb, nk)")

    def __getattr__(self, name):
        if name.endswith("_") and not name.startswith("__"):
            raise NotFittedError(f"{name} is not available: this ArxModel is not fitted yet; call .fit(data) first")
        raise AttributeError(name)

    # ------------------------------------------------------------------ statistics
    @property
    def n_params(self) -> int:
        self._check_fitted()
        return len(self.parameters_)

    @property
    def standard_errors_(self) -> np.ndarray:
        """Standard error of each parameter, √diag(covariance)."""
        self._check_fitted()
        return np.sqrt(np.diag(self.covariance_))

    @property
    def fpe_(self) -> float:
        """Akaike's final prediction error, loss · (1 + p/N) / (1 − p/N)."""
        n, p = self.n_rows_, self.n_params
        return self.loss_ * (n + p) / max(n - p, 1)

    @property
    def aic_(self) -> float:
        """AIC as MATLAB computes it: N log(loss) + 2p + N (log 2π + 1)."""
        n, p = self.n_rows_, self.n_params
        return n * math.log(self.loss_) + 2 * p + n * (math.log(2 * math.pi) + 1) if self.loss_ > 0 else -math.inf

    @property
    def bic_(self) -> float:
        """BIC: N log(loss) + p log N + N (log 2π + 1)."""
        n, p = self.n_rows_, self.n_params
        return n * math.log(self.loss_) + p * math.log(n) + n * (math.log(2 * math.pi) + 1) if self.loss_ > 0 else -math.inf

    # ------------------------------------------------------------------ polynomials
    @property
    def a(self) -> np.ndarray:
        """Denominator A(z⁻¹) = [1, a1, ..., a_na]."""
        self._check_fitted()
        return np.concatenate([[1.0], self.parameters_[: self.na]])

    @property
    def b(self) -> list[np.ndarray]:
        """Numerators B_i(z⁻¹) per input, with ``nk`` leading zeros (MATLAB's layout)."""
        self._check_fitted()
        out, c = [], self.na
        for nb, nk in zip(self.nb, self.nk):
            out.append(np.concatenate([np.zeros(nk), self.parameters_[c:c + nb]]))
            c += nb
        return out

    @property
    def effect_parameters(self) -> dict[str, np.ndarray]:
        """Coefficients of each effect term, by effect name."""
        self._check_fitted()
        nb, _, terms = self._layout_meta
        m = len(self.input_names)
        out, c = {}, self.na + sum(self.nb)
        layout = self._layout(self._data) if self._data is not None else None
        labels = layout.effect_of_column[m:] if layout else [e for e in self.effects]
        for j, b in enumerate(nb[m:]):
            name = labels[j] if j < len(labels) else None
            if name is not None:
                out[name] = self.parameters_[c:c + b]
            c += b
        effect_terms = layout.effect_of_term if layout else ()
        for j in range(len(terms)):
            out[effect_terms[j] if effect_terms else f"term{j}"] = self.parameters_[c:c + 1]
            c += 1
        return out

    @property
    def is_linear(self) -> bool:
        """True without output-derived effects (those have no transfer function)."""
        return not self._layout_meta[2]

    def poles(self) -> np.ndarray:
        """Roots of z^na A(z⁻¹)."""
        return np.roots(self.a) if self.na else np.zeros(0)

    def zeros(self, input: int = 0) -> np.ndarray:
        """Roots of the numerator of ``input`` (delays excluded)."""
        b = self.b[input][self.nk[input]:]
        b = np.trim_zeros(b, "f")
        return np.roots(b) if len(b) > 1 else np.zeros(0)

    @property
    def is_stable(self) -> bool:
        """All poles strictly inside the unit circle."""
        return bool(np.all(np.abs(self.poles()) < 1.0))

    def dc_gain(self) -> np.ndarray:
        """Static gain from each input, B_i(1)/A(1) (inf for an integrator)."""
        a1 = self.a.sum()
        with np.errstate(divide="ignore"):
            return np.array([b.sum() / a1 if a1 != 0 else math.copysign(math.inf, b.sum() or 1.0) for b in self.b])

    # ------------------------------------------------------------------ simulation
    def _layout(self, data: IOData) -> EffectLayout:
        if data.n_inputs != len(self.input_names):
            raise DataError(f"the model has {len(self.input_names)} inputs {list(self.input_names)} but the data have {data.n_inputs}")
        return compile_effects(self.effects, data, self.nb, self.nk)

    def predict(self, data: IOData, horizon: int | None = None) -> np.ndarray:
        """Predicted output, shape (n_samples,), NaN where no prediction exists (initial samples).

        Parameters
        ----------
        data : IOData
        horizon : int or None
            1: one-step prediction; k: k-step-ahead; None: free-run simulation (MATLAB ``compare``).
            Output-derived effect terms use the simulated output beyond the first step.
        """
        self._check_fitted()
        if not isinstance(data, IOData):
            raise DataError(f"predict needs an arxid.IOData, got {type(data).__name__}")
        if horizon is not None:
            horizon = _order("horizon", horizon)
            if horizon < 1:
                raise OrderError("horizon must be >= 1 (or None for free-run simulation)")
        layout = self._layout(data)
        return np.asarray(_core.predict(np.ascontiguousarray(data.y), layout.u, list(data.experiment_starts), self.na,
                                        list(layout.nb), list(layout.nk), list(layout.output_terms),
                                        np.ascontiguousarray(self.parameters_, dtype=float), horizon=horizon))

    @staticmethod
    def _diverged(y: np.ndarray, pred: np.ndarray) -> bool:
        """A simulation that overflowed: the core lets inf (then NaN) propagate instead of restarting."""
        return bool(np.isinf(pred).any())

    @staticmethod
    def _fit_percent(y: np.ndarray, pred: np.ndarray) -> float:
        if ArxModel._diverged(y, pred):
            return -math.inf
        ok = np.isfinite(y) & np.isfinite(pred)
        if not ok.any():
            return math.nan
        with np.errstate(over="ignore", invalid="ignore"):
            e = np.linalg.norm(y[ok] - pred[ok])
        d = np.linalg.norm(y[ok] - y[ok].mean())
        return float(100.0 * (1.0 - e / d)) if d > 0 else math.nan

    def fit_percent(self, data: IOData, horizon: int | None = None) -> float:
        """NRMSE fit in percent, 100 (1 − ‖y − ŷ‖ / ‖y − mean y‖), of the prediction with ``horizon``
        (``-inf`` when a free-run simulation diverges)."""
        return self._fit_percent(data.y, self.predict(data, horizon))

    def rms(self, data: IOData, horizon: int | None = None) -> float:
        """Root mean square of measured − predicted output over the predicted samples (``inf`` when a
        free-run simulation diverges)."""
        pred = self.predict(data, horizon)
        if self._diverged(data.y, pred):
            return math.inf
        ok = np.isfinite(pred) & np.isfinite(data.y)
        if not ok.any():
            return math.nan
        with np.errstate(over="ignore", invalid="ignore"):
            return float(np.sqrt(np.mean((data.y[ok] - pred[ok]) ** 2)))

    def simulate(self, u, initial=None, extra=None) -> np.ndarray:
        """Free-run response to the inputs ``u`` (shape (N,) or (N, n_inputs)).

        Parameters
        ----------
        u : array_like
        initial : array_like, optional
            Outputs before the first sample, oldest first (default zeros: the system at rest).
        extra : mapping, optional
            Extra signals effect terms need (same length as ``u``).
        """
        self._check_fitted()
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u.reshape(-1, 1)
        nb, nk, terms = self._layout_meta
        lag = max(self.na, max((b + k - 1 for b, k in zip(nb, nk) if b > 0), default=0), 2 if terms else 0)
        init = np.zeros(lag) if initial is None else np.asarray(initial, dtype=float)
        if init.shape != (lag,):
            raise DataError(f"initial must hold the {lag} outputs before the first sample, got shape {init.shape}")
        pad_u = np.vstack([np.zeros((lag, u.shape[1])), u])
        pad_extra = {k: np.concatenate([np.zeros(lag), np.asarray(v, dtype=float)]) for k, v in (extra or {}).items()}
        y = np.concatenate([init, np.zeros(len(u))])
        d = IOData(y, pad_u, self.ts, output_name=self.output_name, input_names=self.input_names, extra=pad_extra)
        return self.predict(d, None)[lag:]

    def step(self, n_samples: int, amplitude: float = 1.0, input: int = 0) -> np.ndarray:
        """Response to a step of ``amplitude`` on ``input`` from rest, shape (n_samples,)."""
        self._check_fitted()
        u = np.zeros((_order("n_samples", n_samples), len(self.input_names)))
        u[:, input] = amplitude
        return self.simulate(u)

    # ------------------------------------------------------------------ refit
    def with_effects(self, effects: Sequence[str], data: IOData | None = None) -> "ArxModel":
        """The same orders refitted with ``effects`` added, on ``data`` (default: the estimation data)."""
        self._check_fitted()
        data = data if data is not None else self._data
        if data is None:
            raise ArxidError("this model was loaded without its data: pass data=... to refit it with effects")
        new = [e for e in effects if e not in self.effects]
        return ArxModel(na=self.na, nb=self.nb, nk=self.nk, effects=self.effects + tuple(new)).fit(data, first_lag=self.first_lag_)

    # ------------------------------------------------------------------ export
    def _tf_coefficients(self):
        """(numerators, denominator) in descending powers of z, all of one length."""
        if not self.is_linear:
            raise ArxidError(f"the effects {list(self.effects)} involve the output: the model is nonlinear and has no transfer function")
        nb, nk, _ = self._layout_meta
        num_z1 = []
        c = self.na
        for b, k in zip(nb, nk):
            num_z1.append(np.concatenate([np.zeros(k), self.parameters_[c:c + b]]))
            c += b
        n = max([self.na] + [len(x) - 1 for x in num_z1])
        den = np.zeros(n + 1)
        den[: self.na + 1] = self.a
        nums = []
        for x in num_z1:
            v = np.zeros(n + 1)
            v[: len(x)] = x
            nums.append(v)
        return nums, den

    def _input_labels(self):
        m = len(self.input_names)
        labels = list(self.input_names)
        if self._data is not None:
            layout = self._layout(self._data)
            labels += [lab for lab, b in zip(layout.column_labels[m:], layout.nb[m:])]
        nb = self._layout_meta[0]
        return labels + [f"effect{j}" for j in range(len(labels), len(nb))]

    def to_control(self, continuous: bool = False, input: int | None = None):
        """python-control transfer function with ``dt = ts`` (descending powers of z).

        One input gives a ``TransferFunction``; several inputs (including input-derived effect
        columns) a list with one SISO ``TransferFunction`` per input (MIMO conversions in
        python-control need slycot), or the one picked with ``input``. With ``continuous=True`` the
        zero-order-hold sampling is inverted (matrix logarithm); the input delay of
        ``(nk − 1)·ts`` that ZOH sampling of a strictly proper system does not explain is returned in
        the attribute ``dead_time`` of the result (seconds).
        """
        self._check_fitted()
        try:
            import control
        except ImportError:  # pragma: no cover
            raise ImportError("to_control needs python-control: pip install 'arxid[control]'") from None
        nums, den = self._tf_coefficients()
        labels = self._input_labels()
        idx = range(len(nums)) if input is None else [input]
        if continuous:
            return _d2c(self, [nums[i] for i in idx], den, [self._layout_meta[1][i] for i in idx], [labels[i] for i in idx])
        tfs = [control.TransferFunction(nums[i], den, self.ts, inputs=[labels[i]], outputs=[self.output_name]) for i in idx]
        return tfs[0] if len(tfs) == 1 else tfs

    def to_scipy(self):
        """``scipy.signal.dlti``: a transfer function for one input, a state-space model for several."""
        from scipy import signal

        nums, den = self._tf_coefficients()
        if len(nums) == 1:
            # Leading zeros of the numerator are the delay; scipy warns about them, so drop them.
            num = np.trim_zeros(nums[0], "f")
            return signal.dlti(num if len(num) else [0.0], den, dt=self.ts)
        # Observable canonical form shares A and C across inputs.
        n = len(den) - 1
        a = np.zeros((n, n))
        a[:, 0] = -den[1:]
        a[: n - 1, 1:] = np.eye(n - 1)
        b = np.column_stack([num[1:] - num[0] * den[1:] for num in nums])
        c = np.zeros((1, n))
        c[0, 0] = 1.0
        dmat = np.array([[num[0] for num in nums]])
        return signal.dlti(a, b, c, dmat, dt=self.ts)

    def to_dict(self) -> dict:
        self._check_fitted()
        nb, nk, terms = self._layout_meta
        return {
            "format": _JSON_FORMAT,
            "version": _JSON_VERSION,
            "na": self.na,
            "nb": list(self.nb),
            "nk": list(self.nk),
            "effects": list(self.effects),
            "ts": self.ts,
            "output_name": self.output_name,
            "input_names": list(self.input_names),
            "output_unit": self.output_unit,
            "input_units": list(self.input_units),
            "parameters": [float(x) for x in self.parameters_],
            "covariance": [[float(x) for x in row] for row in self.covariance_],
            "regressor_names": list(self.regressor_names_),
            "n_rows": self.n_rows_,
            "n_skipped": self.n_skipped_,
            "first_lag": self.first_lag_,
            "rss": self.rss_,
            "fit_percent": self.fit_percent_,
            "layout": {"nb": list(nb), "nk": list(nk), "output_terms": [list(t) for t in terms]},
        }

    def to_json(self, path=None, indent: int | None = 2) -> str:
        """Plain JSON (no pickle); floats round-trip exactly. Writes to ``path`` when given."""
        text = json.dumps(self.to_dict(), indent=indent, allow_nan=True)
        if path is not None:
            with open(path, "w") as fh:
                fh.write(text)
        return text

    @classmethod
    def from_json(cls, text_or_path) -> "ArxModel":
        """Load a model written by :meth:`to_json` (a JSON string or a file path)."""
        text = text_or_path
        if not (isinstance(text, str) and text.lstrip().startswith("{")):
            try:
                with open(text_or_path) as fh:
                    text = fh.read()
            except OSError as exc:
                raise DataError(f"cannot read model file {text_or_path!r}: {exc}") from None
        try:
            d = json.loads(text)
            if not isinstance(d, dict) or d.get("format") != _JSON_FORMAT:
                raise ValueError(f"not an arxid model (format {d.get('format') if isinstance(d, dict) else type(d).__name__!r})")
            if d.get("version") != _JSON_VERSION:
                raise ValueError(f"unsupported version {d.get('version')!r}")
            model = cls(na=d["na"], nb=tuple(d["nb"]), nk=tuple(d["nk"]), effects=tuple(d["effects"]))
            model.na = _order("na", d["na"])
            model.nb = tuple(_order("nb", v) for v in d["nb"])
            model.nk = tuple(_order("nk", v) for v in d["nk"])
            model.ts = float(d["ts"])
            model.output_name = str(d["output_name"])
            model.input_names = tuple(map(str, d["input_names"]))
            model.output_unit = str(d.get("output_unit", ""))
            model.input_units = tuple(d.get("input_units", ("",) * len(model.input_names)))
            model.parameters_ = np.array(d["parameters"], dtype=float)
            model.covariance_ = np.array(d["covariance"], dtype=float).reshape(len(model.parameters_), len(model.parameters_))
            model.regressor_names_ = tuple(d["regressor_names"])
            model.n_rows_ = int(d["n_rows"])
            model.n_skipped_ = int(d["n_skipped"])
            model.first_lag_ = int(d["first_lag"])
            model.rss_ = float(d["rss"])
            model.fit_percent_ = float(d["fit_percent"])
            p = len(model.parameters_)
            model.noise_variance_ = model.rss_ / max(model.n_rows_ - p, 1)
            model.loss_ = model.rss_ / model.n_rows_
            lay = d["layout"]
            model._layout_meta = (tuple(lay["nb"]), tuple(lay["nk"]), tuple(tuple(t) for t in lay["output_terms"]))
            model._data = None
            if len(model.nb) != len(model.input_names) or len(model.regressor_names_) != p:
                raise ValueError("orders, inputs and parameters do not agree")
            if p != model.na + sum(model._layout_meta[0]) + len(model._layout_meta[2]):
                raise ValueError("the parameter count does not match the model structure")
        except DataError:
            raise
        except (ValueError, KeyError, TypeError, json.JSONDecodeError, OrderError) as exc:
            raise DataError(f"corrupt model file: {exc}; write models with ArxModel.to_json()") from None
        return model

    # ------------------------------------------------------------------ printing
    def structure_name(self) -> str:
        nb = self.nb[0] if len(set(self.nb)) == 1 else list(self.nb)
        nk = self.nk[0] if len(set(self.nk)) == 1 else list(self.nk)
        s = f"ARX({self.na},{nb},{nk})"
        return s + (" + " + " + ".join(self.effects) if self.effects else "")

    def __str__(self) -> str:
        if not hasattr(self, "parameters_"):
            return f"ArxModel(na={self.na}, nb={self.nb}, nk={self.nk}, effects={list(self.effects)}) (not fitted)"
        den = _format_poly(self.a)
        lines = [f"{self.structure_name()}   ts = {self.ts:g} s"]
        out = self.output_name + (f" [{self.output_unit}]" if self.output_unit else "")
        nb, nk, terms = self._layout_meta
        labels = self._input_labels()
        c = self.na
        for j, (b, k) in enumerate(zip(nb, nk)):
            if b == 0:
                continue
            coefs = self.parameters_[c:c + b]
            c += b
            num = _format_poly(coefs) if b > 1 else f"{coefs[0]:.4g}"
            delay = f" z^-{k}" if k else ""
            width = max(len(num), len(den))
            # Seed 004 eq. (29): y(z) = B(z)/A(z) u(z) z^-nk, one fraction per input or effect column.
            lhs = f"{self.output_name}(z) = "
            pad = " " * len(lhs)
            lines.append(pad + num.center(width))
            lines.append((lhs if j == 0 else pad[:-2] + "+ ") + "-" * width + f" {labels[j]}(z){delay}")
            lines.append(pad + den.center(width))
        for kind, power, mult in terms:
            coef = self.parameters_[c]
            c += 1
            lines.append(f"      {'+' if coef >= 0 else '-'} {abs(coef):.4g}/A(z) · {self._term_text(kind, power, mult)}")
        lines.append(
            f"  fit {self.fit_percent_:.2f}% (one-step, estimation), noise variance {self.noise_variance_:.4g}, "
            f"FPE {self.fpe_:.4g}, {self.n_rows_} rows" + (f", {self.n_skipped_} rows skipped (NaN)" if self.n_skipped_ else "")
        )
        if out != self.output_name:
            lines.append(f"  output unit: {self.output_unit}")
        return "\n".join(lines)

    def _term_text(self, kind, power, mult) -> str:
        g = {"pow": f"{self.output_name}(t-1)^{power}" if power != 1 else f"{self.output_name}(t-1)",
             "abs": f"|{self.output_name}(t-1)|", "signdiff": f"sign(d{self.output_name}(t-1))"}[kind]
        return g + (" · carrier(t-1)" if mult >= 0 else "")

    def __repr__(self) -> str:
        if not hasattr(self, "parameters_"):
            return f"ArxModel(na={self.na}, nb={self.nb}, nk={self.nk}, effects={list(self.effects)})"
        return f"<ArxModel {self.structure_name()} ts={self.ts:g} fit={self.fit_percent_:.2f}%>"


def _d2c(model: ArxModel, nums, den, nks, labels):
    """Continuous-time model whose ZOH sampling is the discrete model (input delays split off)."""
    import control
    from scipy.linalg import logm

    results = []
    for num, nk, label in zip(nums, nks, labels):
        # Pure delay beyond the one sample ZOH sampling of a strictly proper system implies.
        shift = max(nk - 1, 0)
        n = np.trim_zeros(num, "f")
        n = np.concatenate([np.zeros(len(num) - len(n) - shift), n]) if shift else num
        n = np.concatenate([n, np.zeros(len(num) - len(n))])[: len(num)]
        dd = np.trim_zeros(den, "b")
        trimmed = len(den) - len(dd)
        n = n[: len(n) - trimmed] if trimmed else n
        # Remove common trailing zeros (poles and zeros at the origin) from both.
        while len(dd) > 1 and dd[-1] == 0 and n[-1] == 0:
            dd, n = dd[:-1], n[:-1]
        if len(dd) > 1 and dd[-1] == 0:
            raise ArxidError("the model has a pole at z = 0 that cannot be a zero-order-hold sample of a continuous system")
        sys_d = control.tf2ss(control.TransferFunction(n, dd, model.ts))
        a, b, c, d = (np.asarray(x) for x in (sys_d.A, sys_d.B, sys_d.C, sys_d.D))
        k = a.shape[0]
        big = np.zeros((k + 1, k + 1))
        big[:k, :k], big[:k, k:] = a, b
        big[k, k] = 1.0
        with np.errstate(all="ignore"):
            lg = logm(big)
        if np.iscomplexobj(lg):
            if np.max(np.abs(lg.imag)) > 1e-8 * max(1.0, np.max(np.abs(lg.real))):
                raise ArxidError("the model has poles on the negative real axis: it is not the zero-order-hold sample of a real continuous system")
            lg = lg.real
        lg = lg / model.ts
        sys_c = control.ss(lg[:k, :k], lg[:k, k:], c, d)
        tf_c = control.ss2tf(sys_c)
        tf_c = control.TransferFunction(tf_c.num[0][0], tf_c.den[0][0], inputs=[label], outputs=[model.output_name])
        tf_c.dead_time = shift * model.ts
        results.append(tf_c)
    return results[0] if len(results) == 1 else results


def arx(data: IOData, na: int, nb, nk, effects: Sequence[str] = (), *, n_threads: int = 0) -> ArxModel:
    """Fit an ARX model (optionally with effect terms) by Householder QR.

    Parameters
    ----------
    data : IOData
    na : int
        Number of poles.
    nb, nk : int or sequence of int
        Input orders and delays (one per input, or one for all). ``nk = 0`` is direct feedthrough.
    effects : sequence of str
        Extra physical terms, e.g. ``["u1^2", "u1*vbat", "y^3", "sign(dy)", "const"]``.
    n_threads : int
        Threads for the QR reduction (0 = all).

    Returns
    -------
    ArxModel

    Raises
    ------
    DataError, OrderError, IdentifiabilityError
    """
    return ArxModel(na=na, nb=nb, nk=nk, effects=effects).fit(data, n_threads=n_threads)
