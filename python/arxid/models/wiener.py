"""A static nonlinearity after the linear dynamics (a Wiener model): the sensor or the output stage
reads g(x) of the linear part's output x.

========================  ==============================  ========================================
sensor                    g(x)                            typical physics
========================  ==============================  ========================================
``power``                 x^p (x >= 0)                    a quadratic sensor (p = 2), a square-root one
``saturation``            x held within [lo, hi]          a sensor or an amplifier that clips
``dead zone``             sign(x)·max(|x| − c, 0)         a measurement that reads 0 inside a band
========================  ==============================  ========================================

g has unit slope where it is linear, so x is in the output's units and the linear part carries the
gain. Estimation inverts g where it can: z = g⁻¹(y) (samples on a flat part of g are missing, as
gaps), an ARX model of z from the inputs is fitted by least squares, and the model predicts
g(x̂) from the free run x̂ of that linear part. :func:`fit_wiener` scans g's parameter for the lowest
free-run error on the estimation data.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from .._base import _core
from .._base.order_statistics import median
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, OrderError
from .arx_model import ArxModel
from .arx_solver import checked_layout
from .effects import EffectLayout

__all__ = ["SensorShape", "SensorScan", "WienerModel", "fit_wiener", "added_effects", "linear_part", "SENSOR_KINDS"]

#: The output nonlinearities :func:`fit_wiener` knows.
SENSOR_KINDS = ("power", "saturation", "dead zone")


@record
class SensorShape:
    """The static function g the output is read through.

    Attributes
    ----------
    kind : str
        One of :data:`SENSOR_KINDS`.
    params : tuple of float
        The exponent p, the levels (lo, hi) or the half-width c.
    """

    kind: str
    params: tuple[float, ...]

    def __post_init__(self) -> None:
        p = self.params
        bad = {
            "power": lambda: not (len(p) == 1 and 0 < p[0] <= 10),
            "saturation": lambda: not (len(p) == 2 and p[0] < p[1]),
            "dead zone": lambda: not (len(p) == 1 and p[0] >= 0),
        }
        if self.kind not in bad:
            raise OrderError(f"unknown sensor shape {self.kind!r}; use one of {SENSOR_KINDS}")
        if bad[self.kind]():
            raise OrderError(f"sensor shape {self.kind}: an exponent in (0, 10], levels lo < hi or c >= 0; got {p}")

    @property
    def text(self) -> str:
        """e.g. ``"y = x^2"``, ``"y = clip(x,-1,1.2)"``, ``"y = dz(x,0.1)"``."""
        p = [f"{v:.4g}" for v in self.params]
        if self.kind == "power":
            return f"y = x^{p[0]}"
        return f"y = clip(x,{p[0]},{p[1]})" if self.kind == "saturation" else f"y = dz(x,{p[0]})"

    def physics(self) -> str:
        """What the shape stands for, in words."""
        if self.kind == "power":
            p = self.params[0]
            what = (
                "a quadratic sensor"
                if abs(p - 2) <= 0.2
                else "a square-root sensor"
                if abs(p - 0.5) <= 0.05
                else "a power-law sensor"
            )
            return f"the output is read through {self.text} ({what})"
        if self.kind == "saturation":
            return f"the output is read through {self.text} (the sensor saturates at its levels)"
        return f"the output is read through {self.text} (the measurement reads 0 inside a dead band)"

    def __call__(self, x: np.ndarray) -> np.ndarray:
        x = np.asarray(x, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            if self.kind == "power":
                return np.power(np.maximum(x, 0.0), self.params[0])
            if self.kind == "saturation":
                return np.clip(x, self.params[0], self.params[1])
            return np.sign(x) * np.maximum(np.abs(x) - self.params[0], 0.0)

    def inverse(self, y: np.ndarray, floor: float) -> np.ndarray:
        """x = g⁻¹(y) where g is invertible; NaN on its flat parts (within ``floor`` of a level).

        Parameters
        ----------
        y : ndarray
        floor : float
            The measurement noise's size: a sample this close to a flat part may lie on it.
        """
        y = np.asarray(y, dtype=float)
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            if self.kind == "power":
                return np.where(y > floor, np.power(np.maximum(y, 0.0), 1.0 / self.params[0]), np.nan)
            if self.kind == "saturation":
                lo, hi = self.params
                return np.where((y > lo + floor) & (y < hi - floor), y, np.nan)
            c = self.params[0]
            return np.where(np.abs(y) > floor, y + c * np.sign(y), np.nan)


@record(eq=False)
class WienerModel:
    """Linear dynamics followed by a static output nonlinearity: y = g(x), x from an ARX model.

    Attributes
    ----------
    linear : ArxModel
        The linear part, fitted on z = g⁻¹(y).
    sensor : SensorShape
    data_ : IOData
        The estimation data (measured output).
    """

    linear: ArxModel
    sensor: SensorShape
    data_: IOData | None = None

    # What the analysis reads off any model: the names, step and orders are the linear part's (the
    # sensor adds none); the prediction and its errors are the Wiener model's own, never delegated.
    @property
    def effects(self) -> tuple[str, ...]:
        return tuple(self.linear.effects)

    @property
    def sensor_effect(self) -> str:
        """The sensor as the diagnosis names it, e.g. ``"sensor: y = clip(x,-1,1.2)"``."""
        return f"sensor: {self.sensor.text}"

    @property
    def ts(self) -> float:
        return self.linear.ts

    @property
    def output_name(self) -> str:
        return self.linear.output_name

    @property
    def input_names(self) -> tuple[str, ...]:
        return self.linear.input_names

    @property
    def measured_input_names(self) -> tuple[str, ...]:
        return self.linear.measured_input_names

    @property
    def na_(self) -> int:
        return self.linear.na_

    @property
    def nb_(self) -> tuple[int, ...]:
        return tuple(self.linear.nb_)

    @property
    def nk_(self) -> tuple[int, ...]:
        return tuple(self.linear.nk_)

    def check_fitted(self) -> None:
        """Raise unless the linear part is fitted."""
        self.linear.check_fitted()

    @property
    def n_params(self) -> int:
        return self.linear.n_params + len(self.sensor.params)

    def structure_name(self) -> str:
        """e.g. ``ARX(2,2,1), then y = x^2``."""
        return f"{self.linear.structure_name()}, then {self.sensor.text}"

    def predict(self, data: IOData, horizon: int | None = None) -> np.ndarray:
        """g of the linear part's prediction: its free run (``horizon=None``), or k steps ahead from
        the inverted past outputs (NaN where the past output lies on a flat part of g).

        Parameters
        ----------
        data : IOData
        horizon : int or None

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        if horizon is None:
            x = self.linear.predict(data, None)
        else:
            z = self.sensor.inverse(data.y, 0.0)
            x = (
                self.linear.predict(replace(data, y=z), horizon)
                if np.isfinite(z).any()
                else np.full(data.n_samples, np.nan)
            )
        return self.sensor(x)

    def __repr__(self) -> str:
        return f"<WienerModel {self.structure_name()}>"

    def __str__(self) -> str:
        return f"{self.linear}\nthen the sensor reads {self.sensor.text}, x being the output of the dynamics above"


