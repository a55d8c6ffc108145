"""Output nonlinearities as suspects: the output read through a static g after the linear
dynamics (a Wiener model, :mod:`arxid.models.wiener`): a sensor that saturates, a quadratic
sensor, a measurement with a dead band.

Each g's parameter is scanned for the lowest free-run error on the estimation data, with the
model's own orders. The best one per kind is judged on the validation data like every candidate:
its evidence is a Diebold–Mariano test of its free-run errors against the model's (Bonferroni over
the values tried), and it must lower the validation error by ``min_improvement``. A sensor shape
changes what every other candidate means (they act before g), so it is named only when its
validation error is also below the best other suspect's; then the ladder stops at it.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .._base import metrics
from .._base.local_search import simplex_minimum
from .._base.order_statistics import quantiles
from ..checks import prediction
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.iv import IvModel
from ..models.wiener import SensorScan, SensorShape, WienerModel, fit_wiener, noise_floor
from .result import Suspect
from .scan_sample import ScanSample, scan_sample
from .shapes import validation_p

__all__ = ["sensor_suspects", "rank_sensors", "SENSOR_STEPS"]

#: Values of a sensor shape's parameter tried on the estimation data.
SENSOR_STEPS = 12


def _sensor_grid(y: np.ndarray, floor: float) -> list[SensorShape]:
    """The sensors scanned (``floor``: the output's :func:`noise_floor`)."""
    y = y[np.isfinite(y)]
    below = float(np.mean(y < -floor))
    out = []
    if below < 0.02:  # an output that does not go below zero: a power-law sensor
        out += [SensorShape("power", (float(p),)) for p in np.geomspace(0.33, 3.0, SENSOR_STEPS)]
    lo, hi = float(np.min(y)), float(np.max(y))
    qs = np.linspace(0.0, 0.03, 4)
    levels = quantiles(y, np.concatenate([1 - qs, qs]))  # one call: one copy of the record, not eight
    for top, bottom in zip(levels[: len(qs)].tolist(), levels[len(qs) :].tolist()):
        # levels at the plateaus a clipping sensor leaves
        out += [SensorShape("saturation", (bottom, top)), SensorShape("saturation", (lo - (hi - lo), top))]
        out += [SensorShape("saturation", (bottom, hi + (hi - lo)))]
    if below > 0.02 and np.mean(y > floor) > 0.02:  # a two-sided output: a dead band
        top = float(np.max(np.abs(y)))
        out += [SensorShape("dead zone", (float(c),)) for c in np.linspace(0, 0.5 * top, SENSOR_STEPS + 1)[1:]]
    return out


def _fitted(scan: SensorScan, sample: ScanSample, sensor: SensorShape) -> tuple[bool, float]:
    """Whether the Wiener model with ``sensor`` can be fitted on the sample, and its free-run error
    there, each block's warm-up left out (``scan``: the sample's :class:`SensorScan`)."""
    run = scan.free_run(sensor)
    if run is None:
        return False, math.inf
    a, pred = run
    if pred is None:
        return True, math.inf
    counts = sample.settled(a)
    return True, metrics.prediction_rms(sample.data.y, pred if counts is None else np.where(counts, pred, np.nan))


def _polished(scan: SensorScan, sample: ScanSample, sensor: SensorShape, rms: float) -> tuple[float, SensorShape]:
    """A local search from the grid's best parameters (Nelder–Mead; each point a fit and a free run)."""
    kind, start = sensor.kind, np.array(sensor.params)
    scale = np.maximum(np.abs(start), 1e-3) * 0.05
    simplex = [start] + [start + np.eye(start.size)[i] * scale[i] for i in range(start.size)]

    def cost(params: np.ndarray) -> float:
        try:
            tried = SensorShape(kind, tuple(sorted(float(v) for v in params)))
        except ArxidError:  # the search stepped out of the shape's range
            return math.inf
        return _fitted(scan, sample, tried)[1]

    found, fun = simplex_minimum(cost, np.array(simplex), maxfev=40)
    if not fun < rms:
        return rms, sensor
    better = SensorShape(kind, tuple(sorted(float(v) for v in found)))
    fitted, after = _fitted(scan, sample, better)
    return (after, better) if fitted else (rms, sensor)


def sensor_suspects(
    model: ArxModel,
    data: IOData,
    validation: IOData,
    horizon: int | None,
    initial: str,
    base_rms: float,
    base_prediction: np.ndarray | None = None,
) -> list[Suspect]:
    """The best sensor shape of each kind, refitted and judged on the validation data.

    Parameters
    ----------
    model : ArxModel
    data, validation : IOData
    horizon : int or None
        The diagnosis's validation horizon.
    initial : {"zero", "estimate"}
    base_rms : float
        The model's validation error.
    base_prediction : ndarray, optional
        The model's validation prediction at ``horizon`` (made here when not given).

    Returns
    -------
    list of Suspect
        Of kind ``"sensor"`` (significance still to be weighed against the other suspects by
        :func:`rank_sensors`).
    """
    if isinstance(model, IvModel) or model.effects or not (math.isfinite(base_rms) and base_rms > 0):
        return []
    floor = noise_floor(data.y)
    grid = _sensor_grid(np.asarray(data.y, dtype=float), floor)  # the levels of the whole record
    sample = scan_sample(data)
    scan = SensorScan(model, sample.data, floor)
    best: dict[str, tuple[float, SensorShape]] = {}
    for sensor in grid:
        fitted, rms = _fitted(scan, sample, sensor)
        if fitted and rms < best.get(sensor.kind, (math.inf, None))[0]:
            best[sensor.kind] = (rms, sensor)
    best = {kind: _polished(scan, sample, sensor, rms) for kind, (rms, sensor) in best.items()}
    found = [scan.wiener(sensor) for _, sensor in best.values()]  # each fitted as the scan fitted it
    made = prediction(model, validation, horizon, initial)[0] if base_prediction is None else base_prediction
    base_err = validation.y - made
    out = []
    for w in _on_every_sample(found, model, data, sample.data, floor):
        pred = w.predict(validation, horizon)
        after = float(np.sqrt(np.nanmean((validation.y - pred) ** 2))) if np.isfinite(pred).any() else math.inf
        p = validation_p(base_err, validation.y - pred)
        p_adj = min(1.0, p * len(grid))
        gain = 1.0 - after / base_rms if math.isfinite(after) else -math.inf
        s = Suspect(
            w.sensor_effect, "sensor", (), model.na_, tuple(model.nb_), tuple(model.nk_),
            math.nan, math.nan, p, p_adj, len(w.sensor.params), after, gain, False, "", w, w.sensor.physics(),
        )  # fmt: skip
        out.append(s)
    return out


def _on_every_sample(
    found: list[WienerModel], model: ArxModel, data: IOData, sample: IOData, floor: float
) -> list[WienerModel]:
    """The sensors the scan found, their linear parts refitted on every estimation sample (the
    scan read ``sample`` of them); one that no longer fits is dropped."""
    if sample is data:
        return found
    out = []
    for w in found:
        try:
            out.append(fit_wiener(model, data, w.sensor, floor))
        except ArxidError:
            continue
    return out


def rank_sensors(
    suspects: list[Suspect], sensors: list[Suspect], alpha: float, min_improvement: float
) -> list[Suspect]:
    """The sensor suspects among the others: significant when their corrected p-value passes, they
    lower the validation error by ``min_improvement``, and lower it below the best other suspect's.

    Parameters
    ----------
    suspects : list of Suspect
        The judged suspects.
    sensors : list of Suspect
        From :func:`sensor_suspects`.
    alpha, min_improvement : float

    Returns
    -------
    list of Suspect
    """
    rival = min(
        (s for s in suspects if s.significant and math.isfinite(s.rms_sim_val_after)),
        key=lambda s: s.rms_sim_val_after,
        default=None,
    )
    out = []
    for s in sensors:
        if s.p_value >= alpha:
            s = replace(s, note=f"p-value {s.p_value:.2g} is not below {alpha:g}: no evidence it is missing")
        elif not s.improvement >= min_improvement:
            s = replace(s, note=f"validation error falls only {100 * s.improvement:.1f} %")
        elif rival is not None and s.rms_sim_val_after >= rival.rms_sim_val_after:
            s = replace(s, note=f"no better than {rival.effect}", explained_by=rival.effect)
        else:
            s = replace(s, significant=True)
        out.append(s)
    if any(s.significant for s in out):
        best = min((s for s in out if s.significant), key=lambda s: s.rms_sim_val_after)
        out = [s if s is best or not s.significant else replace(s, significant=False) for s in out]
        suspects = [_explained(s, best) for s in suspects]
    return suspects + out


def _explained(s: Suspect, sensor: Suspect) -> Suspect:
    if not s.significant:
        return s
    note = f"the output read through a sensor shape ({sensor.effect}) explains more"
    return replace(s, significant=False, note=note, explained_by=sensor.effect)
