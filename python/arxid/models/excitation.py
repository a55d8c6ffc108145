"""Whether an input excites the system at all: :func:`check_excitation`, the one test behind
:func:`arxid.arx`, the prediction-error fits and :func:`arxid.sweep`.

An input that does not vary carries no information about the system: its coefficients cannot be
identified, and in a fit with an offset-free structure it only plays the part of a constant. An
input is **constant** when its finite samples are all equal, and **nearly constant** when their
standard deviation is at most :data:`CONSTANT_TOLERANCE` (1e-9) of their mean magnitude: a variation
that small is the rounding of a stored constant (float32 keeps about 1e-7 of a value, float64
about 1e-16), never a test signal.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..data.iodata import IOData
from ..exceptions import IdentifiabilityError

__all__ = ["CONSTANT_TOLERANCE", "check_excitation"]

#: Largest standard deviation of an input, relative to its mean magnitude, taken as no variation.
CONSTANT_TOLERANCE = 1e-9


def check_excitation(data: IOData, nb: Sequence[int], *, remedy: str = "set nb=0 for it") -> None:
    """Refuse an input that is constant or nearly constant, naming it, its level and what to do.

    Parameters
    ----------
    data : IOData
    nb : sequence of int
        Per input, its number of coefficients (an input with 0 is not checked).
    remedy : str
        How to leave the input out, for the message.

    Raises
    ------
    IdentifiabilityError
        For the first input with ``nb > 0`` whose finite samples vary by at most
        :data:`CONSTANT_TOLERANCE` of their mean magnitude (``regressors`` names it).
    """
    for i, b in enumerate(nb):
        if not b:
            continue
        x = data.u[:, i]
        x = x[np.isfinite(x)]
        name = data.input_names[i]
        if x.size == 0:
            raise IdentifiabilityError(f"input {name!r} has no finite sample: it carries no information", (name,))
        peak = float(np.max(np.abs(x)))
        z = x / peak if peak > 0 else x  # scaled first: the variance of 1e-200 or 1e200 leaves the float range
        if np.std(z) > CONSTANT_TOLERANCE * np.mean(np.abs(z)):
            continue
        sd = float(np.std(z)) * peak
        unit = f" {data.input_units[i]}" if data.input_units[i] else ""
        how = (
            f"is constant ({x[0]:.6g}{unit} in all {x.size} samples)"
            if np.ptp(x) == 0
            else f"is nearly constant ({np.mean(x):.6g}{unit}, standard deviation {sd:.3g}: at most "
            f"{CONSTANT_TOLERANCE:g} of its level, rounding rather than a test signal)"
        )
        raise IdentifiabilityError(
            f"input {name!r} {how}: it does not excite the system and carries no information about it, so "
            f"its coefficients cannot be identified; use data where it varies (a step, PRBS or chirp, see "
            f"arxid.inputs), or {remedy}",
            (name,),
        )
