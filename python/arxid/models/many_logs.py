"""What a model needs to fit logs it does not hold, stated here and provided by :mod:`arxid.fleet`.

A list of logs fitted in process is one merged :class:`~arxid.IOData` (:func:`arxid.data.logs.merge_logs`)
and needs nothing more. Two ways of fitting a list need a fleet: with ``client=`` the logs stay on
the workers of a Dask cluster, which send back the triangular factor of the model's regressors (a
:class:`FactorSource`); with ``per_experiment=True`` each log gets its own model. The model layer
must not import the fleet layer above it, so the fleet provides both here when it is imported
(:func:`provide`, called by :mod:`arxid.fleet.fit`), imported by name on first need.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from ..exceptions import ArxidError

__all__ = ["FactorSource", "LogsFitting", "logs_fitting", "provide"]


class FactorSource(Protocol):
    """Logs kept elsewhere (on the workers of a Dask cluster) that reduce a model's regressors to
    their combined triangular factor and score the fitted model where they are."""

    @property
    def signals(self) -> Any:
        """What every log shares: ``ts``, ``output_name``, ``input_names``, ``output_unit``,
        ``input_units`` (an :class:`arxid.data.logs.LogSignals`)."""

    def factor(self, na: int, nb: tuple, nk: tuple, effects: Sequence[str]) -> tuple[np.ndarray, int, int, Any, int]:
        """R of ``[Φ | y]`` over every log, its regression rows, the rows at most available, the
        effect layout (without samples) and the samples, for the orders ``na``, ``nb``, ``nk`` (one
        per input) and ``effects`` of an :class:`arxid.ArxModel`."""

    def fit_percent(self, model: Any) -> float:
        """The fitted model's one-step fit percent over every log.

        Parameters
        ----------
        model : ArxModel

        Returns
        -------
        float
        """


@dataclass(frozen=True)
class LogsFitting:
    """How the fleet layer fits a list of logs.

    Attributes
    ----------
    cluster_logs : callable
        ``cluster_logs(client, sources, read)``: the logs read and kept by the workers of a Dask
        cluster, as a :class:`FactorSource`.
    fit_each : callable
        ``fit_each(sources, client, read, fit)``: ``fit`` (a function of an IOData) applied to every
        log, on the workers when ``client`` is not None; the models and their spread.
    """

    cluster_logs: Callable[[Any, Sequence[Any], Any], FactorSource]
    fit_each: Callable[[Sequence[Any], Any, Any, Callable], Any]


_PROVIDED: list[LogsFitting] = []


def provide(fitting: LogsFitting) -> None:
    """Make ``fitting`` the way models fit lists of logs (the fleet layer calls it when imported).

    Parameters
    ----------
    fitting : LogsFitting

    Returns
    -------
    None
    """
    _PROVIDED[:] = [fitting]


def logs_fitting(what: str) -> LogsFitting:
    """The fleet layer's way of fitting lists of logs.

    Parameters
    ----------
    what : str
        The option that needs it, for the message (``"client="``, ``"per_experiment=True"``).

    Returns
    -------
    LogsFitting

    Raises
    ------
    ArxidError
        When :mod:`arxid.fleet` cannot be imported, or does not provide the fits.
    """
    if not _PROVIDED:  # imported by name: this layer does not import the fleet's above it
        importlib.import_module("arxid.fleet")
    if not _PROVIDED:
        raise ArxidError(f"{what} needs arxid.fleet, which provides the fits of many logs: import arxid.fleet first")
    return _PROVIDED[0]
