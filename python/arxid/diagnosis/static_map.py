"""The static map of an input, estimated without assuming a shape, and the named shape nearest to it.

Bai's over-parameterisation (Automatica 34, 1998): the input is replaced by K piecewise-linear
"hat" functions of itself, one per knot (the input's levels on a staircase, else its quantiles),
each entering the model with the input's own lags. The linear fit gives a coefficient matrix Θ
(lags × knots); a Hammerstein plant makes it rank one, Θ = b·fᵀ, and the first pair of its SVD
gives the lag weights b and the shape f at the knots (the share of Θ's energy in that pair says how
well one shape explains the input).

What the report plots is the steady state the model reaches with the input held at each knot,
y_ss(k) = Σ_lags Θ[:, k] / A(1), in the output's units, with its band from the parameter
covariance (delta method): the map an engineer would measure on a test stand. Each named shape is
fitted to it (gain and offset by weighted least squares, its parameter on a grid) and its fit in
percent is listed; the nearest is the best.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._base import metrics
from .._base.order_statistics import distinct, quantiles
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arx_model import ArxModel
from ..models.effects import parse_effect
from ..models.input_shapes import InputShape
from .candidates import candidate_input_names
from .shapes import MIN_SCAN_LEVELS, input_levels

__all__ = ["StaticMap", "static_map", "shape_maps", "shape_map_dict", "MAP_KNOTS"]

#: Knots of the piecewise-linear map on a rich input (its quantiles, ends included).
MAP_KNOTS = 9


@dataclass(frozen=True)
class StaticMap:
    """The estimated static map of one input.

    Attributes
    ----------
    input : str
    knots : ndarray
        Input values.
    steady : ndarray
        Steady-state output with the input held at each knot.
    band : ndarray
        Two standard errors of ``steady``.
    rank_one_share : float
        Share of the coefficient matrix's energy in its first singular pair (1: one shape explains
        every lag, as a Hammerstein plant's does).
    matches : tuple of (str, float, InputShape or None)
        Each named shape (and the linear input) with its fit to the map in percent, best first.
    """

    input: str
    knots: np.ndarray
    steady: np.ndarray
    band: np.ndarray
    rank_one_share: float
    matches: tuple[tuple[str, float, InputShape | None], ...]

    @property
    def nearest(self) -> str:
        """The named shape that fits the map best (``"linear"`` when the straight line does)."""
        return self.matches[0][0] if self.matches else ""

    def curve(self, shape: InputShape | None, x: np.ndarray) -> np.ndarray:
        """A shape scaled to the map (gain and offset by weighted least squares), evaluated at ``x``."""
        f = self._evaluate(shape, self.knots)
        coef = _weighted_line(f, self.steady, self.band)
        return coef[0] + coef[1] * self._evaluate(shape, np.asarray(x, dtype=float))

    @staticmethod
    def _evaluate(shape: InputShape | None, x: np.ndarray) -> np.ndarray:
        if shape is None:
            return np.asarray(x, dtype=float)
        return shape.evaluate(np.maximum(x, 0.0) if shape.kind == "power" else x)

    def fit_of(self, shape: InputShape | None) -> float:
        """The fit in percent of ``shape`` (None: a straight line) to the map."""
        return _fit_percent(self._evaluate(shape, self.knots), self.steady, self.band)

    def lines(self) -> list[str]:
        """The map's sentence and each shape's fit, for the text report."""
        head = f"static map of {self.input} (steady state with {self.input} held, {self.knots.size} knots):"
        fits = ", ".join(f"{label} {fit:.1f} %" for label, fit, _ in self.matches[:5])
        return [head, f"  nearest named shapes (fit to the map): {fits}"]


def _hats(x: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Piecewise-linear interpolation weights of x on the knots: columns summing to 1."""
    out = np.zeros((x.size, knots.size))
    xc = np.clip(x, knots[0], knots[-1])
    j = np.clip(np.searchsorted(knots, xc, side="right") - 1, 0, knots.size - 2)
    w = (xc - knots[j]) / (knots[j + 1] - knots[j])
    rows = np.arange(x.size)
    out[rows, j] = 1.0 - w
    out[rows, j + 1] += w
    out[~np.isfinite(x)] = np.nan
    return out


def _knots(x: np.ndarray) -> np.ndarray:
    levels = input_levels(x)
    if levels.size < MIN_SCAN_LEVELS:
        return levels
    return distinct(quantiles(x[np.isfinite(x)], np.linspace(0, 1, MAP_KNOTS)))


def static_map(model: ArxModel, data: IOData, name: str) -> StaticMap:
    """The static map of input ``name`` with ``model``'s orders (its effects left out).

    Parameters
    ----------
    model : ArxModel
        Gives na and the input's nb and nk.
    data : IOData
        Estimation data.
    name : str
        The input (as candidates name it: its name, or u1, u2, ...).

    Returns
    -------
    StaticMap

    Raises
    ------
    ArxidError
        When the input has fewer than three levels, or the over-parameterised fit fails.
    """
    i = candidate_input_names(data).index(name)
    x = np.asarray(data.u[:, i], dtype=float)
    knots = _knots(x)
    if knots.size < 3:
        raise ArxidError(f"{name} takes {knots.size} levels: a static map needs at least three")
    hats = _hats(x, knots)[:, 1:]  # the first knot is the reference level: the offset carries it
    others = [j for j in range(data.n_inputs) if j != i]
    u = np.column_stack([data.u[:, others], hats])
    names = [data.input_names[j] for j in others] + [f"knot{k}" for k in range(1, knots.size)]
    extended = data.with_signals(u=u, input_names=names)
    nb = [model.nb_[j] for j in others] + [model.nb_[i]] * (knots.size - 1)
    nk = [model.nk_[j] for j in others] + [model.nk_[i]] * (knots.size - 1)
    fit = ArxModel(na=model.na_, nb=nb, nk=nk, effects=["const"]).fit(extended)
    theta = np.column_stack([np.zeros(fit.b[-1].size), *fit.b[len(others) :]])  # (lags, knots)
    steady, band = _steady_state(fit, len(others), knots.size)
    s = np.linalg.svd(theta, compute_uv=False)
    share = float(s[0] ** 2 / np.sum(s**2)) if s.size and np.sum(s**2) > 0 else float("nan")
    return StaticMap(name, knots, steady, band, share, _matches(name, knots, steady, band))


