"""The sweep engine of ``sweep(..., method="iv")``: every structure of a grid fitted by instrumental
variables in one call of the Rust core (:class:`IvRunner`), with instruments common to the grid."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base import _core
from ..data.iodata import IOData
from ..exceptions import ArxidError
from ..models.iv import instrument_signals
from .engine import Runner
from .grid import Grid

__all__ = ["IvRunner", "iv_settings"]


def iv_settings(method: str, instruments: str | Sequence[str] | None) -> dict:
    """The settings an instrumental-variable sweep adds to its result (none for least squares).

    Parameters
    ----------
    method : str
    instruments : None, str or sequence of str

    Returns
    -------
    dict
    """
    return {"method": method, "instruments": instruments} if method == "iv" else {}


class IvRunner:
    """One call of the core's IV sweep at a given horizon (same interface as the least-squares runner).

    Parameters
    ----------
    est, val : IOData, IOData or None
        Estimation and validation data.
    g : Grid
        The structures.
    instruments : None, str or sequence of str
        See :func:`arxid.iv`; the instrument signals are computed once, on the estimation data.
    n_threads : int
    simulate_estimation : bool
    """

    def __init__(
        self,
        est: IOData,
        val: IOData | None,
        g: Grid,
        instruments: str | Sequence[str] | None,
        n_threads: int,
        simulate_estimation: bool,
    ):
        self.est, self.val, self.g = est, val, g
        self.n_threads, self.simulate_estimation = n_threads, simulate_estimation
        self.xy, self.xu = instrument_signals(est, instruments)

    @classmethod
    def of(cls, runner: Runner, method: str, instruments: str | Sequence[str] | None, refine: Any) -> IvRunner:
        """The IV runner of the data and grid of a least-squares ``runner``.

        Parameters
        ----------
        runner : Runner
        method : str
            Must be ``"iv"`` (the caller keeps ``runner`` for ``"arx"``).
        instruments : None, str or sequence of str
        refine : None or str
            The sweep's refinement (refused with IV).

        Returns
        -------
        IvRunner

        Raises
        ------
        ArxidError
            For another method, or effects, refinement or logs on a cluster with ``method="iv"``.
        """
        if method != "iv":
            raise ArxidError(f"method must be 'arx' (least squares) or 'iv' (instrumental variables), got {method!r}")
        inputs = runner.inputs
        if inputs is None or inputs.terms or inputs.u_est.shape[1] != runner.est.n_inputs or refine is not None:
            raise ArxidError(
                "method='iv' sweeps linear ARX structures of one IOData: drop effects=, refine= and lists of logs "
                "(or sweep them by least squares)"
            )
        return cls(runner.est, runner.val, runner.g, instruments, runner.n_threads, runner.simulate_estimation)

    def __call__(self, k: int | None) -> Any:
        val = self.val
        out, _covariances, _rows = _core.iv_sweep(
            np.ascontiguousarray(self.est.y),
            np.ascontiguousarray(self.est.u, dtype=float),
            list(self.est.experiment_starts),
            np.ascontiguousarray(self.xy),
            np.ascontiguousarray(self.xu, dtype=float),
            self.g.layout,
            yv=np.ascontiguousarray(val.y) if val is not None else None,
            uv=np.ascontiguousarray(val.u, dtype=float) if val is not None else None,
            starts_v=list(val.experiment_starts) if val is not None else None,
            simulate_estimation=bool(self.simulate_estimation),
            horizon=k,
            n_threads=self.n_threads,
        )
        return out
