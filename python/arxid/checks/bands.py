"""Confidence bands on a model's curves from its parameter covariance.

A fitted ARX model carries its parameter estimate θ̂ and covariance Σ = σ̂² (ΦᵀΦ)⁻¹
(``model.covariance_``). The bands here say how far a curve computed from the model (a step
response, a free-run simulation, a frequency response) could move when the parameters move within
that uncertainty, as MATLAB's ``showConfidence`` does on ``compare``, ``step`` and ``bode`` plots.

Two methods, both over θ ~ N(θ̂, Σ):

* ``"first-order"`` (default): the curve's standard deviation by first-order (delta-method)
  propagation, sd(t)² = Σ_k (∂y(t)/∂d_k)², where d_k = √λ_k v_k are the principal directions of Σ
  (λ_k, v_k its eigenpairs) and each derivative is a central difference of ±1 % of d_k. It costs
  two simulations per parameter; the band is ŷ ± z·sd with z the two-sided normal point of ``level``.
* ``"monte-carlo"``: ``n_draws`` parameter vectors drawn from N(θ̂, Σ) and simulated; the band is
  the draws' central ``level`` percentile range and sd their standard deviation. Draws whose
  simulation diverges are counted in ``n_diverged`` and left out.

The frequency response is linear in the numerator and rational in the denominator, so its
first-order variance is computed from the analytic gradient (:func:`frequency_response`).

Notes
-----
Σ is the least-squares covariance: it assumes the equation error is white and the structure is
right. With coloured residuals (the residual tests say "not white") the bands are too narrow; they
show parameter uncertainty, not model error, which is what :func:`arxid.frequency_check` and
:func:`arxid.compare` show.

Examples
--------
>>> import numpy as np, arxid
>>> from arxid.checks.bands import step_band
>>> rng = np.random.default_rng(0)
>>> u = rng.standard_normal(2000)
>>> y = np.zeros(2000)
>>> for t in range(1, 2000):
...     y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + 0.05 * rng.standard_normal()
>>> band = step_band(arxid.arx(arxid.IOData(y, u, ts=0.01), 1, 1, 1), 100)
>>> bool(np.all(band.lower <= band.response) and np.all(band.response <= band.upper))
True
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable

import numpy as np

from .._base import _core
from .._base.metrics import normal_quantile
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.arguments import check_data, check_model
from ..models.arx_model import ArxModel
from ..models.polynomial import PolynomialModel

__all__ = [
    "ResponseBand",
    "response_band",
    "step_band",
    "free_run_band",
    "frequency_response",
    "normal_quantile",
    "DEFAULT_LEVEL",
]

#: Confidence level of every band arxid draws (the residual tests' bounds are 99 % too).
DEFAULT_LEVEL = 0.99

_METHODS = ("first-order", "monte-carlo")
_STEP = 0.01  # central-difference step, as a fraction of one principal standard deviation


@record(eq=False)
class ResponseBand:
    """A curve of the model with its confidence band.

    Attributes
    ----------
    time : ndarray of shape (n,)
        Seconds.
    response : ndarray of shape (n,)
        The curve of the estimated model.
    sd : ndarray of shape (n,)
        Standard deviation of the curve over θ ~ N(θ̂, Σ).
    lower, upper : ndarray of shape (n,)
        The band at ``level``.
    level : float
        Confidence level, e.g. 0.99.
    method : str
        ``"first-order"`` or ``"monte-carlo"``.
    n_draws : int
        Simulations made (Monte Carlo draws, or 2 per principal direction).
    n_diverged : int
        Monte Carlo draws left out because their simulation diverged.
    """

    time: np.ndarray
    response: np.ndarray
    sd: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    level: float
    method: str
    n_draws: int
    n_diverged: int = 0

    @property
    def description(self) -> str:
        """One phrase for captions, e.g. ``99 % band from the parameter covariance (first-order)``."""
        return f"{100 * self.level:g} % band from the parameter covariance ({self.method})"

    def to_dict(self) -> dict:
        """JSON-ready summary (not the curves): level, method, draws, and the largest half-width.

        Returns
        -------
        dict
        """
        half = 0.5 * (self.upper - self.lower)
        return {
            "level": self.level,
            "method": self.method,
            "n_draws": self.n_draws,
            "n_diverged": self.n_diverged,
            "max_half_width": float(np.nanmax(half)) if np.isfinite(half).any() else None,
        }


def _with_parameters(model: ArxModel, theta: np.ndarray) -> ArxModel:
    """A copy of ``model`` whose parameters are ``theta`` (same structure, rows and data)."""
    m = copy.copy(model)
    m.parameters_ = np.asarray(theta, dtype=float)
    return m


def _directions(model: ArxModel) -> np.ndarray:
    """Principal standard-deviation directions of the covariance, one per row (d_k = √λ_k v_k)."""
    cov = np.asarray(model.covariance_, dtype=float)
    if cov.shape != (model.n_params, model.n_params) or not np.isfinite(cov).all():
        raise ArxidError("the model has no finite parameter covariance, so no confidence band can be drawn")
    lam, vec = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = lam > 0
    return (vec[:, keep] * np.sqrt(lam[keep])).T


def _first_order(model: ArxModel, curve: Callable[[ArxModel], np.ndarray]) -> tuple[np.ndarray, np.ndarray, int]:
    nominal = np.asarray(curve(model), dtype=float)
    var = np.zeros_like(nominal)
    dirs = _directions(model)
    theta = model.parameters_
    with np.errstate(all="ignore"):
        for d in dirs:
            hi = np.asarray(curve(_with_parameters(model, theta + _STEP * d)), dtype=float)
            lo = curve(_with_parameters(model, theta - _STEP * d))
            # ((hi − lo) / 2h)², in place: no temporaries the size of the curve
            np.subtract(hi, lo, out=hi)
            np.divide(hi, 2.0 * _STEP, out=hi)
            np.multiply(hi, hi, out=hi)
            var += hi
    return nominal, np.sqrt(var), 2 * len(dirs)


def _monte_carlo(
    model: ArxModel, curve: Callable[[ArxModel], np.ndarray], level: float, n_draws: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    nominal = np.asarray(curve(model), dtype=float)
    dirs = _directions(model)
    rng = np.random.default_rng(seed)
    thetas = model.parameters_ + rng.standard_normal((n_draws, len(dirs))) @ dirs
    runs = np.full((n_draws, len(nominal)), np.nan)
    limit = 1e3 * max(float(np.nanmax(np.abs(nominal))), 1e-300) if np.isfinite(nominal).any() else math.inf
    diverged = 0
    with np.errstate(all="ignore"):
        for i, th in enumerate(thetas):
            r = np.asarray(curve(_with_parameters(model, th)), dtype=float)
            if np.any(np.abs(r[np.isfinite(nominal)]) > limit) or not np.isfinite(r[np.isfinite(nominal)]).all():
                diverged += 1
                continue
            runs[i] = r
    if diverged == n_draws:
        raise ArxidError("every Monte Carlo draw diverged: the model is too uncertain for a band")
    tail = 100.0 * (1.0 - level) / 2.0
    lo, hi = np.nanpercentile(runs, [tail, 100.0 - tail], axis=0)
    return nominal, np.nanstd(runs, axis=0), lo, hi, diverged


def response_band(
    model: ArxModel,
    curve: Callable[[ArxModel], np.ndarray],
    time: np.ndarray,
    *,
    level: float = DEFAULT_LEVEL,
    method: str = "first-order",
    n_draws: int = 500,
    seed: int = 0,
) -> ResponseBand:
    """The band of any curve the model computes, over θ ~ N(θ̂, Σ).

    Parameters
    ----------
    model : ArxModel
        A fitted model.
    curve : callable
        ``curve(m)`` returns the curve (ndarray of shape (n,)) of a model ``m`` with the same
        structure as ``model`` and other parameters.
    time : ndarray of shape (n,)
        Seconds, stored with the band.
    level : float
        Confidence level (default 0.99).
    method : {"first-order", "monte-carlo"}
        See the module notes.
    n_draws : int
        Monte Carlo draws.
    seed : int
        Seed of the Monte Carlo draws.

    Returns
    -------
    ResponseBand
    """
    model = check_model(model)
    z = normal_quantile(level)
    if method == "first-order":
        nominal, sd, n = _first_order(model, curve)
        return ResponseBand(np.asarray(time), nominal, sd, nominal - z * sd, nominal + z * sd, level, method, n)
    if method == "monte-carlo":
        if int(n_draws) < 10:
            raise ArxidError(f"n_draws must be at least 10 for a Monte Carlo band, got {n_draws}")
        nominal, sd, lo, hi, bad = _monte_carlo(model, curve, level, int(n_draws), seed)
        return ResponseBand(np.asarray(time), nominal, sd, lo, hi, level, method, int(n_draws), bad)
    raise ArxidError(f"method must be one of {_METHODS}, got {method!r}")


def step_band(
    model: ArxModel,
    n_samples: int,
    amplitude: float = 1.0,
    input: int = 0,
    *,
    level: float = DEFAULT_LEVEL,
    method: str = "first-order",
    n_draws: int = 500,
    seed: int = 0,
) -> ResponseBand:
    """Response to a step of ``amplitude`` on ``input`` from rest, with its confidence band.

    Parameters
    ----------
    model : ArxModel
    n_samples : int
    amplitude : float
    input : int
    level, method, n_draws, seed
        As in :func:`response_band`.

    Returns
    -------
    ResponseBand
    """
    model = check_model(model)
    t = np.arange(int(n_samples)) * model.ts
    return response_band(
        model,
        lambda m: m.step(n_samples, amplitude, input),
        t,
        level=level,
        method=method,
        n_draws=n_draws,
        seed=seed,
    )


def free_run_band(
    model: ArxModel,
    data: IOData,
    *,
    level: float = DEFAULT_LEVEL,
    method: str = "first-order",
    n_draws: int = 500,
    seed: int = 0,
) -> ResponseBand:
    """Free-run simulation on ``data`` (as :func:`arxid.compare` draws it) with its confidence band.

    Parameters
    ----------
    model : ArxModel
    data : IOData
        Measured inputs (and the initial outputs the simulation starts from).
    level, method, n_draws, seed
        As in :func:`response_band`.

    Returns
    -------
    ResponseBand
        ``time`` is :attr:`IOData.time`; samples without a prediction are NaN.
    """
    model, data = check_model(model), check_data(data)
    if method == "first-order":
        z = normal_quantile(level)
        got = _free_run_first_order(model, data)
        if got is not None:
            nominal, sd, n = got
            return ResponseBand(
                np.asarray(data.time), nominal, sd, nominal - z * sd, nominal + z * sd, level, method, n
            )
    return response_band(
        model,
        lambda m: m.predict(data, None),
        data.time,
        level=level,
        method=method,
        n_draws=n_draws,
        seed=seed,
    )


def _free_run_first_order(model: ArxModel, data: IOData) -> tuple[np.ndarray, np.ndarray, int] | None:
    """:func:`_first_order` of the free run, its pairs of runs summed in the Rust core (the same
    numbers to the bit, without an array per run); None for a model the core does not run so: an
    output term, a polynomial model, or a missing sample that restarts the free run."""
    if isinstance(model, PolynomialModel) or model.layout_.output_terms:
        return None
    nominal = np.asarray(model.predict(data, None), dtype=float)
    dirs = _directions(model)
    theta = model.parameters_
    runs = np.empty((2 * len(dirs), len(theta)))
    runs[0::2], runs[1::2] = theta + _STEP * dirs, theta - _STEP * dirs
    lay = model._layout(data)
    var = _core.free_run_variance(
        np.require(data.y, requirements=["C", "A"]),
        lay.u,
        list(data.experiment_starts),
        model.na_,
        list(lay.nb),
        list(lay.nk),
        runs,
        _STEP,
        first_lag=model.first_lag_,
    )
    return None if var is None else (nominal, np.sqrt(var), 2 * len(dirs))


def frequency_response(model: ArxModel, frequency: np.ndarray, input: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Frequency response B(e^{-jω})/(A(e^{-jω}) F(e^{-jω})) of ``input`` and its first-order standard
    deviation (F = 1 for ARX and ARMAX models).

    Parameters
    ----------
    model : ArxModel or PolynomialModel
    frequency : ndarray of shape (n,)
        Frequencies in Hz (ω = 2π f ts).
    input : int
        Which input; the linear part only (effect terms have no transfer function).

    Returns
    -------
    response : ndarray of complex, shape (n,)
    sd : ndarray of shape (n,)
        √E|δG|², the root of the summed variances of the real and imaginary parts from the
        analytic gradient of G with respect to θ and the covariance Σ.
    """
    model = check_model(model)
    f = np.asarray(frequency, dtype=float)
    zinv = np.exp(-2j * np.pi * f * model.ts)
    na, nk, nb = model.na_, model.nk_[input], model.nb_[input]
    powers_a = zinv[:, None] ** np.arange(1, na + 1)[None, :]
    big_a = 1.0 + powers_a @ model.a[1:]
    bpow = zinv[:, None] ** np.arange(nk, nk + nb)[None, :]
    big_b = bpow @ model.b[input][nk:]
    f_coefs, f_start = _input_denominator(model, input)
    powers_f = zinv[:, None] ** np.arange(1, len(f_coefs))[None, :]
    big_f = 1.0 + powers_f @ f_coefs[1:]
    g = big_b / (big_a * big_f)
    grad = np.zeros((len(f), model.n_params), dtype=complex)
    grad[:, :na] = -(g / big_a)[:, None] * powers_a
    b_start = na + int(sum(model.nb_[:input]))
    grad[:, b_start : b_start + nb] = bpow / (big_a * big_f)[:, None]
    grad[:, f_start : f_start + len(f_coefs) - 1] = -(g / big_f)[:, None] * powers_f
    cov = np.asarray(model.covariance_, dtype=float)
    var = np.einsum("fi,ij,fj->f", grad.real, cov, grad.real) + np.einsum("fi,ij,fj->f", grad.imag, cov, grad.imag)
    return g, np.sqrt(np.maximum(var, 0.0))


def _input_denominator(model: ArxModel, input: int) -> tuple[np.ndarray, int]:
    """F_i of an OE or BJ model (``[1.0]`` for ARX and ARMAX) and where its parameters start in θ
    (``getpvec`` order: A, B per input, C, D, F per input)."""
    if not isinstance(model, PolynomialModel) or not model.nf_[input]:
        return np.ones(1), 0
    start = model.na_ + int(sum(model.nb_)) + model.nc_ + model.nd_ + int(sum(model.nf_[:input]))
    return model.f[input], start
