"""Input mixer: motor speeds -> pseudo-torques and total thrust (a published quadrotor study,
Sarıoğlu & Kural, eqs. 5-12 and 24).

A quadrotor is nonlinear in its motor speeds but linear in their squares. The mixer forms the
combinations of squared speeds that drive each axis, so that each axis becomes a linear system
(a double integrator) that ARX can identify.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..data.iodata import IOData
from ..exceptions import DataError

__all__ = ["Mixer", "mix", "CHANNELS"]

#: Names of the mixer's output channels, in order.
CHANNELS = ("roll_torque", "pitch_torque", "yaw_torque", "thrust")

_S = 1.0 / np.sqrt(2.0)
# Motor positions (x forward, y left) in arm lengths and the sign of each motor's yaw reaction
# torque. "plus" is Sarıoğlu & Kural's numbering: motor 1 front, 2 right, 3 back, 4 left, so that
# roll = w4^2 - w2^2, pitch = w3^2 - w1^2, yaw = -w1^2 + w2^2 - w3^2 + w4^2.
# "x" is the Crazyflie 2.x numbering: 1 front-right, 2 back-right, 3 back-left, 4 front-left.
_FRAMES = {
    "plus": (((1.0, 0.0), (0.0, -1.0), (-1.0, 0.0), (0.0, 1.0)), (-1.0, 1.0, -1.0, 1.0)),
    "x": (((_S, -_S), (-_S, -_S), (-_S, _S), (_S, _S)), (-1.0, 1.0, -1.0, 1.0)),
}


@dataclass(frozen=True)
class Mixer:
    """Linear map from squared motor speeds to pseudo-torques and total thrust.

    Parameters
    ----------
    frame : {"plus", "x"}
        Airframe. ``"plus"`` uses Sarıoğlu & Kural's numbering (1 front, 2 right, 3 back, 4 left);
        ``"x"`` the Crazyflie numbering (1 front-right, 2 back-right, 3 back-left, 4 front-left),
        with arms at 45 degrees so each motor's moment arm is ``1/sqrt(2)`` arm lengths.
    positions : array_like of shape (n_motors, 2), optional
        Motor positions ``(x forward, y left)`` in arm lengths; overrides ``frame`` (any numbering,
        any number of motors).
    spin : sequence of {+1, -1}, optional
        Sign of each motor's yaw reaction torque on the body (``+1`` for a clockwise propeller seen
        from above). Default ``(-1, +1, -1, +1)`` as in Sarıoğlu & Kural eq. 9.

    Notes
    -----
    With ``x_i, y_i`` the motor positions and ``s_i`` the spin signs::

        roll_torque  =  sum_i  y_i * w_i^2
        pitch_torque = -sum_i  x_i * w_i^2
        yaw_torque   =  sum_i  s_i * w_i^2
        thrust       =  sum_i  w_i^2

    These are Sarıoğlu & Kural's ``u'`` (eq. 24): the physical torques divided by the thrust
    coefficient ``k`` (times the arm length) and, for yaw, by the drag coefficient ``b``.

    Examples
    --------
    >>> import numpy as np
    >>> from arxid.quadrotor import Mixer
    >>> Mixer("plus")(np.array([[1.0, 2.0, 3.0, 4.0]]))
    array([[12.,  8., 10., 30.]])
    """

    frame: str = "plus"
    positions: tuple | None = None
    spin: tuple | None = None

    def __post_init__(self):
        if self.positions is None:
            if self.frame not in _FRAMES:
                raise DataError(f"unknown frame {self.frame!r}; use 'plus' or 'x', or pass positions=")
            pos = _FRAMES[self.frame][0]
        else:
            pos = tuple(tuple(float(c) for c in p) for p in np.asarray(self.positions, dtype=float).tolist())
            if any(len(p) != 2 for p in pos):
                raise DataError("positions must have shape (n_motors, 2): (x forward, y left) per motor")
        n = len(pos)
        spin = self.spin if self.spin is not None else _FRAMES.get(self.frame, _FRAMES["plus"])[1]
        spin = tuple(float(s) for s in spin)
        if len(spin) != n:
            raise DataError(f"spin has {len(spin)} entries for {n} motors; give one sign per motor")
        if any(s not in (1.0, -1.0) for s in spin):
            raise DataError(f"spin entries must be +1 or -1, got {spin}")
        object.__setattr__(self, "positions", pos)
        object.__setattr__(self, "spin", spin)

    @property
    def n_motors(self) -> int:
        """Number of motors."""
        assert self.positions is not None  # set by __post_init__
        return len(self.positions)

    @property
    def matrix(self) -> np.ndarray:
        """Mixer matrix of shape (4, n_motors); rows are :data:`CHANNELS`."""
        pos = np.asarray(self.positions)
        return np.vstack([pos[:, 1], -pos[:, 0], np.asarray(self.spin), np.ones(self.n_motors)])

    def __call__(self, speeds) -> np.ndarray:
        """Pseudo-torques and thrust from motor speeds.

        Parameters
        ----------
        speeds : array_like of shape (n_samples, n_motors)
            Motor speeds (any unit; the result is in that unit squared).

        Returns
        -------
        ndarray of shape (n_samples, 4)
            Columns ``roll_torque, pitch_torque, yaw_torque, thrust``.
        """
        w = np.asarray(speeds, dtype=float)
        if w.ndim == 1 and w.shape[0] == self.n_motors:
            w = w[None, :]
        if w.ndim != 2 or w.shape[1] != self.n_motors:
            raise DataError(f"speeds have shape {w.shape}; expected (n_samples, {self.n_motors}), one column per motor")
        return (w * w) @ self.matrix.T

    def squared_speeds(self, channels) -> np.ndarray:
        """Inverse mixer: squared motor speeds that produce given pseudo-torques and thrust.

        Parameters
        ----------
        channels : array_like of shape (n_samples, 4)
            ``roll_torque, pitch_torque, yaw_torque, thrust``.

        Returns
        -------
        ndarray of shape (n_samples, n_motors)
            Least-squares (minimum-norm for more than four motors) squared speeds; may be negative
            when the request is not reachable.
        """
        c = np.atleast_2d(np.asarray(channels, dtype=float))
        if c.shape[1] != 4:
            raise DataError(f"channels have shape {c.shape}; expected (n_samples, 4)")
        return c @ np.linalg.pinv(self.matrix).T

    def apply(
        self, data: IOData, speeds: Sequence[str] = ("w1", "w2", "w3", "w4"), channels: Sequence[str] = CHANNELS
    ) -> IOData:
        """Replace the inputs of ``data`` by mixer channels computed from its logged motor speeds.

        Parameters
        ----------
        data : IOData
            Data that hold the motor speeds as inputs or extra signals.
        speeds : sequence of str
            Names of the motor-speed signals, in motor order.
        channels : sequence of str
            Which of :data:`CHANNELS` become the inputs (e.g. ``["roll_torque"]``).

        Returns
        -------
        IOData
            Same output, ts and experiments; inputs ``channels``; the extra signals of ``data``
            plus any of its inputs that did not become a channel (an extra signal named like a
            channel, such as a measured ``thrust``, is kept as ``thrust_logged``).
        """
        if len(speeds) != self.n_motors:
            raise DataError(f"{len(speeds)} speed signals named for a {self.n_motors}-motor mixer")
        unknown = [c for c in channels if c not in CHANNELS]
        if unknown or not channels:
            raise DataError(f"unknown mixer channels {unknown}; choose from {list(CHANNELS)}")
        w = np.column_stack([data.signal(s) for s in speeds])
        mixed = self(w)
        cols = [CHANNELS.index(c) for c in channels]
        extra = {}
        for name, values in list(data.extra.items()) + [(n, data.u[:, i]) for i, n in enumerate(data.input_names)]:
            if name in channels:
                continue
            # a logged signal named like a channel (e.g. the measured thrust) is kept as <name>_logged
            extra[f"{name}_logged" if name in channels or name == data.output_name else name] = values
        for name in channels:
            if name in data.extra:
                extra[f"{name}_logged"] = data.extra[name]
        speed_unit = data.unit(speeds[0])
        unit = f"({speed_unit})^2" if speed_unit else ""
        return IOData(
            data.y,
            mixed[:, cols],
            data.ts,
            output_name=data.output_name,
            input_names=tuple(channels),
            output_unit=data.output_unit,
            input_units=(unit,) * len(cols),
            extra=extra,
            extra_units={n: data.unit(n[:-7] if n.endswith("_logged") else n) for n in extra},
            experiment_starts=data.experiment_starts,
        )


def mix(speeds, frame: str = "plus", **kwargs):
    """Apply a :class:`Mixer` to an array of motor speeds or to :class:`~arxid.IOData`.

    Parameters
    ----------
    speeds : array_like of shape (n_samples, n_motors) or IOData
        Motor speeds, or data holding signals ``w1..w4`` (see :meth:`Mixer.apply`).
    frame : {"plus", "x"}
    **kwargs
        ``positions`` and ``spin`` go to :class:`Mixer`; ``speeds``/``channels`` names to
        :meth:`Mixer.apply`.

    Returns
    -------
    ndarray of shape (n_samples, 4) or IOData
    """
    mk = {k: kwargs.pop(k) for k in ("positions", "spin") if k in kwargs}
    m = Mixer(frame, **mk)
    if isinstance(speeds, IOData):
        if "speed_names" in kwargs:
            kwargs["speeds"] = kwargs.pop("speed_names")
        return m.apply(speeds, **kwargs)
    if kwargs:
        raise DataError(f"unexpected arguments {sorted(kwargs)} for array input")
    return m(speeds)
