"""Physical parameters by structured least squares (seed 002).

Thrust and torque coefficients from static stand data, and the principal inertias from
Newton-Euler rotational data, each as a closed-form least-squares problem with standard errors.
Seed 002 trains a linear neural network without bias for the same purpose; with linear
activations and no bias its output is linear in the same regressors, so at convergence it
reaches this least-squares estimate, which QR gives directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

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
        """``{name: (estimate - truth) / truth}`` for the names in ``truth``."""
        return {k: (self[k] - v) / v for k, v in truth.items()}

    def to_dict(self) -> dict:
        return {n: float(v) for n, v in zip(self.names, self.values)}

    def __str__(self) -> str:
        rows = [f"  {n:<8s} {v: .6g}  +- {s:.2g}  ({100 * s / abs(v) if v else np.inf:.2f} %)"
                for n, v, s in zip(self.names, self.values, self.stderr)]
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
        raise IdentifiabilityError(f"regressor {names[int(np.argmin(scale))]} is zero in every row; "
                                   "the data do not excite it", regressors=tuple(names))
    q, r = np.linalg.qr(phi / scale)
    if np.abs(np.diag(r)).min() < 1e-10 * np.abs(np.diag(r)).max():
        raise IdentifiabilityError("the regressors are collinear; excite the axes independently",
                                   regressors=tuple(names))
    theta = np.linalg.solve(r, q.T @ y)
    e = y - (phi / scale) @ theta
    sigma2 = e @ e / (n - p)
    rinv = np.linalg.inv(r)
    cov = sigma2 * rinv @ rinv.T
    return LeastSquaresEstimate(names=tuple(names), values=theta / scale,
                                stderr=np.sqrt(np.diag(cov)) / scale, rms=float(np.sqrt(e @ e / n)), n_samples=n)


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
        ``k`` and, when ``torque`` is given, ``b``: seed 002's second-order polynomial through the
        origin, closed form ``k = sum(w^2 f) / sum(w^4)``.
    """
    w = np.asarray(speed, dtype=float)
    w2 = (w * w).sum(axis=1) if w.ndim == 2 else w * w
    k = structured_lstsq(w2[:, None], thrust, ["k"])
    b = structured_lstsq(w2[:, None], torque, ["b"]) if torque is not None else None
    return k, b


def inertia_from_rotation(rates, accelerations, torques, rotor_speed_sum=None) -> LeastSquaresEstimate:
    """Principal inertias from Newton-Euler rotational data (seed 004 eqs. 13-17).

    Parameters
    ----------
    rates : array_like of shape (n_samples, 3)
        Body rates ``p, q, r`` [rad/s].
    accelerations : array_like of shape (n_samples, 3)
        Angular accelerations ``p', q', r'`` [rad/s^2].
    torques : array_like of shape (n_samples, 3)
        Body torques [N m] (e.g. ``k l (w4^2 - w2^2)`` from the motor speeds).
    rotor_speed_sum : array_like of shape (n_samples,), optional
        ``W = -w1 + w2 - w3 + w4`` [rad/s]; when given, the rotor inertia ``Ir`` is estimated too.

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

    Solving the axes together uses the gyroscopic coupling as information, as seed 002's sparse
    network does.
    """
    om = np.asarray(rates, dtype=float)
    acc = np.asarray(accelerations, dtype=float)
    tau = np.asarray(torques, dtype=float)
    if not (om.shape == acc.shape == tau.shape) or om.ndim != 2 or om.shape[1] != 3:
        raise DataError(f"rates, accelerations and torques must all have shape (n_samples, 3), got "
                        f"{om.shape}, {acc.shape}, {tau.shape}")
    p, q, r = om.T
    pd, qd, rd = acc.T
    z = np.zeros_like(p)
    rows_x = [pd, -q * r, q * r]
    rows_y = [p * r, qd, -p * r]
    rows_z = [-p * q, p * q, rd]
    names = ["Ixx", "Iyy", "Izz"]
    if rotor_speed_sum is not None:
        W = np.asarray(rotor_speed_sum, dtype=float).reshape(-1)
        rows_x.append(q * W)
        rows_y.append(-p * W)
        rows_z.append(z)
        names.append("Ir")
    phi = np.vstack([np.column_stack(rows_x), np.column_stack(rows_y), np.column_stack(rows_z)])
    return structured_lstsq(phi, np.concatenate([tau[:, 0], tau[:, 1], tau[:, 2]]), names)
