"""Instrumental variables (MATLAB ``iv4``): ARX structures that stay consistent when the noise is
coloured, and in closed loop when a measured reference is given.

:func:`iv` fits ``A(q) y = B(q) u + v`` with the normal equations of the instruments
``Σ z(t) φ(t)ᵀ θ = Σ z(t) y(t)``, where ``z(t)`` is the ARX regressor built from noise-free
versions of the output and inputs:

* open loop (``instruments=None``): the input itself, and the output of a high-order ARX model
  simulated from the input (IV4's second stage);
* closed loop (``instruments="roll_sp"`` or several names): a measured reference or setpoint, which
  the noise does not reach. The output and every input are projected on the references (high-order
  ARX models from the references, simulated), and those projections are the instruments.

Then (``iterations``, default 2) the IV4 refinement: an autoregressive model of the equation error
prefilters the data, and the instruments are simulated from the current model. Ljung, *System
Identification*, 2nd ed., sections 7.6 and 15.3 (IV4) and 13.4-13.5 (closed loop). The numerics,
cross moments over the data and the small solves, run in the Rust core (one pass over the samples
for a whole grid, see :func:`arxid.sweep` with ``method="iv"``).
"""

from __future__ import annotations

import weakref
from collections.abc import Sequence
from typing import Any

import numpy as np

from .._base import _core, metrics
from .._base.limits import check_order
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError, IdentifiabilityError, OrderError
from .arx_model import ArxModel
from .arx_solver import per_input
from .effects import compile_effects
from .lagged import filter_segments, lagged_columns
from .regressors import regressor_names

__all__ = ["IvModel", "iv", "instrument_names", "instrument_signals", "PROJECTION_ORDER"]

#: Order of the high-order ARX models whose simulations are the instruments.
PROJECTION_ORDER = 10


def instrument_names(data: IOData, instruments: str | Sequence[str] | None) -> tuple[str, ...]:
    """The reference signals named by ``instruments`` (empty for open loop), checked against the data.

    Parameters
    ----------
    data : IOData
    instruments : None, str or sequence of str

    Returns
    -------
    tuple of str

    Raises
    ------
    DataError
        When a name is not a logged signal, or names the output or an input.
    """
    if instruments is None:
        return ()
    names = (instruments,) if isinstance(instruments, str) else tuple(instruments)
    for name in names:
        if name == data.output_name or name in data.input_names:
            raise DataError(
                f"instrument {name!r} is the output or an input; in closed loop these carry the noise. Name a "
                "measured reference or setpoint (an extra signal), e.g. instruments='roll_sp'"
            )
        if name not in data.extra:
            raise DataError(
                f"no signal {name!r} for the instruments; the data's extra signals are {sorted(data.extra)}. Load "
                "the setpoint with extra=[...] (IOData.from_csv, from_ulog)"
            )
    if not names:
        raise DataError("instruments must name at least one reference signal (or be None for open loop)")
    return names


def _simulate(data: IOData, target: np.ndarray, sources: np.ndarray, order: int) -> np.ndarray:
    """The simulated output of an ARX(order, order + 1, 0) model of ``target`` on ``sources``."""
    from .arx_model import arx

    m = sources.shape[1]
    proj = IOData(target, sources, data.ts, experiment_starts=data.experiment_starts)
    model = arx(proj, order, order + 1, 0, n_threads=1)
    a = model.a
    out = np.zeros(data.n_samples)
    for i, b in enumerate(model.b[:m]):
        out += filter_segments(b, a, sources[:, i], data.segments)
    return out


def instrument_signals(
    data: IOData, instruments: str | Sequence[str] | None, order: int = PROJECTION_ORDER
) -> tuple[np.ndarray, np.ndarray]:
    """The noise-free output and inputs whose regressor is the instrument vector.

    Parameters
    ----------
    data : IOData
    instruments : None, str or sequence of str
        None: open loop (the inputs, and the output simulated from them); names: the measured
        references (output and inputs projected on them).
    order : int
        Order of the projecting ARX models.

    Returns
    -------
    xy : ndarray of shape (n_samples,)
    xu : ndarray of shape (n_samples, n_inputs)
    """
    names = instrument_names(data, instruments)
    if not names:
        u = np.where(np.isfinite(data.u), data.u, 0.0)
        return _simulate(data, data.y, u, order), np.ascontiguousarray(data.u)
    xy = projected(data, None, names, order)
    return xy, projected_inputs(data, names, order)


