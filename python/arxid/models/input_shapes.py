"""Static input nonlinearities that *replace* an input: the input acts through f(u) (Hammerstein).

Physics often writes an actuator this way: a lamp heats with power ∝ V², a propeller thrusts
∝ ω², a motor does nothing inside its dead band and saturates at full duty. The model keeps its
linear dynamics and feeds them f(u) instead of u, with one gain per lag as for u itself. In the
effect grammar (:mod:`arxid.models.effects`) a replacing shape is written ``through(SHAPE)``:

=========================  =====================================  ======================================
shape                      f(u)                                   typical physics
=========================  =====================================  ======================================
``through(u1^2.05)``       u^p, for an input that is never < 0    lamp power ∝ V², thrust ∝ ω², √Δp
``through(spow(u1,1.5))``  sign(u)·|u|^p                          a reversible propeller, ω·|ω|
``through(clip(u1,a,b))``  u held within [a, b]                   actuator saturation at its levels
``through(dz(u1,0.2))``    sign(u)·max(|u| − c, 0)                no response inside the dead band
``through(u1*vbat)``       u·v, v a logged signal                 duty × battery voltage
=========================  =====================================  ======================================

Each shape contains the linear input (p = 1, levels outside the input's range, c = 0), so the
linear model is nested in each family. A power of an input that goes negative is refused: u^p is
not defined there (use the signed power).
"""

from __future__ import annotations

import re

import numpy as np

from .._base.records import record
from ..exceptions import DataError, OrderError

__all__ = ["InputShape", "parse_shape", "shape_values", "check_params", "SHAPE_KINDS"]

#: The named shape families, in the order the diagnosis lists them.
SHAPE_KINDS = ("power", "signed power", "saturation", "dead zone", "product")

_NAME = r"[A-Za-z_]\w*"
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_FORMS = {
    "power": re.compile(rf"(?P<s>{_NAME})\^(?P<p>{_NUM})"),
    "signed power": re.compile(rf"spow\((?P<s>{_NAME}),(?P<p>{_NUM})\)"),
    "saturation": re.compile(rf"clip\((?P<s>{_NAME}),(?P<lo>{_NUM}),(?P<hi>{_NUM})\)"),
    "dead zone": re.compile(rf"dz\((?P<s>{_NAME}),(?P<c>{_NUM})\)"),
    "product": re.compile(rf"(?P<s>{_NAME})\*(?P<o>{_NAME})"),
}


def _num(x: float) -> str:
    """A parameter as the grammar writes it: four significant digits, no ``+`` in an exponent."""
    return f"{x:.4g}".replace("e+", "e")


@record
class InputShape:
    """A static function f through which one input acts.

    Attributes
    ----------
    kind : str
        One of :data:`SHAPE_KINDS`.
    signal : str
        The input it replaces.
    params : tuple of float
        The exponent p (power, signed power), the levels (lo, hi) (saturation) or the half-width
        c (dead zone); none for a product.
    other : str
        The logged signal of a product.
    """

    kind: str
    signal: str
    params: tuple[float, ...] = ()
    other: str = ""

    @property
    def text(self) -> str:
        """The shape in the grammar, inside ``through( )``: ``volt^2``, ``clip(u1,-0.8,0.9)``."""
        s, p = self.signal, self.params
        return {
            "power": lambda: f"{s}^{_num(p[0])}",
            "signed power": lambda: f"spow({s},{_num(p[0])})",
            "saturation": lambda: f"clip({s},{_num(p[0])},{_num(p[1])})",
            "dead zone": lambda: f"dz({s},{_num(p[0])})",
            "product": lambda: f"{s}*{self.other}",
        }[self.kind]()

    @property
    def effect(self) -> str:
        """The effect string: ``through(volt^2)``."""
        return f"through({self.text})"

    def evaluate(self, x: np.ndarray, other: np.ndarray | None = None) -> np.ndarray:
        """f(x) at each sample (``other``: the logged signal of a product).

        Parameters
        ----------
        x : ndarray
            The input's samples.
        other : ndarray, optional
            The modulating signal's samples (product only).

        Returns
        -------
        ndarray
            A new array.

        Raises
        ------
        DataError
            For a power of an input that goes negative.
        """
        x = np.asarray(x, dtype=float)
        k, p = self.kind, self.params
        if k == "power" and np.nanmin(x, initial=0.0) < 0:
            raise DataError(
                f"{self.effect}: {self.signal} goes negative (down to {np.nanmin(x):.4g}), where a power law is "
                f"not defined; use the signed power through(spow({self.signal},{_num(p[0])})) or shift the input"
            )
        if k != "product":
            return shape_values(k, p, x, np.empty(x.shape))
        if other is None:
            raise OrderError(f"{self.effect} needs the samples of {self.other}")
        return x * np.asarray(other, dtype=float)

    def physics(self) -> str:
        """What the shape stands for, in a control engineer's words.

        Returns
        -------
        str
            e.g. ``"the input acts through volt^2 (power): lamp power or thrust ∝ square"``.
        """
        head = f"the input acts through {self.text}"
        if self.kind in ("power", "signed power"):
            return f"{head} ({self.kind}): {_power_physics(self.params[0], self.kind == 'signed power')}"
        return (
            head
            + {
                "saturation": " (saturation): the actuator stops at its levels",
                "dead zone": " (dead zone): no response inside the dead band",
                "product": f" (product): the command scaled by {self.other}, as duty × battery voltage",
            }[self.kind]
        )


