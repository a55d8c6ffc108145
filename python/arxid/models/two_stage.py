"""The reference-driven part of a closed-loop input: the first stage of the two-stage method.

In closed loop the input is ``u = S_u r - C S v``: a part driven by the reference ``r`` and a part
the controller ``C`` makes from the output noise ``v``. :func:`reference_driven` estimates the
first part, ``û``, by projecting every input on the logged references (a high-order ARX model from
``r`` to ``u``, simulated; the same projection the instruments of :func:`arxid.iv` use). The noise
never passes through ``û``: a plant simulated on it and compared with the measured output is
judged on a signal the feedback did not touch, so the comparison favours the true plant, not the
closed loop (Van den Hof & Schrama, Automatica 29, 1993; Forssell & Ljung, Automatica 35, 1999).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..data.iodata import IOData
from .iv import PROJECTION_ORDER, instrument_names, projected_inputs

__all__ = ["reference_driven"]


def reference_driven(data: IOData, references: str | Sequence[str], order: int = PROJECTION_ORDER) -> IOData:
    """``data`` with each input replaced by its reference-driven part ``û`` (same names and units).

    Parameters
    ----------
    data : IOData
        Closed-loop data holding the references among its extra signals.
    references : str or sequence of str
        The logged references or setpoints (extra signals of ``data``).
    order : int
        Order of the high-order ARX model from the references to each input.

    Returns
    -------
    IOData
        The same output, extra signals and experiments; a sample where the measured input is
        missing stays missing.

    Raises
    ------
    DataError
        When a reference is not an extra signal, names the output or an input, or is constant.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from arxid.datasets import pi_loop
    >>> from arxid.models.two_stage import reference_driven
    >>> d = pi_loop(seed=0, n_samples=4000)
    >>> u_hat = reference_driven(d, "r").u[:, 0]
    >>> bool(abs(np.corrcoef(u_hat, d.u[:, 0])[0, 1]) > 0.5)
    True
    """
    xu = projected_inputs(data, instrument_names(data, references), order)
    xu = np.where(np.isfinite(data.u), xu, np.nan)
    return data.with_signals(u=xu, input_names=data.input_names, input_units=data.input_units)