def noise_floor(y: np.ndarray) -> float:
    """A robust size of the measurement noise: 3 × the scaled MAD of the first differences / √2."""
    d = np.diff(y[np.isfinite(y)])
    if d.size < 3:
        return 0.0
    return float(3 * 1.4826 * median(np.abs(d - median(d))) / math.sqrt(2))


def fit_wiener(model: ArxModel, data: IOData, sensor: SensorShape, floor: float | None = None) -> WienerModel:
    """The Wiener model with ``model``'s orders and effects and the output read through ``sensor``.

    Parameters
    ----------
    model : ArxModel
        Gives the orders, delays and effects of the linear part.
    data : IOData
        Estimation data.
    sensor : SensorShape
    floor : float, optional
        ``noise_floor(data.y)``, when a scan of many sensors has it already.

    Returns
    -------
    WienerModel

    Raises
    ------
    DataError
        When too few samples lie where g can be inverted.
    """
    z = sensor.inverse(data.y, noise_floor(data.y) if floor is None else floor)
    if np.isfinite(z).sum() < 0.2 * data.n_samples:
        raise DataError(f"fewer than 20 % of the samples lie where {sensor.text} can be inverted")
    zdata = replace(data, y=z)
    linear = ArxModel(na=model.na_, nb=model.nb_, nk=model.nk_, effects=model.effects).fit(zdata)
    return WienerModel(linear, sensor, data)