def _steady_state(fit: ArxModel, first: int, n_knots: int) -> tuple[np.ndarray, np.ndarray]:
    """y_ss at each knot = (Σ θ + offset) / A(1), and two standard errors by the delta method."""
    a1 = float(np.sum(fit.a))
    na = fit.na_
    starts = na + np.concatenate([[0], np.cumsum(fit.nb_)])
    offset = fit.regressor_names_.index("const")
    steady, band = np.zeros(n_knots), np.zeros(n_knots)
    for k in range(n_knots):
        cols = np.arange(starts[first + k - 1], starts[first + k]) if k else np.zeros(0, dtype=int)
        cols = np.append(cols, offset)
        c = float(np.sum(fit.parameters_[cols]))
        grad = np.zeros(fit.parameters_.size)
        grad[cols] = 1.0 / a1
        grad[:na] = -c / a1**2
        steady[k] = c / a1
        band[k] = 2.0 * float(np.sqrt(max(grad @ fit.covariance_ @ grad, 0.0)))
    return steady, band


def _weights(y: np.ndarray, band: np.ndarray) -> np.ndarray:
    """1 / band, kept finite where a knot's band is zero."""
    return 1.0 / np.maximum(band, 1e-12 * max(float(np.max(np.abs(y))), 1.0))


def _weighted_line(f: np.ndarray, y: np.ndarray, band: np.ndarray) -> np.ndarray:
    w = _weights(y, band)
    design = np.column_stack([np.ones_like(f), f]) * w[:, None]
    return np.linalg.lstsq(design, y * w, rcond=None)[0]


def _fit_percent(f: np.ndarray, y: np.ndarray, band: np.ndarray) -> float:
    """The weighted fit of a + b·f to the map, as :func:`arxid._base.metrics.fit_percent_from_norms` defines it."""
    w = _weights(y, band)
    coef = _weighted_line(f, y, band)
    error = float(np.linalg.norm((y - coef[0] - coef[1] * f) * w))
    centred = float(np.linalg.norm((y - np.average(y, weights=w**2)) * w))
    return float(metrics.fit_percent_from_norms(error, centred))


def _matches(name: str, knots: np.ndarray, steady: np.ndarray, band: np.ndarray) -> tuple:
    """Each family's best member fitted to the map, with its fit in percent, best first."""
    lo, hi, top = float(knots[0]), float(knots[-1]), float(np.max(np.abs(knots)))
    families: dict[str, list[InputShape]] = {}
    if lo >= 0:
        families["power"] = [InputShape("power", name, (float(p),)) for p in np.geomspace(0.25, 4, 41)]
    if lo < 0 < hi:
        families["signed power"] = [InputShape("signed power", name, (float(p),)) for p in np.geomspace(0.25, 4, 41)]
    inner = np.linspace(lo, hi, 42)[1:-1]
    families["saturation"] = [
        InputShape("saturation", name, (float(a), float(b))) for a in inner for b in inner if a < b
    ]
    families["dead zone"] = [InputShape("dead zone", name, (float(c),)) for c in np.linspace(0, top, 41)[1:-1]]
    out: list[tuple[str, float, InputShape | None]] = [("linear", _fit_percent(knots, steady, band), None)]
    for kind, shapes in families.items():
        fits = [_fit_percent(StaticMap._evaluate(s, knots), steady, band) for s in shapes]
        j = int(np.nanargmax(fits))
        out.append((f"{kind} {shapes[j].text}", fits[j], shapes[j]))
    return tuple(sorted(out, key=lambda m: -np.nan_to_num(m[1], nan=-np.inf)))


def shape_maps(model: object, data: IOData) -> tuple[tuple[InputShape, StaticMap], ...]:
    """The shape of each input ``model`` feeds through one (``through(...)``), with the input's
    static map estimated on ``data`` at the model's orders (empty for a model without a shape).

    Parameters
    ----------
    model : ArxModel or another fitted model
    data : IOData
        Estimation data.

    Returns
    -------
    tuple of (InputShape, StaticMap)
    """
    if not isinstance(model, ArxModel):
        return ()
    out = []
    for e in model.effects:
        shape = parse_effect(e, data).shape if e.startswith("through(") else None
        if shape is None or shape.kind == "product":
            continue
        try:
            out.append((shape, static_map(model, data, shape.signal)))
        except ArxidError:
            continue
    return tuple(out)


def shape_map_dict(shape: InputShape, m: StaticMap) -> dict:
    """One entry of ``Analysis.to_dict()["input_shapes"]``."""
    return {
        "shape": shape.effect,
        "physics": shape.physics(),
        "input": m.input,
        "knots": m.knots.tolist(),
        "steady_state": m.steady.tolist(),
        "band": m.band.tolist(),
        "rank_one_share": m.rank_one_share,
        "nearest": [{"shape": label, "fit": fit} for label, fit, _ in m.matches],
    }