def projected_inputs(data: IOData, references: Sequence[str], order: int = PROJECTION_ORDER) -> np.ndarray:
    """Every input projected on the references (see :func:`projected`), one column each.

    Parameters
    ----------
    data : IOData
    references : sequence of str
        Checked reference names (:func:`instrument_names`).
    order : int

    Returns
    -------
    ndarray of shape (n_samples, n_inputs)
    """
    return np.column_stack([projected(data, i, references, order) for i in range(data.n_inputs)])


#: Projections already made, per data set (the IV fits of a diagnosis' refits all ask for them).
_PROJECTIONS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def projected(data: IOData, signal: int | None, references: Sequence[str], order: int = PROJECTION_ORDER) -> np.ndarray:
    """The output (``signal=None``) or input ``signal`` simulated from a high-order ARX model on the
    references: its part the references drive, which the noise does not reach. Made once per data
    set, signal, references and order (read-only).

    Parameters
    ----------
    data : IOData
    signal : int or None
    references : sequence of str
        Checked reference names (:func:`instrument_names`).
    order : int

    Returns
    -------
    ndarray of shape (n_samples,)

    Raises
    ------
    DataError
        When a reference is constant.
    """
    memo = _PROJECTIONS.setdefault(data, {})
    key = (signal, tuple(references), order)
    if key not in memo:
        refs = np.column_stack([np.where(np.isfinite(data.extra[n]), data.extra[n], 0.0) for n in references])
        if np.any(np.ptp(refs, axis=0) == 0):
            raise DataError(
                f"the reference {tuple(references)} is constant: it excites nothing and cannot serve as instrument"
            )
        target = data.y if signal is None else data.u[:, signal]
        out = _simulate(data, target, refs, order)
        out.setflags(write=False)
        memo[key] = out
    return memo[key]


@record
class _IvFit:
    theta: np.ndarray
    rss: float
    n_rows: int
    n_skipped: int
    inv_gram: np.ndarray
    first_lag: int


def _orders_row(na: int, nb: Sequence[int], nk: Sequence[int]) -> list[int]:
    return [int(na), *(int(v) for v in nb), *(int(v) for v in nk)]


def solve_iv(data: IOData, xy, xu, grid: np.ndarray, n_threads: int = 0) -> Any:
    """One call of the core's IV sweep without validation (``(SweepOutput, covariances, n_rows)``).

    Parameters
    ----------
    data : IOData
    xy, xu : ndarray
        Instrument signals (:func:`instrument_signals`).
    grid : ndarray of int, shape (S, 1 + 2 n_inputs)
        Rows ``(na, nb..., nk...)``.
    n_threads : int

    Returns
    -------
    tuple
    """
    return _core.iv_sweep(
        np.ascontiguousarray(data.y, dtype=float),
        np.ascontiguousarray(data.u, dtype=float),
        list(data.experiment_starts),
        np.ascontiguousarray(xy, dtype=float),
        np.ascontiguousarray(xu, dtype=float),
        np.ascontiguousarray(grid, dtype=np.int64),
        simulate_estimation=False,
        n_threads=n_threads,
    )


