"""The part every fitted model class shares (:class:`~arxid.ArxModel`, :class:`~arxid.PolynomialModel`):
names and units, loss and information criteria, prediction quality and JSON, defined once."""

from __future__ import annotations

import numbers
from typing import Any

import numpy as np

from .._base import metrics
from .._base.limits import check_order
from ..data.iodata import IOData
from ..exceptions import DataError

__all__ = ["FittedModel"]


class FittedModel:
    """What every fitted model class shares: the names and units the data gave, the loss, noise
    variance, standard errors and FPE/AIC/AICc/nAIC/BIC (from ``rss_``, ``n_rows_``, ``parameters_``,
    ``covariance_``), the fit and RMS of a prediction, and JSON. Subclasses define ``check_fitted``,
    ``predict`` and ``to_dict``."""

    rss_: float
    n_rows_: int
    parameters_: np.ndarray
    covariance_: np.ndarray
    ts_: float
    output_name_: str
    input_names_: tuple[str, ...]
    output_unit_: str
    input_units_: tuple[str, ...]

    def check_fitted(self) -> None:  # pragma: no cover - every model class defines it
        """Raise unless fitted (each model class says how)."""
        raise NotImplementedError

    def predict(self, data: IOData, horizon: int | None = 1) -> np.ndarray:  # pragma: no cover
        """The prediction of ``data.y`` (each model class defines it)."""
        raise NotImplementedError

    def simulate(self, u: Any) -> np.ndarray:  # pragma: no cover - every model class defines it
        """Free-run response to the inputs ``u`` from rest (each model class defines it)."""
        raise NotImplementedError

    def poles(self) -> np.ndarray:  # pragma: no cover - every model class defines it
        """Poles of the model (each model class defines it)."""
        raise NotImplementedError

    def zeros(self, input: int = 0) -> np.ndarray:  # pragma: no cover - every model class defines it
        """Zeros of ``input``'s transfer function (each model class defines it)."""
        raise NotImplementedError

    def discrete_poles(self) -> np.ndarray:
        """Poles in z of the sampled model: :meth:`poles` of a discrete model (a continuous one's
        :meth:`poles` are in rad/s, and this gives its exact sampled equivalent's). Stability and
        the checks judge these.

        Returns
        -------
        ndarray of complex
        """
        return self.poles()

    def discrete_zeros(self, input: int = 0) -> np.ndarray:
        """Zeros in z of ``input``'s transfer function of the sampled model (see :meth:`discrete_poles`).

        Parameters
        ----------
        input : int

        Returns
        -------
        ndarray of complex
        """
        return self.zeros(input)

    def step(self, n_samples: int, amplitude: float = 1.0, input: int = 0) -> np.ndarray:
        """Response to a step of ``amplitude`` on ``input`` from rest.

        Parameters
        ----------
        n_samples : int
        amplitude : float
        input : int

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        self.check_fitted()
        input = self._input_index(input)
        u = np.zeros((check_order("n_samples", n_samples), len(self.input_names_)))
        u[:, input] = amplitude
        return self.simulate(u)

    def _input_index(self, input: Any) -> int:
        """``input`` as an index of the model's inputs, else a DataError listing them."""
        self.check_fitted()
        m = len(self.input_names_)
        if isinstance(input, bool) or not isinstance(input, numbers.Integral) or not 0 <= int(input) < m:
            raise DataError(
                f"input {input!r} does not exist: the model has {m} input(s) {list(self.input_names_)}, "
                f"numbered 0 to {m - 1}"
            )
        return int(input)

    def to_dict(self) -> dict:  # pragma: no cover - every model class defines it
        """Everything needed to rebuild the fitted model (each model class defines it)."""
        raise NotImplementedError

    # ------------------------------------------------------------------ what the data named
    @property
    def ts(self) -> float:
        """Sampling time in seconds (of the estimation data)."""
        return float(self.ts_)

    @property
    def output_name(self) -> str:
        """Name of the output signal."""
        return str(self.output_name_)

    @property
    def input_names(self) -> tuple[str, ...]:
        """Names of the input signals."""
        return tuple(self.input_names_)

    @property
    def measured_input_names(self) -> tuple[str, ...]:
        """The inputs data must have for this model (a polynomial model computes the inputs the
        diagnosis added from them; see :mod:`arxid.derived_inputs`)."""
        return self.input_names

    @property
    def output_unit(self) -> str:
        """Unit of the output ('' when unknown)."""
        return str(self.output_unit_)

    @property
    def input_units(self) -> tuple[str, ...]:
        """Units of the inputs ('' when unknown)."""
        return tuple(self.input_units_)

    # ------------------------------------------------------------------ loss and criteria
    @property
    def n_params(self) -> int:
        """Number of estimated parameters."""
        self.check_fitted()
        return len(self.parameters_)

    @property
    def loss_(self) -> float:
        """Loss V = RSS / N of the one-step prediction error on the scored samples."""
        return self.rss_ / self.n_rows_

    @property
    def noise_variance_(self) -> float:
        """Unbiased noise variance RSS / (N − p)."""
        return self.rss_ / max(self.n_rows_ - self.n_params, 1)

    @property
    def standard_errors_(self) -> np.ndarray:
        """Standard error of each parameter, √diag(covariance)."""
        self.check_fitted()
        return np.sqrt(np.diag(self.covariance_))

    @property
    def fpe_(self) -> float:
        """Akaike's final prediction error, V (N + p) / (N − p)."""
        return float(metrics.fpe(self.rss_, self.n_rows_, self.n_params))

    @property
    def aic_(self) -> float:
        """AIC as MATLAB computes it: N log V + 2p + N (log 2π + 1)."""
        return float(metrics.aic(self.rss_, self.n_rows_, self.n_params))

    @property
    def aicc_(self) -> float:
        """Small-sample corrected AIC, AIC + 2p (p + 1) / (N − p − 1)."""
        return float(metrics.aicc(self.rss_, self.n_rows_, self.n_params))

    @property
    def naic_(self) -> float:
        """MATLAB's normalised AIC, log V + 2p / N."""
        return float(metrics.naic(self.rss_, self.n_rows_, self.n_params))

    @property
    def bic_(self) -> float:
        """BIC: N log V + p log N + N (log 2π + 1)."""
        return float(metrics.bic(self.rss_, self.n_rows_, self.n_params))

    # ------------------------------------------------------------------ prediction quality
    def fit_percent(self, data: IOData, horizon: int | None = None) -> float:
        """NRMSE fit in percent of the prediction with ``horizon`` (see :mod:`arxid._metrics`).

        Parameters
        ----------
        data : IOData
        horizon : int or None
            None: free run; k: k-step-ahead prediction.

        Returns
        -------
        float
            ``-inf`` when the prediction diverges.
        """
        return metrics.fit_percent(data.y, self.predict(data, horizon))

    def rms(self, data: IOData, horizon: int | None = None) -> float:
        """RMS of measured − predicted output over the predicted samples.

        Parameters
        ----------
        data : IOData
        horizon : int or None
            None: free run; k: k-step-ahead prediction.

        Returns
        -------
        float
            ``inf`` when the prediction diverges.
        """
        return metrics.prediction_rms(data.y, self.predict(data, horizon))

    # ------------------------------------------------------------------ export
    def to_json(self, path: str | None = None, indent: int | None = 2) -> str:
        """Plain JSON (no pickle); floats round-trip exactly.

        Parameters
        ----------
        path : str, optional
            Also write it to this file.
        indent : int or None

        Returns
        -------
        str
        """
        import json

        text = json.dumps(self.to_dict(), indent=indent, allow_nan=True)
        if path is not None:
            from .files import write_atomically

            write_atomically(path, text)
        return text
