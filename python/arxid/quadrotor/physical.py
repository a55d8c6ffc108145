"""Physical parameters by structured least squares, after a published neural-network study.

Thrust and torque coefficients from static stand data, and the principal inertias from
Newton-Euler rotational data, each as a closed-form least-squares problem with standard errors.
That study, which estimates the parameters of a Newton-Euler quadrotor model, trains a linear
neural network without bias for the same purpose; with linear activations and no bias its output
is linear in the same regressors, so at convergence it reaches this least-squares estimate, which
QR gives directly.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._base import metrics
from ..exceptions import DataError, IdentifiabilityError

__all__ = ["LeastSquaresEstimate", "structured_lstsq", "thrust_torque_coefficients", "inertia_from_rotation"]


@dataclass(frozen=True)
class LeastSquaresEstimate:
    """Parameters of a linear-in-parameters model with standard errors.

    Attributes
    ----------
    names : tuple of str
    values : ndarray of shape (n_params,)
    stderr : ndarray of shape (n_params,)
        From ``sigma^2 (Phi^T Phi)^-1`` with ``sigma^2 = RSS / (n - p)`` (white-noise errors).
    rms : float
        Residual RMS.
    n_samples : int
    """

    names: tuple
    values: np.ndarray
    stderr: np.ndarray
    rms: float
    n_samples: int

    def __getitem__(self, name: str) -> float:
        return float(self.values[self.names.index(name)])

    def relative_error(self, truth: dict) -> dict:
        """Relative error of the estimates against known values.

        Parameters
        ----------
        truth : dict of str to float
            True value of some parameters, by name.

        Returns
        -------
        dict of str to float
            ``{name: (estimate - truth) / truth}`` for the names in ``truth``.
        """
        return {k: (self[k] - v) / v for k, v in truth.items()}

    def to_dict(self) -> dict:
        """The estimates by name.

        Returns
        -------
        dict of str to float
        """
        return {n: float(v) for n, v in zip(self.names, self.values, strict=True)}

    def __str__(self) -> str:
        rows = [
            f"  {n:<8s} {v: .6g}  +- {s:.2g}  ({100 * s / abs(v) if v else np.inf:.2f} %)"
            for n, v, s in zip(self.names, self.values, self.stderr, strict=True)
        ]
        return "\n".join(rows + [f"  residual rms {self.rms:.4g}, {self.n_samples} rows"])


def structured_lstsq(phi, y, names) -> LeastSquaresEstimate:
    """Least squares ``y = Phi theta`` by QR, with standard errors.

    Parameters
    ----------
    phi : array_like of shape (n_rows, n_params)
    y : array_like of shape (n_rows,)
    names : sequence of str
        One name per parameter.

    Returns
    -------
    LeastSquaresEstimate
    """
    phi = np.asarray(phi, dtype=float)
    y = np.asarray(y, dtype=float).reshape(-1)
    if phi.ndim != 2 or phi.shape[0] != y.shape[0] or phi.shape[1] != len(names):
        raise DataError(f"regressors {phi.shape} do not match {y.shape[0]} rows and {len(names)} names")
    ok = np.all(np.isfinite(phi), axis=1) & np.isfinite(y)
    phi, y = phi[ok], y[ok]
    n, p = phi.shape
    if n <= p:
        raise DataError(f"{n} usable rows for {p} parameters; log more samples")
    scale = np.linalg.norm(phi, axis=0)
    if np.any(scale == 0):
        raise IdentifiabilityError(
            f"regressor {names[int(np.argmin(scale))]} is zero in every row; the data do not excite it",
            regressors=tuple(names),
        )
    q, r = np.linalg.qr(phi / scale)
    if np.abs(np.diag(r)).min() < 1e-10 * np.abs(np.diag(r)).max():
        raise IdentifiabilityError(
            "the regressors are collinear; excite the axes independently", regressors=tuple(names)
        )
    theta = np.linalg.solve(r, q.T @ y)
    e = y - (phi / scale) @ theta
    sigma2 = e @ e / (n - p)
    rinv = np.linalg.inv(r)
    cov = sigma2 * rinv @ rinv.T
    return LeastSquaresEstimate(
        names=tuple(names),
        values=theta / scale,
        stderr=np.sqrt(np.diag(cov)) / scale,
        rms=metrics.rms(e),
        n_samples=n,
    )


def thrust_torque_coefficients(speed, thrust, torque=None) -> tuple:
    """Thrust coefficient ``k`` (``f = k w^2``) and torque coefficient ``b`` (``Q = b w^2``).

    Parameters
    ----------
    speed : array_like of shape (n_samples,) or (n_samples, n_motors)
        Motor speed [rad/s]; with several motors the thrust is their sum (``sum_i w_i^2``).
    thrust : array_like of shape (n_samples,)
        Measured thrust [N].
    torque : array_like of shape (n_samples,), optional
        Measured reaction torque [N m] of the same motors.

    Returns
    -------
    (LeastSquaresEstimate, LeastSquaresEstimate or None)
        ``k`` and, when ``torque`` is given, ``b``: the neural-network study's second-order
        polynomial through the origin, closed form ``k = sum(w^2 f) / sum(w^4)``.
    """
    w = np.asarray(speed, dtype=float)
    w2 = (w * w).sum(axis=1) if w.ndim == 2 else w * w
    k = structured_lstsq(w2[:, None], thrust, ["k"])
    b = structured_lstsq(w2[:, None], torque, ["b"]) if torque is not None else None
    return k, b


def inertia_from_rotation(
    rates,
    accelerations=None,
    torques=None,
    rotor_speed_sum=None,
    *,
    ts: float | None = None,
    smoothing: int | None = None,
    delay: int = 0,
) -> LeastSquaresEstimate:
    """Principal inertias from Newton-Euler rotational data (Sarıoğlu & Kural eqs. 13-17).

    Parameters
    ----------
    rates : array_like of shape (n_samples, 3)
        Body rates ``p, q, r`` [rad/s].
    accelerations : array_like of shape (n_samples, 3), optional
        Angular accelerations ``p', q', r'`` [rad/s^2]. None: differentiate ``rates`` (needs
        ``ts``) by central differences, after the smoothing filter when ``smoothing`` is given.
    torques : array_like of shape (n_samples, 3)
        Body torques [N m] (e.g. ``k l (w4^2 - w2^2)`` from the motor speeds).
    rotor_speed_sum : array_like of shape (n_samples,), optional
        ``W = -w1 + w2 - w3 + w4`` [rad/s]; when given, the rotor inertia ``Ir`` is estimated too.
    ts : float, optional
        Sampling time [s]; needed when ``accelerations`` is None.
    smoothing : int, optional
        Window [samples, odd] of a quadratic Savitzky-Golay filter applied to every regressor
        column and to the torques alike (the same linear filter on both sides keeps the
        Newton-Euler relation exact) and, with ``accelerations=None``, used to differentiate the
        rates. Differentiating white gyro noise otherwise swamps the accelerations and pulls the
        inertias towards zero (errors in variables): on the default simulated flight (seed 4,
        10 s, ``delay=7``), ``Izz`` comes out 71 % low unsmoothed and 1.4 % low with
        ``smoothing=51`` (``Ixx``, ``Iyy`` within 0.05 %).
    delay : int
        Samples by which the logged rates lag the torques (the simulator's sensor delay minus one,
        ``delay_samples - 1`` = 7); the rates are shifted back before the fit.

    Returns
    -------
    LeastSquaresEstimate
        ``Ixx, Iyy, Izz`` (and ``Ir``).

    Notes
    -----
    The three axes stack into one linear problem in the inertias::

        Ixx p' + (Izz - Iyy) q r + Ir q W = tau_x
        Iyy q' + (Ixx - Izz) p r - Ir p W = tau_y
        Izz r' + (Iyy - Ixx) p q          = tau_z

    Solving the axes together uses the gyroscopic coupling as information, as the neural-network
    study's sparse network does.
    """
    om, acc_in, tau, W = _rotation_data(rates, accelerations, torques, rotor_speed_sum, ts, int(delay))
    smooth = _smoother(smoothing, om.shape[0])
    if acc_in is not None:
        acc = smooth(acc_in)
    else:
        # derivative of the smoothed rates = smoothed derivative (the filter commutes with d/dt),
        # so both sides of the relation see the same filter
        acc = np.gradient(smooth(om), float(ts or 0.0), axis=0)
    phi, names = _newton_euler_regressors(om, acc, W, smooth)
    tau = smooth(tau)
    return structured_lstsq(phi, np.concatenate([tau[:, 0], tau[:, 1], tau[:, 2]]), names)


def _rotation_data(
    rates, accelerations, torques, rotor_speed_sum, ts: float | None, delay: int
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray, np.ndarray | None]:
    """Checked rates, accelerations (None: to differentiate), torques and rotor speed sum, the rates
    and accelerations shifted back by ``delay`` samples onto the torques."""
    om = np.asarray(rates, dtype=float)
    if torques is None:
        raise DataError("torques are required: shape (n_samples, 3), e.g. k l (w4^2 - w2^2) from the motor speeds")
    tau = np.asarray(torques, dtype=float)
    if om.ndim != 2 or om.shape[1] != 3 or om.shape != tau.shape:
        raise DataError(f"rates and torques must both have shape (n_samples, 3), got {om.shape}, {tau.shape}")
    acc_in = None
    if accelerations is None:
        if not ts or ts <= 0:
            raise DataError("give accelerations, or ts (the sampling time) to differentiate the rates")
    else:
        acc_in = np.asarray(accelerations, dtype=float)
        if acc_in.shape != om.shape:
            raise DataError(f"accelerations must have the rates' shape {om.shape}, got {acc_in.shape}")
    W = None if rotor_speed_sum is None else np.asarray(rotor_speed_sum, dtype=float).reshape(-1)
    if delay < 0 or delay >= om.shape[0] - 3:
        raise DataError(f"delay must be between 0 and the record length, got {delay}")
    if delay:
        # rates[t + delay] belong to torques[t]
        om = om[delay:]
        tau = tau[: tau.shape[0] - delay]
        W = None if W is None else W[: W.size - delay]
        acc_in = None if acc_in is None else acc_in[delay:]
    return om, acc_in, tau, W


def _smoother(smoothing: int | None, n: int) -> Callable[[np.ndarray], np.ndarray]:
    """The quadratic Savitzky-Golay filter of ``smoothing`` samples along axis 0 (identity for None),
    checked against a record of ``n`` samples."""
    if smoothing is None:
        return _identity
    from scipy.signal import savgol_filter

    win = int(smoothing) | 1
    if win < 5 or win >= n:
        raise DataError(
            f"smoothing must be an odd window of at least 5 samples and shorter than the record, got {smoothing}"
        )

    def smooth(x: np.ndarray) -> np.ndarray:
        return savgol_filter(x, win, 2, axis=0, mode="interp")

    return smooth


def _identity(x: np.ndarray) -> np.ndarray:
    return x


def _newton_euler_regressors(
    om: np.ndarray, acc: np.ndarray, W: np.ndarray | None, smooth: Callable[[np.ndarray], np.ndarray]
) -> tuple[np.ndarray, list[str]]:
    """Regressors of the three stacked axes (x rows, then y, then z) and the parameter names."""
    p, q, r = om.T
    pd, qd, rd = acc.T
    rows_x = [pd, smooth(-q * r), smooth(q * r)]
    rows_y = [smooth(p * r), qd, smooth(-p * r)]
    rows_z = [smooth(-p * q), smooth(p * q), rd]
    names = ["Ixx", "Iyy", "Izz"]
    if W is not None:
        rows_x.append(smooth(q * W))
        rows_y.append(smooth(-p * W))
        rows_z.append(np.zeros_like(p))
        names.append("Ir")
    return np.vstack([np.column_stack(rows_x), np.column_stack(rows_y), np.column_stack(rows_z)]), names
