"""Battery-aware total thrust model class (Staub & Franchi, ICRA 2015, eqs. 5-10, Tables I-II).

    tau F_T' = sum_{j<=nu, k<=nb} alpha_jk v_jk - F_T,    v_jk = beta^k sum_i u_i^j

``u_i`` are the motor commands (PWM), ``beta`` the battery voltage. Sampled with a zero-order
hold, ``F[t+1] = a F[t] + (1 - a) sum alpha_jk v_jk[t]`` with ``a = exp(-ts/tau)``: linear in
``a`` and ``(1 - a) alpha`` (an ARX(1, 1, 0) with effects), then ``tau`` is refined by the
free-run error, with the ``alpha`` that minimise it for each ``tau`` found by least squares.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._base import metrics
from ..data.iodata import IOData
from ..exceptions import DataError

__all__ = [
    "ThrustModel",
    "ThrustClassRow",
    "ThrustClassTable",
    "fit_thrust_model",
    "thrust_model_class",
    "thrust_from_accelerometer",
    "SEED001_MODEL_IDS",
]

#: Staub & Franchi's Table I: model id for each (nu, nbeta).
SEED001_MODEL_IDS = {(0, 0): 1, (0, 1): 2, (1, 0): 3, (1, 1): 4, (0, 2): 5, (2, 0): 6, (1, 2): 7, (2, 1): 8, (2, 2): 9}


def thrust_from_accelerometer(az, mass: float) -> np.ndarray:
    """Total thrust ``F_T = m a_z`` from the body-z accelerometer (Staub & Franchi eq. 13).

    Parameters
    ----------
    az : array_like
        Body-z specific force [m/s^2].
    mass : float
        Vehicle mass [kg].

    Returns
    -------
    ndarray, same shape as ``az``
        Thrust [N].
    """
    return float(mass) * np.asarray(az, dtype=float)


def _features(u, beta, nu, nb):
    """v_jk = beta^k sum_i u_i^j, columns ordered j-major as alpha_00, alpha_01, ..."""
    cols, names = [], []
    for j in range(nu + 1):
        s = (u**j).sum(axis=1)
        for k in range(nb + 1):
            cols.append(s * beta**k)
            names.append(f"alpha{j}{k}")
    return np.column_stack(cols), names


def _lowpass(v, a, init):
    """x[t+1] = a x[t] + (1 - a) v[t], x[0] = init, column-wise (scipy.signal.lfilter)."""
    from scipy.signal import lfilter

    # y[t] = a y[t-1] + (1 - a) v[t-1]; start from y[0] = init by filtering the shifted input
    vv = np.concatenate([v[:1] * 0, v[:-1]], axis=0)
    zi = np.atleast_1d(init)[None, :] if v.ndim == 2 else np.array([float(init)])
    out = lfilter([1.0 - a], [1.0, -a], vv, axis=0, zi=zi)[0]
    out[0] = init
    return out


def _unpack(data, inputs, vbat):
    if not isinstance(data, IOData):
        raise DataError("pass an IOData with the thrust as output, motor commands as inputs and vbat")
    u = data.u if inputs is None else np.column_stack([data.signal(n) for n in inputs])
    return u, data.signal(vbat), data.y, data.ts


@dataclass(frozen=True)
class ThrustModel:
    """Member ``(nu, nb)`` of Staub & Franchi's model class.

    Attributes
    ----------
    nu, nb : int
        Polynomial orders in the command and in the battery voltage.
    tau : float
        Time constant [s].
    alpha : ndarray of shape ((nu+1)*(nb+1),)
        ``alpha_jk``, j-major (``alpha00, alpha01, ..., alpha10, ...``).
    ts : float
    """

    nu: int
    nb: int
    tau: float
    alpha: np.ndarray
    ts: float

    @property
    def n_params(self) -> int:
        """``(nu + 1)(nb + 1) + 1`` as in Staub & Franchi's Table I."""
        return (self.nu + 1) * (self.nb + 1) + 1

    def static(self, u, beta) -> np.ndarray:
        """Steady-state thrust ``sum alpha_jk v_jk``.

        Parameters
        ----------
        u : array_like of shape (n_samples,) or (n_samples, n_motors)
            Motor commands.
        beta : array_like of shape (n_samples,)
            Battery voltage [V].

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        u = np.asarray(u, dtype=float)
        u = u[:, None] if u.ndim == 1 else u
        phi, _ = _features(u, np.asarray(beta, dtype=float), self.nu, self.nb)
        return phi @ self.alpha

    def simulate(self, u, beta, f0=None) -> np.ndarray:
        """Free-run thrust.

        Parameters
        ----------
        u : array_like of shape (n_samples,) or (n_samples, n_motors)
            Motor commands.
        beta : array_like of shape (n_samples,)
            Battery voltage [V].
        f0 : float, optional
            Initial thrust (default: the steady-state thrust of the first sample).

        Returns
        -------
        ndarray of shape (n_samples,)
        """
        target = self.static(u, beta)
        a = np.exp(-self.ts / self.tau)
        f0 = target[0] if f0 is None else f0
        return _lowpass(target, a, np.asarray(f0, dtype=float))

    def __str__(self) -> str:
        _, names = _features(np.ones((1, 1)), np.ones(1), self.nu, self.nb)
        terms = ", ".join(f"{n}={v:.4g}" for n, v in zip(names, self.alpha, strict=True))
        return f"thrust model nu={self.nu} nb={self.nb}: tau={self.tau:.4g} s, {terms}"


def fit_thrust_model(
    data: IOData, nu: int = 1, nb: int = 1, inputs=None, vbat: str = "vbat", refine: bool = True, tau_bounds=None
) -> ThrustModel:
    """Fit one member of the class.

    Parameters
    ----------
    data : IOData
        Output the total thrust [N] (or ``m a_z``, see :func:`thrust_from_accelerometer`); inputs
        the motor commands (one column per motor, or one shared command).
    nu, nb : int
        Orders in the command and in the battery voltage, each in {0, 1, 2} in Staub & Franchi.
    inputs : sequence of str, optional
        Signals to use as the commands (default: the inputs).
    vbat : str
        Name of the battery-voltage signal.
    refine : bool
        Refine ``tau`` by the free-run error (the ``alpha`` follow by least squares).
    tau_bounds : (float, float), optional
        Search interval for ``tau`` [s]; default ``(0.1 ts, 50 ts)``.

    Returns
    -------
    ThrustModel
    """
    from scipy.optimize import minimize_scalar

    if nu < 0 or nb < 0:
        raise DataError(f"orders must be non-negative, got nu={nu}, nb={nb}")
    u, beta, f, ts = _unpack(data, inputs, vbat)
    phi, _ = _features(u, beta, nu, nb)
    scale = np.abs(phi).max(axis=0)
    scale[scale == 0] = 1.0
    # equation error: F[t+1] = a F[t] + sum theta_jk v_jk[t]
    X = np.column_stack([f[:-1], phi[:-1] / scale])
    sol = np.linalg.lstsq(X, f[1:], rcond=None)[0]
    a = float(np.clip(sol[0], 1e-6, 1 - 1e-9))
    alpha = sol[1:] / scale / (1 - a)
    tau = -ts / np.log(a)

    def free_run(t):
        aa = np.exp(-ts / t)
        filt = _lowpass(phi / scale, aa, phi[0] / scale)
        coef = np.linalg.lstsq(filt, f, rcond=None)[0]
        e = f - filt @ coef
        return float(e @ e), coef / scale

    if refine:
        tau_bounds = (0.1 * ts, 50 * ts) if tau_bounds is None else tau_bounds
        lo, hi = np.log(tau_bounds[0]), np.log(tau_bounds[1])
        res = minimize_scalar(
            lambda lt: free_run(np.exp(lt))[0], bounds=(lo, hi), method="bounded", options={"xatol": 1e-4}
        )
        tau = float(np.exp(res.x))
        alpha = free_run(tau)[1]
    return ThrustModel(nu=nu, nb=nb, tau=float(tau), alpha=np.asarray(alpha, dtype=float), ts=ts)


@dataclass(frozen=True)
class ThrustClassRow:
    """One row of the class table."""

    model_id: int
    nu: int
    nb: int
    n_params: int
    tau: float
    rms: float
    median_abs_error: float
    fit_percent: float
    model: ThrustModel


@dataclass(frozen=True)
class ThrustClassTable:
    """Staub & Franchi's model class fitted on estimation data and scored by free-run error on
    validation data (Table I numbering)."""

    rows: tuple

    def row(self, nu: int, nb: int) -> ThrustClassRow:
        """The row of one model.

        Parameters
        ----------
        nu, nb : int
            Orders in the command and in the battery voltage.

        Returns
        -------
        ThrustClassRow

        Raises
        ------
        KeyError
            When the table has no such model.
        """
        for r in self.rows:
            if (r.nu, r.nb) == (nu, nb):
                return r
        raise KeyError((nu, nb))

    def best(self) -> ThrustClassRow:
        """The simplest good model.

        Returns
        -------
        ThrustClassRow
            Fewest parameters among the models within 5 % of the smallest validation RMS.
        """
        best = min(r.rms for r in self.rows)
        return min((r for r in self.rows if r.rms <= 1.05 * best), key=lambda r: (r.n_params, r.rms))

    def to_pandas(self):
        """The table as a pandas DataFrame.

        Returns
        -------
        pandas.DataFrame
            One row per model: id, orders, parameter count, time constant and the scores.
        """
        import pandas as pd

        return pd.DataFrame(
            [
                {
                    k: getattr(r, k)
                    for k in ("model_id", "nu", "nb", "n_params", "tau", "rms", "median_abs_error", "fit_percent")
                }
                for r in self.rows
            ]
        )

    def __str__(self) -> str:
        head = " id  nu  nb  params   tau [s]    rms        median|e|   fit %"
        lines = [head] + [
            f"{r.model_id:3d} {r.nu:3d} {r.nb:3d} {r.n_params:6d}  {r.tau:9.4g}  {r.rms:9.4g}  "
            f"{r.median_abs_error:9.4g}  {r.fit_percent:7.2f}"
            for r in self.rows
        ]
        b = self.best()
        lines.append(f"simplest model within 5 % of the best: id {b.model_id} (nu={b.nu}, nb={b.nb})")
        return "\n".join(lines)


def thrust_model_class(
    estimation: IOData,
    validation: IOData,
    orders=(0, 1, 2),
    inputs=None,
    vbat: str = "vbat",
    skip_constant: bool = True,
) -> ThrustClassTable:
    """Fit every ``(nu, nb)`` in ``orders x orders`` and score it in free run on validation data.

    Parameters
    ----------
    estimation, validation : IOData
        As for :func:`fit_thrust_model`. For Staub & Franchi's claim 2, let the battery voltage in the
        validation data span other values than in the estimation data.
    orders : sequence of int
    inputs, vbat
        As for :func:`fit_thrust_model`.
    skip_constant : bool
        Leave out models without the command (``nu = 0``: Staub & Franchi's models 1, 2 and 5).

    Returns
    -------
    ThrustClassTable
        Rows in order of model id.
    """
    rows = []
    uv, bv, fv, _ = _unpack(validation, inputs, vbat)
    for nu in orders:
        for nb in orders:
            if skip_constant and nu == 0:
                continue
            m = fit_thrust_model(estimation, nu, nb, inputs=inputs, vbat=vbat)
            sim = m.simulate(uv, bv, f0=fv[0])
            rows.append(
                ThrustClassRow(
                    model_id=SEED001_MODEL_IDS.get((nu, nb), 0),
                    nu=nu,
                    nb=nb,
                    n_params=m.n_params,
                    tau=m.tau,
                    rms=metrics.prediction_rms(fv, sim),
                    median_abs_error=float(np.median(np.abs(fv - sim))),
                    fit_percent=metrics.fit_percent(fv, sim),
                    model=m,
                )
            )
    rows.sort(key=lambda r: (r.model_id, r.nu, r.nb))
    return ThrustClassTable(rows=tuple(rows))
