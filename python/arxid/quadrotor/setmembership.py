"""Set-membership parameter bounds with bounded error.

For a model linear in its parameters with bounded error ``|y - phi^T theta| <= eps``, the feasible
set is a polytope; its bounding box follows from two linear programs per parameter (HiGHS).
The set-membership quadrocopter study ("Robust Identification of Quadrocopter Model for Control
Purposes") applies this per battery-voltage level to thrust ``F = b(e) u^2`` and torque
``M = d(e) u^2``, then bounds ``b(e) = p1 e + p2`` from the per-level intervals, and shrinks the
conservative box by a rotated parametrisation (eqs. 17-22, 27).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..exceptions import ArxidError, DataError

__all__ = [
    "ParameterBox",
    "EmptyFeasibleSetError",
    "parameter_box",
    "smallest_epsilon",
    "levels_box",
    "linear_in_voltage_box",
    "rotated_box",
    "RotatedBox",
    "inertia_intervals",
    "InertiaIntervals",
]


class EmptyFeasibleSetError(ArxidError):
    """No parameter explains every sample within the error bound.

    Attributes
    ----------
    epsilon : float
        The bound that was asked for.
    smallest_epsilon : float
        The smallest bound for which the feasible set is not empty.
    """

    def __init__(self, message: str, epsilon: float, smallest_epsilon: float):
        super().__init__(message)
        self.epsilon = epsilon
        self.smallest_epsilon = smallest_epsilon


@dataclass(frozen=True)
class ParameterBox:
    """Axis-aligned bounding box of the feasible parameter set.

    Attributes
    ----------
    names : tuple of str
    lower, upper : ndarray of shape (n_params,)
    epsilon : float
        Error bound used.
    """

    names: tuple
    lower: np.ndarray
    upper: np.ndarray
    epsilon: float

    @property
    def width(self) -> np.ndarray:
        """Width of the box along each parameter."""
        return self.upper - self.lower

    @property
    def center(self) -> np.ndarray:
        """Centre of the box."""
        return (self.upper + self.lower) / 2

    @property
    def volume(self) -> float:
        """Product of the widths (an area for two parameters)."""
        return float(np.prod(self.width))

    def contains(self, theta, tol: float = 1e-9) -> bool:
        """Whether a parameter vector lies in the box.

        Parameters
        ----------
        theta : array_like of shape (n_params,)
        tol : float
            Relative tolerance on the bounds (the LP solutions are exact to about this).

        Returns
        -------
        bool
        """
        t = np.asarray(theta, dtype=float)
        pad = tol * np.maximum(np.abs(self.upper), np.abs(self.lower))
        return bool(np.all(t >= self.lower - pad) and np.all(t <= self.upper + pad))

    def __str__(self) -> str:
        rows = [f"  {n:<6s} [{lo:.6g}, {hi:.6g}]" for n, lo, hi in zip(self.names, self.lower, self.upper, strict=True)]
        return f"parameter box (eps = {self.epsilon:.4g}):\n" + "\n".join(rows)


def _linprog(c, A_ub, b_ub, bounds):
    from scipy.optimize import linprog

    return linprog(c, A_ub=A_ub, b_ub=b_ub, bounds=bounds, method="highs")


def smallest_epsilon(phi, y, nonnegative: bool = False) -> float:
    """Smallest ``eps`` with a ``theta`` such that ``|y - Phi theta| <= eps`` for every row
    (Chebyshev fit, one LP).

    Parameters
    ----------
    phi : array_like of shape (n_rows, n_params)
    y : array_like of shape (n_rows,)
    nonnegative : bool
        Restrict ``theta >= 0`` (the set-membership study, eqs. 11-12).

    Returns
    -------
    float
    """
    phi = np.atleast_2d(np.asarray(phi, dtype=float))
    y = np.asarray(y, dtype=float).reshape(-1)
    n, p = phi.shape
    # variables (theta, eps): minimise eps s.t. Phi theta - eps <= y, -Phi theta - eps <= -y
    A = np.block([[phi, -np.ones((n, 1))], [-phi, -np.ones((n, 1))]])
    b = np.concatenate([y, -y])
    c = np.zeros(p + 1)
    c[-1] = 1.0
    bounds = [(0, None) if nonnegative else (None, None)] * p + [(0, None)]
    res = _linprog(c, A, b, bounds)
    if res.status != 0:
        raise DataError(f"the min-eps LP failed: {res.message}")
    return float(res.x[-1])


def parameter_box(phi, y, epsilon: float, names=None, nonnegative: bool = False) -> ParameterBox:
    """Bounding box of ``{theta : |y - Phi theta| <= eps}`` by 2 p linear programs.

    Parameters
    ----------
    phi : array_like of shape (n_rows, n_params)
    y : array_like of shape (n_rows,)
    epsilon : float
        Error bound (measurement plus structural error, the set-membership study's Assumption 7).
    names : sequence of str, optional
    nonnegative : bool
        Restrict the parameters to be non-negative.

    Returns
    -------
    ParameterBox

    Raises
    ------
    EmptyFeasibleSetError
        When no parameter satisfies every bound; the message gives the smallest feasible ``eps``.
    """
    phi = np.atleast_2d(np.asarray(phi, dtype=float))
    if phi.shape[0] == 1 and np.asarray(y).size > 1:
        phi = phi.T
    y = np.asarray(y, dtype=float).reshape(-1)
    if phi.shape[0] != y.shape[0]:
        raise DataError(f"Phi has {phi.shape[0]} rows but y has {y.shape[0]}")
    if not epsilon >= 0:
        raise DataError(f"epsilon must be a non-negative error bound, got {epsilon}")
    n, p = phi.shape
    names = tuple(names) if names is not None else tuple(f"theta{i + 1}" for i in range(p))
    A = np.vstack([phi, -phi])
    b = np.concatenate([y + epsilon, -(y - epsilon)])
    bounds = [(0, None) if nonnegative else (None, None)] * p
    lo, hi = np.empty(p), np.empty(p)
    for i in range(p):
        c = np.zeros(p)
        c[i] = 1.0
        r_lo = _linprog(c, A, b, bounds)
        if r_lo.status == 2:
            e_min = smallest_epsilon(phi, y, nonnegative)
            raise EmptyFeasibleSetError(
                f"no parameter explains all {n} samples within eps = {epsilon:.4g}; the smallest error "
                f"bound that does is eps = {e_min:.4g}. Raise epsilon to at least that (Assumption 7 "
                "of the set-membership quadrocopter study: the bound must cover measurement and structural "
                "error)",
                epsilon,
                e_min,
            )
        r_hi = _linprog(-c, A, b, bounds)
        if r_lo.status != 0 or r_hi.status != 0:
            raise DataError(f"parameter {names[i]} is unbounded by the data; excite it or add constraints")
        lo[i], hi[i] = r_lo.x[i], r_hi.x[i]
    return ParameterBox(names=names, lower=lo, upper=hi, epsilon=float(epsilon))


def levels_box(u, y, levels, epsilon: float, offset: float = 0.0):
    """Interval of ``b >= 0`` in ``y = b (u - offset)^2`` per voltage level (set-membership study eqs. 9-12).

    Parameters
    ----------
    u : array_like of shape (n_samples,)
        Command (PWM, duty or PPM).
    y : array_like of shape (n_samples,)
        Measured thrust (or torque).
    levels : array_like of shape (n_samples,)
        Voltage level of each sample; samples with equal level form one LP.
    epsilon : float
    offset : float
        Command at zero speed (the set-membership study: ``c = 1000 us`` of PPM).

    Returns
    -------
    (ndarray of levels, ndarray of lower bounds, ndarray of upper bounds)
    """
    u, y, lev = (np.asarray(a, dtype=float).reshape(-1) for a in (u, y, levels))
    values = np.unique(lev)
    lo, hi = [], []
    for e in values:
        m = lev == e
        box = parameter_box(((u[m] - offset) ** 2)[:, None], y[m], epsilon, names=("b",), nonnegative=True)
        lo.append(box.lower[0])
        hi.append(box.upper[0])
    return values, np.array(lo), np.array(hi)


def linear_in_voltage_box(levels, lower, upper) -> ParameterBox:
    """Box of ``(p1, p2)`` with ``lower_i <= p1 e_i + p2 <= upper_i`` (set-membership study eqs. 13-16, 25).

    Parameters
    ----------
    levels : array_like of shape (n_levels,)
        Voltage levels ``e_i``.
    lower, upper : array_like of shape (n_levels,)
        Interval of ``b`` at each level (from :func:`levels_box`).

    Returns
    -------
    ParameterBox
        Bounds of ``p1`` and ``p2`` (``epsilon`` NaN).
    """
    e = np.asarray(levels, dtype=float)
    phi = np.column_stack([e, np.ones_like(e)])
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    if np.any(hi < lo):
        raise DataError("every lower bound must be below its upper bound")
    return _interval_box(phi, lo, hi, ("p1", "p2"))


def _interval_box(phi, lo, hi, names) -> ParameterBox:
    """Box of {p : lo <= phi p <= hi} by 2 LPs per parameter."""
    A = np.vstack([phi, -phi])
    b = np.concatenate([hi, -lo])
    p = phi.shape[1]
    lower, upper = np.empty(p), np.empty(p)
    for i in range(p):
        c = np.zeros(p)
        c[i] = 1.0
        r_lo = _linprog(c, A, b, [(None, None)] * p)
        r_hi = _linprog(-c, A, b, [(None, None)] * p)
        if r_lo.status == 2:
            raise EmptyFeasibleSetError(
                "the per-level intervals admit no straight line b(e) = p1 e + p2; widen epsilon or use a richer b(e)",
                float("nan"),
                float("nan"),
            )
        if r_lo.status != 0 or r_hi.status != 0:
            raise DataError(f"parameter {names[i]} is unbounded; give at least two voltage levels")
        lower[i], upper[i] = r_lo.x[i], r_hi.x[i]
    return ParameterBox(names=tuple(names), lower=lower, upper=upper, epsilon=float("nan"))


@dataclass(frozen=True)
class RotatedBox:
    """Box in rotated coordinates ``p = center + R q`` (set-membership study eqs. 17-22, 27).

    Attributes
    ----------
    center : ndarray of shape (2,)
    rotation : ndarray of shape (2, 2)
        ``R`` of eq. 27.
    box : ParameterBox
        Bounds of ``q``.
    original : ParameterBox
        The axis-aligned box in ``p``.
    """

    center: np.ndarray
    rotation: np.ndarray
    box: ParameterBox
    original: ParameterBox

    @property
    def area(self) -> float:
        """Area of the rotated box (a parallelogram) in the original coordinates."""
        return float(abs(np.linalg.det(self.rotation)) * self.box.volume)

    @property
    def shrink_ratio(self) -> float:
        """Area of the rotated box over the area of the axis-aligned box (< 1: less conservative)."""
        return self.area / self.original.volume

    def contains(self, p, tol: float = 1e-9) -> bool:
        """Whether a point ``(p1, p2)`` lies in the rotated box.

        Parameters
        ----------
        p : array_like of shape (2,)
        tol : float
            Relative tolerance on the bounds of ``q``.

        Returns
        -------
        bool
        """
        q = np.linalg.solve(self.rotation, np.asarray(p, dtype=float) - self.center)
        return self.box.contains(q, tol)

    def corners(self) -> np.ndarray:
        """The corners of the rotated box.

        Returns
        -------
        ndarray of shape (4, 2)
            The four corners in the original coordinates ``(p1, p2)``, in order around the box.
        """
        lo, hi = self.box.lower, self.box.upper
        qs = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        return self.center + qs @ self.rotation.T

    def __str__(self) -> str:
        return (
            f"rotated box: area {self.area:.4g} = {100 * self.shrink_ratio:.2f} % of the axis-aligned "
            f"box\n  corners (p1, p2):\n" + "\n".join(f"    ({a:.6g}, {b:.6g})" for a, b in self.corners())
        )


def rotated_box(levels, lower, upper) -> RotatedBox:
    """The set-membership study's conservatism reduction for ``b(e) = p1 e + p2``.

    The axis-aligned box of ``(p1, p2)`` is loose because the feasible set is a thin sliver along
    a diagonal (slope and intercept trade off). Re-parametrise ``p = center + R q`` with ``R``
    from eq. 27 (columns along the box's diagonals) and bound ``q`` by LPs again.

    Parameters
    ----------
    levels : array_like of shape (n_levels,)
        Voltage levels ``e_i``.
    lower, upper : array_like of shape (n_levels,)
        Interval of ``b`` at each level (from :func:`levels_box`).

    Returns
    -------
    RotatedBox
    """
    e = np.asarray(levels, dtype=float)
    lo, hi = np.asarray(lower, float), np.asarray(upper, float)
    first = linear_in_voltage_box(e, lo, hi)
    d1, d2 = first.width
    R = np.array([[d1, -d2], [-d2, -d1]])
    center = first.center
    phi = np.column_stack([e, np.ones_like(e)])
    # lo <= phi (center + R q) <= hi  =>  interval constraints on q
    q = _interval_box(phi @ R, lo - phi @ center, hi - phi @ center, ("q1", "q2"))
    return RotatedBox(center=center, rotation=R, box=q, original=first)


@dataclass(frozen=True)
class InertiaIntervals:
    """Inertia intervals from measured mass and length intervals (set-membership study eqs. 4, 23-24)."""

    ixy: tuple
    iz: tuple
    arm: tuple

    def __str__(self) -> str:
        return (
            f"I_xy in [{self.ixy[0]:.6g}, {self.ixy[1]:.6g}] kg m^2\n"
            f"I_z  in [{self.iz[0]:.6g}, {self.iz[1]:.6g}] kg m^2\n"
            f"l    in [{self.arm[0]:.6g}, {self.arm[1]:.6g}] m"
        )


def inertia_intervals(
    body_mass=(0.464, 0.466), body_length=(0.09, 0.11), arm=(0.23, 0.25), motor_mass=(0.065, 0.067)
) -> InertiaIntervals:
    """Intervals of ``I_xy = 2 m_s l^2 + m_M l_M^2 / 12`` and ``I_z = 4 m_s l^2 + m_M l_M^2 / 6``.

    Parameters
    ----------
    body_mass, body_length, arm, motor_mass : (float, float)
        Measured intervals of ``m_M`` [kg], ``l_M`` [m], ``l`` [m], ``m_s`` [kg] (defaults: the
        set-membership study's Table I).

    Returns
    -------
    InertiaIntervals

    Notes
    -----
    Both inertias increase in every argument, so the interval ends are attained at the lower and
    upper ends of all intervals (eqs. 23-24); no optimisation is needed.
    """
    for name, iv in (("body_mass", body_mass), ("body_length", body_length), ("arm", arm), ("motor_mass", motor_mass)):
        if len(iv) != 2 or not 0 <= iv[0] <= iv[1]:
            raise DataError(f"{name} must be an interval (low, high) with 0 <= low <= high, got {iv}")

    def ixy(mM, lM, length, ms):
        return 2 * ms * length**2 + mM * lM**2 / 12

    def iz(mM, lM, length, ms):
        return 4 * ms * length**2 + mM * lM**2 / 6

    lo = (body_mass[0], body_length[0], arm[0], motor_mass[0])
    hi = (body_mass[1], body_length[1], arm[1], motor_mass[1])
    return InertiaIntervals(ixy=(ixy(*lo), ixy(*hi)), iz=(iz(*lo), iz(*hi)), arm=tuple(arm))