class IvModel(ArxModel):
    """An ARX structure fitted by instrumental variables (see :func:`iv`).

    Parameters
    ----------
    na : int
    nb, nk : int or sequence of int
    instruments : None, str or sequence of str
        None: open loop (IV4). Names of measured reference signals: closed loop.
    iterations : int
        IV4 refinements (prefilter by the equation error's AR model, instruments simulated from
        the current model); 0 keeps the first IV step, as a sweep does.

    Examples
    --------
    >>> from arxid.datasets import pi_loop
    >>> m = IvModel(na=2, nb=2, nk=1, instruments="r").fit(pi_loop(seed=0, n_samples=8000))
    >>> m.structure_name()
    'IV(2,2,1)'
    """

    def __init__(self, *, na: int, nb, nk, instruments: str | Sequence[str] | None = None, iterations: int = 2):
        super().__init__(na=na, nb=nb, nk=nk)
        self.instruments = instruments
        self.iterations = iterations

    def fit(  # type: ignore[override]
        self,
        data: IOData,
        *,
        first_lag: int = 0,
        n_threads: int = 0,
        rows_like: tuple[int, Sequence[int], Sequence[int]] | None = None,
    ) -> IvModel:
        """Fit by instrumental variables in the Rust core.

        Parameters
        ----------
        data : IOData
            Estimation data; with ``instruments`` names, they must be among its extra signals.
        first_lag : int
            Start the rows this far into each experiment (a sweep's rows).
        n_threads : int
            Threads (0 = all cores).
        rows_like : (na, nb, nk), optional
            Orders of a larger structure whose rows are used (a sweep's envelope).

        Returns
        -------
        IvModel
            ``self``, fitted.
        """
        if not isinstance(data, IOData):
            raise DataError(f"fit needs an arxid.IOData, got {type(data).__name__}")
        m = data.n_inputs
        na, nb, nk = check_order("na", self.na), per_input("nb", self.nb, m), per_input("nk", self.nk, m)
        iterations = check_order("iterations", self.iterations)
        names = instrument_names(data, self.instruments)
        xy, xu = instrument_signals(data, names or None)
        grid = [_orders_row(na, nb, nk)]
        if rows_like is not None:
            grid.append(_orders_row(rows_like[0], rows_like[1], rows_like[2]))
        elif first_lag > max(na, *(b + k - 1 for b, k in zip(nb, nk, strict=True))):
            grid.append(_orders_row(max(na, first_lag), nb, nk))
        grid_arr = np.array(grid, dtype=np.int64)
        res = self._solve(data, xy, xu, grid_arr, n_threads)
        if not (np.all(np.isfinite(data.y)) and np.all(np.isfinite(data.u))):
            iterations = 0  # the prefilter would smear a gap: keep the first IV step on data with NaN
        for _ in range(iterations):
            res = self._refine(data, res.theta, xu, na, nb, nk, grid_arr, n_threads)
        layout = compile_effects((), data, nb, nk)
        names_ = regressor_names(data.output_name, na, layout)
        self._store(data, (na, nb, nk), layout, names_, res.first_lag if len(grid) > 1 else 0, res)
        return self

    def _solve(self, data: IOData, xy, xu, grid: np.ndarray, n_threads: int) -> _IvFit:
        out, covs, n_rows = solve_iv(data, xy, xu, grid, n_threads)
        if out.errors[0] is not None:
            raise IdentifiabilityError(
                f"{self.structure_name()} cannot be fitted by instrumental variables: {out.errors[0]}. The instruments "
                "do not excite every parameter: lower the orders, or use a reference that moves more"
            )
        k = int(grid[0, 0] + grid[0, 1 : 1 + data.n_inputs].sum())
        theta = np.asarray(out.theta[0, :k])
        usable = sum(max(0, b - a - int(out.first_lag)) for a, b in data.segments)  # before NaN rows
        lag = int(out.first_lag)
        return _IvFit(theta, float(out.rss_est[0]), int(out.n_est), usable - int(out.n_est), np.asarray(covs[0]), lag)

    def _refine(self, data: IOData, theta, xu, na, nb, nk, grid, n_threads) -> _IvFit:
        """One IV4 refinement: AR prefilter of the equation error, instruments from the model."""
        segs = data.segments
        a = np.concatenate([[1.0], theta[:na]])
        bs, c = [], na
        for i in range(data.n_inputs):
            bs.append(np.concatenate([np.zeros(nk[i]), theta[c : c + nb[i]]]))
            c += nb[i]
        w = filter_segments(a, np.array([1.0]), data.y, segs)
        x = np.zeros(data.n_samples)
        for i, b in enumerate(bs):
            w -= filter_segments(b, np.array([1.0]), data.u[:, i], segs)
            x += filter_segments(b, a, xu[:, i], segs)
        order = na + sum(nb)
        mat, _ = lagged_columns([(w, 0)] + [(w, k) for k in range(1, order + 1)], segs, order + max(na, 1))
        if mat.shape[0] <= 2 * order:
            return self._solve(data, x, xu, grid, n_threads)
        ar = np.linalg.lstsq(-mat[:, 1:], mat[:, 0], rcond=None)[0]
        lp = np.concatenate([[1.0], ar])
        if np.any(np.abs(np.roots(lp)) >= 1.0):
            lp = np.array([1.0])
        one = np.array([1.0])

        def filt(v: np.ndarray) -> np.ndarray:
            return filter_segments(lp, one, v, segs)

        u_f = np.column_stack([filt(data.u[:, i]) for i in range(data.n_inputs)])
        xu_f = np.column_stack([filt(xu[:, i]) for i in range(data.n_inputs)])
        filtered = IOData(filt(data.y), u_f, data.ts, experiment_starts=data.experiment_starts)
        res = self._solve(filtered, filt(x), xu_f, grid, n_threads)
        # the loss of the model on the measured (unfiltered) equation, for fit and criteria
        rss = _equation_rss(data, res.theta, na, nb, nk, res.first_lag)
        return _IvFit(res.theta, rss, res.n_rows, res.n_skipped, res.inv_gram, res.first_lag)

    def structure_name(self) -> str:
        """``IV(na,nb,nk)`` (per-input lists for several inputs).

        Returns
        -------
        str
        """
        return "IV" + super().structure_name()[3:]


