"""ARX models: :func:`arx` fits one, :class:`ArxModel` holds, simulates and exports it."""

from __future__ import annotations

import functools
import math
import types
from collections.abc import Mapping, Sequence
from importlib import import_module
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from .._base import _core, metrics
from .._base.limits import check_order, check_work
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, NotFittedError, OrderError
from .arx_solver import check_rows, check_size, checked_solution, per_input, solve_factor
from .effects import EffectLayout, compile_effects, effect_names
from .envelope import EnvelopeFactor
from .fitted import FittedModel
from .fitted_layout import FittedLayout
from .regressors import max_lag, regressor_names

if TYPE_CHECKING:  # the logs of a fleet: imported when a list of logs is fitted
    from .many_logs import FactorSource

__all__ = ["ArxModel", "FittedLayout", "arx"]


class ArxModel(FittedModel):
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

    data_: IOData | None
    # The sweep that chose this structure (an arxid.selection.search.Selection, set by
    # SweepResult.model); a model knows nothing of sweeps, so its type is not named here.
    selection_: Any

    def __init__(self, *, na: int, nb, nk, effects: Sequence[str] = ()):
        self.na, self.nb, self.nk = na, nb, nk
        self.effects = effect_names(effects)

    # ------------------------------------------------------------------ fitting
    def fit(
        self,
        data: IOData | Sequence[Any],
        *,
        first_lag: int = 0,
        n_threads: int = 0,
        rows_like: tuple[int, Sequence[int], Sequence[int]] | None = None,
        client: Any = None,
        read: Any = None,
    ) -> ArxModel:
        """Least squares by Householder QR in the Rust core.

        Parameters
        ----------
        data : IOData, or list of IOData or file paths
            Estimation data. A list of logs is fitted as one data set with one experiment per log
            (see :func:`arxid.data.logs.merge_logs` and :mod:`arxid.fleet.fit`).
        first_lag : int
            Start the regression rows this far into each experiment (at least the model's own
            largest lag); sweeps use it to compare structures on the same rows.
        n_threads : int
            Threads for the QR reduction (0 = all cores).
        rows_like : (na, nb, nk), optional
            Orders per column of the effect layout of a larger structure: rows where its
            regressors touch a NaN are left out too (a sweep passes its grid's envelope, so that
            on data with NaN the refit uses exactly the sweep's rows).
        client : dask.distributed.Client, optional
            With a list of logs: fit on this Dask cluster, each worker reducing its own logs to a
            triangular factor (:mod:`arxid.fleet.fit`); the model then keeps no ``data_``.
        read : dict or callable, optional
            With file paths: how to read them (see :func:`arxid.data.logs.load_experiment`).

        Returns
        -------
        ArxModel
            ``self``, fitted.
        """
        if isinstance(data, (list, tuple)):
            if client is not None:
                logs = import_module("arxid.models.many_logs").logs_fitting("client=").cluster_logs(client, data, read)
                return self._fit_cluster(logs, first_lag, rows_like)
            data = import_module("arxid.data.logs").merge_logs(data, read)  # imported for a list of logs only
        elif client is not None:
            raise DataError("client= fits a list of logs: pass a list of IOData objects or file paths")
        if not isinstance(data, IOData):
            raise DataError(
                f"fit needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)"
            )
        orders, layout, names, res = checked_solution(self, data, first_lag, n_threads, rows_like)
        self._store(data, orders, layout, names, check_order("first_lag", first_lag), res)
        return self

    def _fit_cluster(self, logs: FactorSource, first_lag: int, rows_like: Any) -> ArxModel:
        """The fit of logs kept on a Dask cluster, solved from their combined factor."""
        if first_lag or rows_like is not None:
            raise ArxidError("first_lag and rows_like are not available with client=; fit the merged IOData instead")
        sig = logs.signals
        m = len(sig.input_names)
        na, nb, nk = check_order("na", self.na), per_input("nb", self.nb, m), per_input("nk", self.nk, m)
        r, n_rows, usable, layout, n_samples = logs.factor(na, nb, nk, self.effects)
        check_rows(na, layout, usable, n_samples, max_lag(na, layout))
        names = regressor_names(sig.output_name, na, layout)
        res = solve_factor(r, n_rows, usable, na, layout, names)
        self._store(sig, (na, nb, nk), layout, names, 0, res, fit_percent=logs.fit_percent)
        return self

    def fit_from_factor(
        self,
        data: IOData,
        r: np.ndarray,
        n_rows: int,
        envelope: tuple[int, Sequence[int], Sequence[int]],
        first_lag: int,
    ) -> ArxModel:
        """The fit from the triangular factor ``r`` of a larger linear structure's ``[Φ | y]`` on
        ``data`` (a sweep's estimation factor: ``envelope`` its (na, nb, nk), ``n_rows`` its rows from
        ``first_lag``): the sweep's numbers (to rounding, the refit on its rows), no pass over the data.

        Parameters
        ----------
        data : IOData
        r : ndarray of shape (q, q)
        n_rows, first_lag : int
        envelope : (na, nb, nk)

        Returns
        -------
        ArxModel
            ``self``, fitted.
        """
        if self.effects:
            raise ArxidError("a fit from a linear factor has no effect columns; fit the data")
        m = data.n_inputs
        na, nb, nk = check_order("na", self.na), per_input("nb", self.nb, m), per_input("nk", self.nk, m)
        layout = compile_effects((), data, nb, nk)
        _, usable = check_size(na, layout, data, first_lag)
        out = _core.fit_from_factor(r, n_rows, envelope, (na, list(nb), list(nk)), [])
        res = types.SimpleNamespace(theta=out.theta, rss=out.rss, n_rows=n_rows, n_skipped=usable - n_rows)
        res.inv_gram = out.inv_gram
        self._store(data, (na, nb, nk), layout, regressor_names(data.output_name, na, layout), first_lag, res)
        return self

    def fit_in(self, envelope: EnvelopeFactor, i: int) -> ArxModel:
        """Fit as structure ``i`` of ``envelope``, from its shared factor (the model's orders and
        effects are the structure's): the fit on the envelope's rows without another pass over the data.

        Parameters
        ----------
        envelope : EnvelopeFactor
            The factor of the structures' envelope (:mod:`arxid.models.envelope`).
        i : int
            Which of its structures this model is.

        Returns
        -------
        ArxModel
            ``self``, fitted with ``first_lag_`` the envelope's first row.
        """
        na, nb, nk, effects = envelope.structures[i]
        mine = (self.na, tuple(np.atleast_1d(self.nb)), tuple(np.atleast_1d(self.nk)), tuple(self.effects))
        if mine != (na, nb, nk, effects):
            raise ArxidError(f"{self.structure_name()} is not structure {i} of the envelope")
        layout, names, res = envelope.solve(i)
        self._store(envelope.data, (na, nb, nk), layout, names, envelope.first_lag, res)
        return self

    def _store(
        self,
        data: Any,
        orders: tuple,
        layout: EffectLayout,
        names: list[str],
        first_lag: int,
        res: Any,
        fit_percent: Any = None,
    ) -> None:
        """Fitted state from the core's result (constructor arguments stay as given). ``data`` is the
        IOData, or the signals of logs kept elsewhere, with ``fit_percent`` computing the fit there."""
        self.na_, self.nb_, self.nk_ = orders
        self.ts_ = data.ts
        self.output_name_, self.input_names_ = data.output_name, data.input_names
        self.output_unit_, self.input_units_ = data.output_unit, data.input_units
        self.layout_ = FittedLayout.of(layout)
        self.parameters_ = np.asarray(res.theta)
        self.regressor_names_ = tuple(names)
        self.n_rows_ = int(res.n_rows)
        self.n_skipped_ = int(res.n_skipped)
        self.first_lag_ = first_lag
        self.rss_ = float(res.rss)
        # made when first read (a diagnosis's refits, a few hundred, are read for their loss only)
        self.__dict__.pop("covariance_", None)
        self._covariance_of = (res.inv_gram, self.rss_, self.n_rows_)
        self.data_ = data if isinstance(data, IOData) else None
        if fit_percent is not None:
            self.fit_percent_ = fit_percent(self)
        else:  # a pass over the data: made when first read (refits in a diagnosis never read it)
            self.__dict__.pop("fit_percent_", None)

    def check_fitted(self) -> None:
        """Raise :class:`NotFittedError` unless the model is fitted (or loaded from JSON).

        Returns
        -------
        None
        """
        if "parameters_" not in self.__dict__:
            raise NotFittedError("this ArxModel is not fitted yet: call .fit(data) or use arxid.arx(data, na, nb, nk)")

    def __getattr__(self, name: str) -> Any:
        # A property of the class (``a``, ``b``) that needs the fitted state raised NotFittedError,
        # an AttributeError, so Python asked here: say why instead of "no attribute 'a'".
        if hasattr(type(self), name):
            self.check_fitted()
        parts = self.__dict__.get("_covariance_of") if name == "covariance_" else None
        if parts is not None:  # (two threads that ask at once make the same)
            covariance = self.covariance_ = metrics.parameter_covariance(*parts)
            self.__dict__.pop("_covariance_of", None)
            return covariance
        if name == "fit_percent_" and "parameters_" in self.__dict__ and self.__dict__.get("data_") is not None:
            data = self.__dict__["data_"]
            self.fit_percent_ = metrics.fit_percent(data.y, self.predict(data, horizon=1))
            return self.fit_percent_
        if name.endswith("_") and not name.startswith("__"):
            raise NotFittedError(f"{name} is not available: this ArxModel is not fitted yet; call .fit(data) first")
        raise AttributeError(name)

    # ------------------------------------------------------------------ polynomials
    # (names, units, loss, criteria, fit_percent, rms and to_json come from FittedModel)
    @property
    def a(self) -> np.ndarray:
        """Denominator A(z⁻¹) = [1, a1, ..., a_na]."""
        self.check_fitted()
        return np.concatenate([[1.0], self.parameters_[: self.na_]])

    @property
    def b(self) -> list[np.ndarray]:
        """Numerators B_i(z⁻¹) per input, with ``nk`` leading zeros (MATLAB's layout)."""
        return self.layout_numerators()[: len(self.input_names_)]

    def layout_numerators(self) -> list[np.ndarray]:
        """Numerators of every column of the effect layout (inputs, then input-derived effects),
        with their delays as leading zeros.

        Returns
        -------
        list of ndarray
        """
        self.check_fitted()
        out, c = [], self.na_
        for nb, nk in zip(self.layout_.nb, self.layout_.nk):
            out.append(np.concatenate([np.zeros(nk), self.parameters_[c : c + nb]]))
            c += nb
        return out

    @property
    def effect_parameters(self) -> dict[str, np.ndarray]:
        """Coefficients of each effect term, by effect name."""
        self.check_fitted()
        lay, m = self.layout_, len(self.input_names_)
        out, c = {}, self.na_ + sum(self.nb_)
        for name, b in zip(lay.effect_of_column[m:], lay.nb[m:]):
            if name is not None:
                out[name] = self.parameters_[c : c + b]
            c += b
        for j, name in enumerate(lay.effect_of_term or [f"term{j}" for j in range(len(lay.output_terms))]):
            out[name] = self.parameters_[c + j : c + j + 1]
        return out

    @property
    def is_linear(self) -> bool:
        """True without output-derived effects (those have no transfer function)."""
        return not self.layout_.output_terms

    def poles(self) -> np.ndarray:
        """Roots of z^na A(z⁻¹).

        Returns
        -------
        ndarray of complex
        """
        return np.roots(self.a) if self.na_ else np.zeros(0)

    def zeros(self, input: int = 0) -> np.ndarray:
        """Roots of the numerator of ``input`` (delays excluded).

        Parameters
        ----------
        input : int
            Input index.

        Returns
        -------
        ndarray of complex
        """
        input = self._input_index(input)
        b = np.trim_zeros(self.b[input][self.nk_[input] :], "f")
        return np.roots(b) if len(b) > 1 else np.zeros(0)

    @property
    def is_stable(self) -> bool:
        """All poles strictly inside the unit circle."""
        return bool(np.all(np.abs(self.discrete_poles()) < 1.0))

    def dc_gain(self) -> np.ndarray:
        """Static gain from each input, B_i(1)/A(1) (±inf for an integrator).

        Returns
        -------
        ndarray of shape (n_inputs,)
        """
        a1 = self.a.sum()
        return np.array([b.sum() / a1 if a1 != 0 else math.copysign(math.inf, b.sum() or 1.0) for b in self.b])

    # ------------------------------------------------------------------ simulation
    def _layout(self, data: IOData) -> EffectLayout:
        if data.n_inputs != len(self.input_names_):
            raise DataError(
                f"the model has {len(self.input_names_)} inputs {list(self.input_names_)} but the data "
                f"have {data.n_inputs}"
            )
        return compile_effects(self.effects, data, self.nb_, self.nk_)

    def predict(self, data: IOData, horizon: int | None = None) -> np.ndarray:
        """Predicted output, NaN where no prediction exists (initial samples).

        Each experiment's first ``max(first_lag_, largest lag)`` samples are initial conditions: a
        structure chosen from a sweep starts where the sweep started it, so its errors are the
        sweep's.

        Parameters
        ----------
        data : IOData
        horizon : int or None
            1: one-step prediction; k: k-step-ahead; None: free-run simulation (MATLAB ``compare``).
            Output-derived effect terms use the simulated output beyond the first step.

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        self.check_fitted()
        if not isinstance(data, IOData):
            raise DataError(f"predict needs an arxid.IOData, got {type(data).__name__}")
        if horizon is not None:
            horizon = check_order("horizon", horizon)
            if horizon < 1:
                raise OrderError("horizon must be >= 1 (or None for free-run simulation)")
        layout = self._layout(data)
        self._check_prediction_work(data, layout, horizon)
        return np.asarray(
            _core.predict(
                np.require(data.y, requirements=["C", "A"]),
                layout.u,
                list(data.experiment_starts),
                self.na_,
                list(layout.nb),
                list(layout.nk),
                list(layout.output_terms),
                np.require(self.parameters_, dtype=float, requirements=["C", "A"]),
                horizon=horizon,
                first_lag=self.first_lag_,
            )
        )

    def _check_prediction_work(self, data: IOData, layout: EffectLayout, horizon: int | None) -> None:
        """A k-step prediction of a linear model on complete data is a filter (O(N p) for any k);
        with output-derived terms or missing samples it runs k steps per sample: refuse it when
        that is hours of work."""
        if horizon is None or horizon < 2:
            return
        if not layout.output_terms and np.isfinite(data.y).all() and np.isfinite(layout.u).all():
            return
        longest = max(b - a for a, b in data.segments)
        check_work(
            data.n_samples * min(horizon, longest) * max(self.n_params, 1),
            f"the {horizon}-step prediction of {self.structure_name()} on {data.n_samples:,} samples "
            "(output-derived effects or missing samples need a k-step simulation per sample)",
            "use a shorter horizon or fewer samples",
        )

    def simulate(self, u: Any, initial: Any = None, extra: Mapping[str, Any] | None = None) -> np.ndarray:
        """Free-run response to the inputs ``u``.

        Parameters
        ----------
        u : array_like of shape (N,) or (N, n_inputs)
        initial : array_like, optional
            Outputs before the first sample, oldest first (default zeros: the system at rest).
        extra : mapping, optional
            Extra signals effect terms need (same length as ``u``).

        Returns
        -------
        ndarray of shape (N,)
        """
        self.check_fitted()
        u = np.asarray(u, dtype=float)
        if u.ndim == 1:
            u = u.reshape(-1, 1)
        lay = self.layout_
        lag = max(
            self.na_,
            max((b + k - 1 for b, k in zip(lay.nb, lay.nk) if b > 0), default=0),
            2 if lay.output_terms else 0,
            self.first_lag_,
        )
        init = np.zeros(lag) if initial is None else np.asarray(initial, dtype=float)
        if init.shape != (lag,):
            raise DataError(f"initial must hold the {lag} outputs before the first sample, got shape {init.shape}")
        pad_u = np.vstack([np.zeros((lag, u.shape[1])), u])
        pad_extra = {k: np.concatenate([np.zeros(lag), np.asarray(v, dtype=float)]) for k, v in (extra or {}).items()}
        y = np.concatenate([init, np.zeros(len(u))])
        d = IOData(y, pad_u, self.ts, output_name=self.output_name, input_names=self.input_names, extra=pad_extra)
        return self.predict(d, None)[lag:]

    # ------------------------------------------------------------------ refit
    def with_effects(self, effects: Sequence[str], data: IOData | None = None) -> ArxModel:
        """The same orders refitted with ``effects`` added.

        Parameters
        ----------
        effects : sequence of str
        data : IOData, optional
            Estimation data (default: the data the model was fitted on, ``data_``).

        Returns
        -------
        ArxModel
        """
        self.check_fitted()
        data = data if data is not None else self.data_
        if data is None:
            raise ArxidError("this model was loaded without its data: pass data=... to refit it with effects")
        new = [e for e in effects if e not in self.effects]
        return ArxModel(na=self.na_, nb=self.nb_, nk=self.nk_, effects=self.effects + tuple(new)).fit(
            data, first_lag=self.first_lag_
        )

    # ------------------------------------------------------------------ export
    def input_labels(self) -> list[str]:
        """Names of the layout's columns: the inputs, then each input-derived effect column.

        Returns
        -------
        list of str
        """
        return list(self.input_names_) + list(self.layout_.column_labels[len(self.input_names_) :])

    def to_control(self, continuous: bool = False, input: int | None = None, method: str = "zoh") -> Any:
        """python-control transfer function(s); see :func:`arxid.convert.to_control`.

        Parameters
        ----------
        continuous : bool
            Convert to continuous time (d2c); the dead time is in ``.dead_time``.
        input : int, optional
            Only this input's transfer function.
        method : {"zoh", "tustin", "matched"}
            d2c method with ``continuous`` (exact ZOH inverse by default).

        Returns
        -------
        control.TransferFunction or list of them
        """
        return import_module("arxid.models.convert").to_control(self, continuous=continuous, input=input, method=method)

    def to_scipy(self) -> Any:
        """``scipy.signal.dlti``; see :func:`arxid.convert.to_scipy`.

        Returns
        -------
        scipy.signal.dlti
        """
        return import_module("arxid.models.convert").to_scipy(self)

    def to_dict(self) -> dict:
        """Everything needed to rebuild the fitted model (the JSON content).

        Returns
        -------
        dict
        """
        return import_module("arxid.models.files").model_content(self)

    @classmethod
    def from_json(cls, path_or_text: Any) -> ArxModel:
        """Load a model written by :meth:`to_json`; it behaves as the fitted one, except that
        refitting (``with_effects``, ``diagnose``) needs the estimation data passed explicitly.

        The rule: a ``str`` whose first character other than a byte-order mark or white space is
        ``{`` is JSON text (as :meth:`from_json_text`); any other ``str`` or path-like is a file
        path (as :meth:`from_json_file`). Anything else is refused.

        Parameters
        ----------
        path_or_text : str or os.PathLike
            A model file, or JSON text.

        Returns
        -------
        ArxModel

        Raises
        ------
        DataError
            The file cannot be read or breaks the schema (see :mod:`arxid.modelfile`); the message
            names the field.
        """
        if isinstance(path_or_text, str) and path_or_text.lstrip("\ufeff \t\r\n").startswith("{"):
            return cls.from_json_text(path_or_text)
        return cls.from_json_file(path_or_text)

    @classmethod
    def from_json_file(cls, path: Any) -> ArxModel:
        """Load a model from a file written by :meth:`to_json` (a regular file, UTF-8 JSON).

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        ArxModel
        """
        return cls.from_json_text(import_module("arxid.models.files").read_text(path))

    @classmethod
    def from_json_text(cls, text: str) -> ArxModel:
        """Load a model from JSON text written by :meth:`to_json`, checked against the schema of
        :mod:`arxid.modelfile`.

        Parameters
        ----------
        text : str

        Returns
        -------
        ArxModel
        """
        modelfile = import_module("arxid.models.files")  # the model files, read when a model is loaded
        return modelfile.model_of(cls, modelfile.parse(text))

    # ------------------------------------------------------------------ printing
    def structure_name(self) -> str:
        """``ARX(na,nb,nk)`` plus the effects (per-input lists for several inputs).

        Returns
        -------
        str
        """
        na, nb, nk = (
            (self.na_, self.nb_, self.nk_)
            if "parameters_" in self.__dict__
            else (self.na, _as_tuple(self.nb), _as_tuple(self.nk))
        )
        b = nb[0] if len(set(nb)) == 1 else list(nb)
        k = nk[0] if len(set(nk)) == 1 else list(nk)
        return f"ARX({na},{b},{k})" + (" + " + " + ".join(self.effects) if self.effects else "")

    def __str__(self) -> str:
        if "parameters_" not in self.__dict__:
            return f"ArxModel(na={self.na}, nb={self.nb}, nk={self.nk}, effects={list(self.effects)}) (not fitted)"
        return import_module("arxid.models.arx_text").describe(self)

    def __repr__(self) -> str:
        if "parameters_" not in self.__dict__:
            return f"ArxModel(na={self.na}, nb={self.nb}, nk={self.nk}, effects={list(self.effects)})"
        return f"<ArxModel {self.structure_name()} ts={self.ts:g} fit={self.fit_percent_:.2f}%>"


def _as_tuple(v: Any) -> tuple:
    return tuple(v) if isinstance(v, (list, tuple, np.ndarray)) else (v,)


@overload
def arx(
    data: IOData | Sequence[Any],
    na: int,
    nb,
    nk,
    effects: Sequence[str] = ...,
    *,
    n_threads: int = ...,
    client: Any = ...,
    per_experiment: Literal[False] = ...,
    read: Any = ...,
) -> ArxModel: ...


@overload
def arx(
    data: Sequence[Any],
    na: int,
    nb,
    nk,
    effects: Sequence[str] = ...,
    *,
    n_threads: int = ...,
    client: Any = ...,
    per_experiment: Literal[True],
    read: Any = ...,
) -> Any: ...


def arx(
    data: IOData | Sequence[Any],
    na: int,
    nb,
    nk,
    effects: Sequence[str] = (),
    *,
    n_threads: int = 0,
    client: Any = None,
    per_experiment: bool = False,
    read: Any = None,
) -> Any:
    """Fit an ARX model (optionally with effect terms) by Householder QR.

    Parameters
    ----------
    data : IOData, or list of IOData or file paths
        Estimation data. A list of logs is fitted as one data set with one experiment per log (no
        regressor straddles two logs); see :mod:`arxid.fleet.fit`.
    na : int
        Number of poles.
    nb, nk : int or sequence of int
        Input orders and delays (one per input, or one for all). ``nk = 0`` is direct feedthrough.
    effects : sequence of str
        Extra physical terms, e.g. ``["u1^2", "u1*vbat", "y^3", "sign(dy)", "const"]``.
    n_threads : int
        Threads for the QR reduction (0 = all).
    client : dask.distributed.Client, optional
        With a list of logs: fit on this Dask cluster; the workers read their own logs and send
        back triangular factors, never the samples.
    per_experiment : bool
        With a list of logs: fit one model per log and return a :class:`arxid.fleet.fit.FleetModels`
        (the models, and how each parameter varies across the logs).
    read : dict or callable, optional
        With file paths: how to read them (see :func:`arxid.data.logs.load_experiment`).

    Returns
    -------
    ArxModel
        A :class:`arxid.fleet.fit.FleetModels` with ``per_experiment=True``.

    Raises
    ------
    DataError, OrderError, IdentifiabilityError
    """
    if per_experiment:
        if not isinstance(data, (list, tuple)):
            raise DataError("per_experiment=True fits each log of a list: pass a list of IOData objects or file paths")
        fit = functools.partial(arx, na=na, nb=nb, nk=nk, effects=effects, n_threads=1 if client else n_threads)
        logs = import_module("arxid.models.many_logs").logs_fitting("per_experiment=True")
        return logs.fit_each(data, client, read, fit)
    return ArxModel(na=na, nb=nb, nk=nk, effects=effects).fit(data, n_threads=n_threads, client=client, read=read)