class SensorScan:
    """The linear parts of many Wiener models of one record (a scan of g's parameter): the fit's
    checks and the layout once (they read the inputs and the record's size, not the output), then
    per sensor one call of the core for the fit on g⁻¹(y) and one for the free run, the calls of
    :func:`fit_wiener` and :meth:`WienerModel.predict` with the same arguments (the same numbers),
    without a new IOData and a fitted model per sensor.

    Parameters
    ----------
    model : ArxModel
        Gives the orders, delays and effects of the linear part.
    data : IOData
    floor : float
        ``noise_floor(data.y)``.
    """

    def __init__(self, model: ArxModel, data: IOData, floor: float):
        self.model, self.data, self.floor = model, data, floor
        self.na = model.na_
        self.layout: EffectLayout | None = None
        try:
            linear = ArxModel(na=model.na_, nb=model.nb_, nk=model.nk_, effects=model.effects)
            self.layout = checked_layout(linear, data, 0, 0)[1]
        except ArxidError:  # refused whatever the output: every sensor's fit fails
            return
        # the core's arguments that do not depend on the sensor, once
        lay = self.layout
        self._structure = (list(data.experiment_starts), list(lay.nb), list(lay.nk), list(lay.output_terms))
        self._y = np.require(data.y, requirements=["C", "A"])

    def free_run(self, sensor: SensorShape) -> tuple[np.ndarray, np.ndarray | None] | None:
        """The linear part's A(z⁻¹) and g of its free run on the data: None where the fit fails, a
        free run of None where the prediction fails (NaN where it has no value)."""
        data, layout = self.data, self.layout
        z = sensor.inverse(data.y, self.floor)
        if layout is None or np.isfinite(z).sum() < 0.2 * data.n_samples:
            return None
        starts, nb, nk, terms = self._structure
        try:
            fit = _core.fit(np.require(z, requirements=["C", "A"]), layout.u, starts, self.na, nb, nk, terms)
        except ArxidError:
            return None
        theta = np.require(np.asarray(fit.theta), dtype=float, requirements=["C", "A"])
        a = np.concatenate([[1.0], theta[: self.na]])
        try:
            x = np.asarray(_core.predict(self._y, layout.u, starts, self.na, nb, nk, terms, theta, horizon=None))
        except ArxidError:
            return a, None
        return a, sensor(x)

    def wiener(self, sensor: SensorShape) -> WienerModel:
        """The Wiener model with ``sensor`` (its fit: :func:`fit_wiener`)."""
        return fit_wiener(self.model, self.data, sensor, self.floor)


def added_effects(model: Any) -> tuple[str, ...]:
    """What a model adds to linear dynamics: its effects, and a Wiener model's sensor after them."""
    sensor = (model.sensor_effect,) if isinstance(model, WienerModel) else ()
    return (*model.effects, *sensor)


def linear_part(model: Any) -> Any:
    """The model whose frequency response, parameters and effects describe ``model``'s dynamics: a
    Wiener model's linear part (its sensor is static), any other model itself."""
    return model.linear if isinstance(model, WienerModel) else model