def _equation_rss(data: IOData, theta, na, nb, nk, lag: int) -> float:
    """Σ (A(q) y − B(q) u)² over the rows from ``lag`` on."""
    cols = [(data.y, 0)] + [(data.y, k) for k in range(1, na + 1)]
    for i in range(data.n_inputs):
        cols += [(data.u[:, i], nk[i] + j) for j in range(nb[i])]
    mat, _ = lagged_columns(cols, data.segments, lag)
    phi = np.column_stack([-mat[:, 1 : 1 + na], mat[:, 1 + na :]]) if mat.shape[1] > 1 else mat[:, :0]
    return metrics.mean_square(mat[:, 0] - phi @ theta) * mat.shape[0]


def iv(
    data: IOData,
    na: int,
    nb,
    nk,
    *,
    instruments: str | Sequence[str] | None = None,
    iterations: int = 2,
    n_threads: int = 0,
) -> IvModel:
    """Fit an ARX structure by instrumental variables (MATLAB ``iv4``; closed loop with a reference).

    Parameters
    ----------
    data : IOData
        Estimation data.
    na : int
        Number of poles.
    nb, nk : int or sequence of int
        Input orders and delays (one per input, or one for all).
    instruments : None, str or sequence of str
        None: open loop, instruments from the input (IV4). The name of a measured reference or
        setpoint among the data's extra signals (``"roll_sp"``), or several names: closed loop,
        instruments from the reference, which the noise does not reach.
    iterations : int
        IV4 refinement steps (0: the first IV step only).
    n_threads : int
        Threads (0 = all cores).

    Returns
    -------
    IvModel
        An :class:`~arxid.ArxModel` (same polynomials, predictions, checks and exports) whose
        parameters come from the instruments.

    Raises
    ------
    DataError
        When an instrument is not a logged signal, or is the output or an input.
    IdentifiabilityError
        When the instruments do not determine every parameter.

    Notes
    -----
    On closed-loop data, least squares (ARX) and output error (OE) are biased: the controller feeds
    the output noise back into the input. IV with the reference as instrument is consistent for
    any noise colour, because the reference is independent of the noise (Ljung, 2nd ed., 13.5).
    Its price is variance: use enough data and a reference that moves.

    Examples
    --------
    >>> import arxid
    >>> from arxid.datasets import pi_loop, PiLoopPlant
    >>> m = arxid.iv(pi_loop(seed=2, n_samples=8000), 2, 2, 1, instruments="r")
    >>> bool(abs(m.b[0].sum() / m.a.sum() / PiLoopPlant().gain - 1) < 0.05)
    True
    """
    if iterations < 0:
        raise OrderError(f"iterations must be >= 0, got {iterations}")
    return IvModel(na=na, nb=nb, nk=nk, instruments=instruments, iterations=iterations).fit(data, n_threads=n_threads)