def shape_values(
    kind: str,
    params: tuple[float, ...],
    x: np.ndarray,
    out: np.ndarray,
    magnitude: np.ndarray | None = None,
    sign: np.ndarray | None = None,
) -> np.ndarray:
    """f(x) of a family with parameters (not a product), written into ``out``: the numbers of
    :meth:`InputShape.evaluate`, which checks what this does not (a power of a negative input).

    A scan evaluates one family at many values on the same samples: it passes |x| and sign(x),
    found once, as ``magnitude`` and ``sign``.

    Parameters
    ----------
    kind : str
        ``"power"``, ``"signed power"``, ``"saturation"`` or ``"dead zone"``.
    params : tuple of float
    x : ndarray of float, shape (n,)
    out : ndarray of float, shape (n,)
        Written over (in place: one temporary of the record's length, not four).
    magnitude, sign : ndarray of shape (n,), optional
        ``np.abs(x)`` and ``np.sign(x)``.

    Returns
    -------
    ndarray
        ``out``.
    """
    if kind == "power":
        return np.power(x, params[0], out=out)
    if kind == "saturation":
        return x.clip(params[0], params[1], out=out)  # np.clip's own call
    source = np.abs(x, out=out) if magnitude is None else magnitude
    if kind == "signed power":
        np.power(source, params[0], out=out)
    else:
        np.subtract(source, params[0], out=out)
        np.maximum(out, 0.0, out=out)
    out *= np.sign(x) if sign is None else sign
    return out


def _power_physics(p: float, signed: bool) -> str:
    if abs(p - 2) <= 0.2:
        return "thrust ∝ ω·|ω|" if signed else "lamp power or thrust ∝ square"
    if abs(p - 0.5) <= 0.05:
        return "flow ∝ square root of the pressure drop"
    if abs(p - 3) <= 0.3:
        return "cube law"
    return f"a power law with exponent {p:.3g}"


def parse_shape(inner: str, signals: set[str], effect: str) -> InputShape:
    """The shape written inside ``through( )``.

    Parameters
    ----------
    inner : str
        e.g. ``"volt^2"``, ``"spow(u1,1.5)"``, ``"clip(u1,-1,0.8)"``, ``"dz(u1,0.2)"``, ``"u1*vbat"``.
    signals : set of str
        The names the data know.
    effect : str
        The whole effect, for messages.

    Returns
    -------
    InputShape

    Raises
    ------
    OrderError
        For a shape the grammar does not know, an unknown signal or a parameter out of range.
    """
    for kind, form in _FORMS.items():
        m = form.fullmatch(inner)
        if m is None:
            continue
        names = [m["s"]] + ([m["o"]] if kind == "product" else [])
        for n in names:
            if n not in signals:
                raise OrderError(f"effect {effect!r} uses signal {n!r}, which the data do not have")
        params = tuple(float(m[g]) for g in ("p", "lo", "hi", "c") if g in form.groupindex)
        check_params(kind, params, effect)
        return InputShape(kind, m["s"], params, m["o"] if kind == "product" else "")
    raise OrderError(
        f"cannot read effect {effect!r}: through( ) takes one of u^p, spow(u,p), clip(u,lo,hi), dz(u,c), u*x"
    )


def check_params(kind: str, params: tuple[float, ...], effect: str) -> None:
    """Raise :class:`~arxid.OrderError` for a parameter out of its family's range (as
    :func:`parse_shape` reads it)."""
    if kind in ("power", "signed power") and not 0 < params[0] <= 10:
        raise OrderError(f"effect {effect!r}: the exponent must be in (0, 10], got {params[0]}")
    if kind == "saturation" and not params[0] < params[1]:
        raise OrderError(f"effect {effect!r}: the lower level must be below the upper one, got {params}")
    if kind == "dead zone" and not params[0] >= 0:
        raise OrderError(f"effect {effect!r}: the dead band's half-width must be >= 0, got {params[0]}")
