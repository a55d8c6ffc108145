"""Free-run comparison: measured output against models' simulations or k-step predictions.

* :func:`compare` — fit percent and RMS of one or more models on measured data (MATLAB ``compare``),
  as a :class:`Comparison`.
* :func:`prediction_error` — a model's prediction, error and divergence flag at a horizon: the
  error the residual tests, the failure analysis and the diagnosis start from;
  :func:`prediction` the same without the error (an array the size of the record), for a caller
  who needs only the prediction or its RMS.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from .._base import metrics
from .._base.formatting import finite_or_none, horizon_label, require_pandas, text_table
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from ..models.arguments import check_data, check_horizon, check_predictor, check_same_signals
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel, check_initial
from ..models.state_space import StateSpaceModel
from ..models.wiener import WienerModel
from .initial_state import estimated_free_run
from .state_space import PerOutput, in_model_order, state_space_label, state_space_prediction

__all__ = ["compare", "Comparison", "prediction", "prediction_error", "error_rms"]


def prediction_error(model: ArxModel, data: IOData, horizon: int | None = None, initial: str = "zero"):
    """Prediction, error and a divergence flag.

    Parameters
    ----------
    model : ArxModel
        A fitted model.
    data : IOData
        Measured data.
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction.
    initial : {"zero", "estimate"}
        ``"estimate"``: each run's initial state is fitted to ``data`` first (see
        :meth:`arxid.PolynomialModel.predict`; for an ARX model, with or without effect terms, the
        outputs its free run starts from, see :mod:`arxid.checks.initial_state`).

    Returns
    -------
    pred : ndarray of shape (n_samples,)
        Output predicted with ``horizon``; NaN where no prediction exists.
    error : ndarray of shape (n_samples,)
        ``y - pred`` (NaN where either is missing).
    diverged : bool
        The prediction diverged (see :mod:`arxid._metrics`: inf, or beyond
        ``DIVERGENCE_FACTOR`` times the largest measured |y|); its RMS is reported as infinite.
    """
    pred, diverged = prediction(model, data, horizon, initial)
    with np.errstate(all="ignore"):
        err = data.y - pred
    return pred, err, diverged


def prediction(
    model: ArxModel, data: IOData, horizon: int | None = None, initial: str = "zero"
) -> tuple[np.ndarray, bool]:
    """The prediction and divergence flag of :func:`prediction_error`, without its error array.

    Parameters
    ----------
    model : ArxModel
    data : IOData
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction.
    initial : {"zero", "estimate"}
        As :func:`prediction_error`.

    Returns
    -------
    pred : ndarray of shape (n_samples,)
    diverged : bool
    """
    with np.errstate(all="ignore"):
        if isinstance(model, WienerModel):  # its linear part's free run starts at rest either way
            check_initial(initial)
            pred = np.asarray(model.predict(data, horizon), dtype=float)
        elif check_initial(initial) == "estimate" and isinstance(model, PolynomialModel):
            pred = np.asarray(model.predict(data, horizon, initial="estimate"), dtype=float)
        elif initial == "estimate":
            pred = estimated_free_run(model, data, horizon)
        else:
            pred = np.asarray(model.predict(data, horizon), dtype=float)
    return pred, metrics.diverged(data.y, pred)


def error_rms(model: ArxModel, data: IOData, horizon: int | None = None, initial: str = "zero") -> float:
    """RMS of ``y - prediction`` at ``horizon``; ``inf`` when the prediction diverges.

    Parameters
    ----------
    model : ArxModel
    data : IOData
    horizon : int or None
        None: free run; k: k-step-ahead prediction.
    initial : {"zero", "estimate"}
        Initial conditions of the prediction (see :func:`prediction_error`).

    Returns
    -------
    float
    """
    if check_initial(initial) == "zero":
        return model.rms(data, horizon)
    return metrics.prediction_rms(data.y, prediction(model, data, horizon, initial)[0])  # inf when it diverged


@record(eq=False)
class Comparison:
    """Measured output against several models' predictions.

    Attributes
    ----------
    names : tuple of str
        One label per model.
    fit_percent, rms : tuple of float
        NRMSE fit in percent and RMS of the error, per model (``rms`` is ``inf`` for a simulation
        that diverges).
    horizon : int or None
        None: free-run simulation; k: k-step-ahead prediction.
    time, y : ndarray of shape (n_samples,)
        Sample times and the measured output.
    predictions : tuple of ndarray of shape (n_samples,)
        Each model's prediction (NaN where it has none).
    diverged : tuple of bool
    output_name : str
    """

    names: tuple[str, ...]
    fit_percent: tuple[float, ...]
    rms: tuple[float, ...]
    horizon: int | None
    time: np.ndarray
    y: np.ndarray
    predictions: tuple[np.ndarray, ...]
    diverged: tuple[bool, ...]
    output_name: str = "y"
    output_unit: str = ""

    @property
    def best(self) -> str:
        """Name of the model with the lowest RMS."""
        return self.names[int(np.nanargmin(np.where(np.isfinite(self.rms), self.rms, np.inf)))]

    def __str__(self) -> str:
        rows = [
            (n, f, r, "diverged" if d else "")
            for n, f, r, d in zip(self.names, self.fit_percent, self.rms, self.diverged)
        ]
        return f"compare ({horizon_label(self.horizon)}), output {self.output_name}\n" + text_table(
            ["model", "fit %", "rms", ""], rows
        )

    def to_dict(self) -> dict:
        """JSON-ready dict: the horizon and, per model, its fit, RMS and divergence flag.

        Returns
        -------
        dict
            ``{"horizon": int or None, "models": [{"name", "fit_percent", "rms", "diverged"}, ...]}``;
            non-finite numbers are None.
        """
        return {
            "horizon": self.horizon,
            "models": [
                {"name": n, "fit_percent": finite_or_none(f), "rms": finite_or_none(r), "diverged": bool(d)}
                for n, f, r, d in zip(self.names, self.fit_percent, self.rms, self.diverged)
            ],
        }

    def to_json(self, indent: int | None = 2) -> str:
        """JSON of :meth:`to_dict`.

        Parameters
        ----------
        indent : int or None
            Indentation of the JSON; None writes one line.

        Returns
        -------
        str
        """
        import json

        return json.dumps(self.to_dict(), indent=indent)

    def to_pandas(self):
        """One row per model: fit, RMS and divergence flag.

        Returns
        -------
        pandas.DataFrame
            Indexed by model name, columns ``fit_percent``, ``rms``, ``diverged``.
        """
        pd = require_pandas()
        return pd.DataFrame(
            {"fit_percent": self.fit_percent, "rms": self.rms, "diverged": self.diverged},
            index=pd.Index(self.names, name="model"),
        )

    def plot(self, ax: Any = None) -> Any:
        """Measured against predicted output, with the error underneath.

        Parameters
        ----------
        ax : pair of Axes, optional
            Where to draw (output, error); default a new figure.

        Returns
        -------
        matplotlib.figure.Figure
        """
        from ..plots.diagnostics import plot_comparison

        return plot_comparison(self, ax=ax)


def _model_list(models) -> tuple[list[str], list[Any]]:
    if isinstance(models, (ArxModel, PolynomialModel, StateSpaceModel)):
        models = [models]
    if isinstance(models, Mapping):
        names, ms = [str(k) for k in models], list(models.values())
    else:
        try:
            ms = list(models)
        except TypeError:
            raise ArxidError(
                f"compare takes a model, a list of models or a dict name -> model, got {type(models).__name__}"
            ) from None
        names = []
        for m in ms:
            base = state_space_label(m) if isinstance(m, StateSpaceModel) else check_predictor(m).structure_name()
            name, i = base, 2
            while name in names:
                name, i = f"{base} #{i}", i + 1
            names.append(name)
    if not ms:
        raise ArxidError("compare needs at least one model")
    for m in ms:
        if not isinstance(m, StateSpaceModel):
            check_predictor(m)
    return names, ms


def compare(models, data: IOData, horizon: int | None = None, initial: str = "zero") -> Any:
    """Compare models with measured data.

    Parameters
    ----------
    models : model, sequence of models or mapping of str to model
        ARX, polynomial (OE, ARMAX, BJ) or state-space models (a mapping gives them names).
    data : IOData
        Measured data, preferably not the estimation data; of several outputs for a state-space
        model of several outputs.
    horizon : int or None
        None (default): free-run simulation, as MATLAB ``compare``; 1: one-step prediction;
        k: k-step-ahead prediction (for plants with an integrator, whose free run drifts).
    initial : {"zero", "estimate"}
        ``"zero"`` (default): each model starts at rest in each run of the data. ``"estimate"``:
        each run's initial state is fitted to the data first, as MATLAB ``compare`` does, so a
        record that starts mid-transient is not held against the model (OE, ARMAX and BJ models
        from their fitted initial state; ARX models, with their effect terms, from fitted initial
        outputs on the samples ``"zero"`` predicts, see :mod:`arxid.checks.initial_state`).

    Returns
    -------
    Comparison or PerOutput of Comparison
        ``fit_percent`` and ``rms`` per model; ``.plot()`` draws measured against predicted output.
        For data of several outputs, one Comparison per output by name (``result["q"]``), each
        with the models that predict that output.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(1)
    >>> u = rng.standard_normal(400); y = np.zeros(400)
    >>> for t in range(1, 400):
    ...     y[t] = 0.9 * y[t - 1] + u[t - 1]
    >>> d = arxid.IOData(y, u, ts=1.0)
    >>> c = arxid.compare(arxid.arx(d, 1, 1, 1), d)
    >>> round(c.fit_percent[0], 6)
    100.0
    """
    data = check_data(data)
    horizon = check_horizon(horizon)
    names, ms = _model_list(models)
    check_initial(initial)
    predicted: dict[str, list[tuple[str, np.ndarray]]] = {name: [] for name in data.output_names}
    for name, m in zip(names, ms, strict=True):
        for output, pred in _output_predictions(m, data, horizon, initial).items():
            predicted[output].append((name, pred))
    results = {output: _comparison(entries, data, output, horizon) for output, entries in predicted.items() if entries}
    return results[data.output_names[0]] if data.n_outputs == 1 else PerOutput(results)


def _output_predictions(model: Any, data: IOData, horizon: int | None, initial: str) -> dict[str, np.ndarray]:
    """The model's prediction of each output it describes, by output name."""
    what = "the data to compare with"
    if isinstance(model, StateSpaceModel):
        pred = state_space_prediction(model, in_model_order(model, data, what), horizon, initial)
        return {name: pred[:, i] for i, name in enumerate(model.output_names)}
    if model.output_name not in data.output_names:
        raise DataError(f"{what} have outputs {list(data.output_names)}, but the model predicts {model.output_name!r}")
    one = data.output(model.output_name) if data.n_outputs > 1 else data
    inputs = model.input_names if one.input_names == model.input_names else model.measured_input_names
    check_same_signals(model.ts, model.output_name, inputs, one, what)
    return {model.output_name: prediction(model, one, horizon, initial)[0]}


def _comparison(entries: list[tuple[str, np.ndarray]], data: IOData, output: str, horizon: int | None) -> Comparison:
    """The Comparison of one output with the models' predictions of it."""
    y = data.signal(output)
    return Comparison(
        tuple(name for name, _ in entries),
        tuple(metrics.fit_percent(y, pred) for _, pred in entries),
        tuple(metrics.prediction_rms(y, pred) for _, pred in entries),
        horizon,
        np.arange(data.n_samples) * data.ts,
        y.copy(),
        tuple(pred for _, pred in entries),
        tuple(metrics.diverged(y, pred) for _, pred in entries),
        output,
        data.unit(output),
    )
