"""The reference a sweep's speed is measured against: MATLAB's ``arxstruc`` in vectorised numpy.

One Gram matrix of the grid's largest regressor ``[Φ_max | y]`` per data set, then per structure a
Cholesky solve of its normal equations, its one-step validation loss as a quadratic form of the
validation Gram matrix, and, for the structures a sweep simulates, a free run with
``scipy.signal.lfilter`` from the measured outputs (where arxid's free run starts). Every structure
uses the rows from the grid's largest lag on, as arxid's sweep does, so the two give the same
numbers and their times compare at equal work.

The benchmark scripts of ``benches/`` and ``arxid bench`` use this one implementation.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from .._base.metrics import rms
from ..data.iodata import IOData
from ..exceptions import DataError

__all__ = ["ArxGrid", "NumpySweep", "numpy_sweep", "arxstruc", "free_run_rms"]

#: One structure: (na, nb per input, nk per input).
Structure = tuple[int, tuple[int, ...], tuple[int, ...]]


@dataclass(frozen=True)
class ArxGrid:
    """The envelope of a set of ARX structures: the columns of ``[Φ_max | y]`` every one reads.

    Columns: ``-y[t-1] … -y[t-na_max]``, then per input ``u_i[t] … u_i[t-span+1]``, then ``y[t]``.

    Parameters
    ----------
    na_max : int
        Largest number of poles.
    span : int
        Input lags per input in the envelope (largest ``nk + nb`` over the structures).
    lag : int
        First regression row (the largest lag of any structure).
    n_inputs : int
        Number of inputs.
    """

    na_max: int
    span: int
    lag: int
    n_inputs: int

    @classmethod
    def of(cls, structures: Sequence[Structure]) -> ArxGrid:
        """The envelope of ``structures`` (a non-empty sequence of ``(na, nb, nk)``).

        Parameters
        ----------
        structures : sequence of (int, tuple of int, tuple of int)
            The structures, nb and nk with one entry per input.

        Returns
        -------
        ArxGrid
            Their envelope.
        """
        na_max = max(s[0] for s in structures)
        span = max(k + b for s in structures for b, k in zip(s[1], s[2]))
        lag = max(max(s[0], *(k + b - 1 for b, k in zip(s[1], s[2]))) for s in structures)
        return cls(na_max=na_max, span=span, lag=max(lag, 1), n_inputs=len(structures[0][1]))

    def matrix(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """``[Φ_max | y]`` of one record on the rows from ``lag`` on.

        Parameters
        ----------
        y : ndarray of shape (n_samples,)
            Output.
        u : ndarray of shape (n_samples, n_inputs)
            Inputs.

        Returns
        -------
        ndarray of shape (n_samples - lag, na_max + n_inputs * span + 1)
        """
        rows = np.arange(self.lag, len(y))
        cols = [-y[rows - i] for i in range(1, self.na_max + 1)]
        for i in range(self.n_inputs):
            cols += [u[rows - k, i] for k in range(self.span)]
        return np.column_stack([*cols, y[rows]])

    def gram(self, y: np.ndarray, u: np.ndarray) -> np.ndarray:
        """The Gram matrix ``AᵀA`` of :meth:`matrix`.

        Parameters
        ----------
        y : ndarray of shape (n_samples,)
            Output.
        u : ndarray of shape (n_samples, n_inputs)
            Inputs.

        Returns
        -------
        ndarray of shape (q, q)
        """
        a = self.matrix(y, u)
        return a.T @ a

    def columns(self, s: Structure) -> list[int]:
        """The envelope's columns structure ``s`` reads, in the order of its parameters.

        Parameters
        ----------
        s : (int, tuple of int, tuple of int)
            One structure.

        Returns
        -------
        list of int
        """
        na, nb, nk = s
        cols, off = list(range(na)), self.na_max
        for b, k in zip(nb, nk):
            cols += [off + k + j for j in range(b)]
            off += self.span
        return cols


def arxstruc(g: np.ndarray, gv: np.ndarray, grid: ArxGrid, structures: Sequence[Structure]) -> tuple[list, np.ndarray]:
    """Parameters and one-step validation loss sums of every structure from two Gram matrices.

    Parameters
    ----------
    g, gv : ndarray of shape (q, q)
        Gram matrices of the envelope on the estimation and validation records.
    grid : ArxGrid
        The envelope.
    structures : sequence of (int, tuple of int, tuple of int)
        The structures.

    Returns
    -------
    thetas : list of ndarray
        Each structure's parameters (a before b, input by input).
    losses : ndarray of shape (n_structures,)
        Sum of squared one-step prediction errors on the validation rows.
    """
    from scipy.linalg import cho_factor, cho_solve  # here: importing arxid does not import scipy.linalg

    q = g.shape[0] - 1
    thetas, out = [], np.empty(len(structures))
    for i, s in enumerate(structures):
        c = grid.columns(s)
        theta = cho_solve(cho_factor(g[np.ix_(c, c)]), g[c, q])
        out[i] = theta @ gv[np.ix_(c, c)] @ theta - 2 * theta @ gv[c, q] + gv[q, q]
        thetas.append(theta)
    return thetas, out


def free_run_rms(theta: np.ndarray, s: Structure, y: np.ndarray, u: np.ndarray, lag: int) -> float:
    """RMS error of a free run with ``scipy.signal.lfilter`` from the measured outputs before ``lag``.

    Parameters
    ----------
    theta : ndarray
        Parameters (a before b, input by input).
    s : (int, tuple of int, tuple of int)
        The structure.
    y : ndarray of shape (n_samples,)
        Measured output.
    u : ndarray of shape (n_samples, n_inputs)
        Inputs.
    lag : int
        First simulated sample (earlier outputs are the measured ones).

    Returns
    -------
    float
        The RMS of ``y - ŷ`` from ``lag`` on (inf when the run overflows).
    """
    from scipy.signal import lfilter, lfiltic  # here: scipy.signal takes seconds to import

    na, nb, nk = s
    a = np.concatenate([[1.0], theta[:na]])
    x, off = np.zeros(len(y)), na
    for i, (b, k) in enumerate(zip(nb, nk)):
        if b:
            x[k:] += np.convolve(u[:, i], theta[off : off + b])[: len(y) - k]
        off += b
    zi = lfiltic([1.0], a, y[lag - 1 :: -1][:na]) if na else None
    with np.errstate(all="ignore"):
        sim = lfilter([1.0], a, x[lag:], zi=zi)[0] if na else x[lag:]
        value = rms(y[lag:] - sim)
    return value if np.isfinite(value) else float("inf")


@dataclass(frozen=True)
class NumpySweep:
    """What :func:`numpy_sweep` computed.

    Attributes
    ----------
    loss_one_step : ndarray of shape (n_structures,)
        Mean squared one-step prediction error on the validation rows.
    rms_free_run : ndarray of shape (n_structures,)
        Free-run RMS on the validation record (NaN where not simulated).
    """

    loss_one_step: np.ndarray
    rms_free_run: np.ndarray


def numpy_sweep(
    est: IOData, val: IOData, structures: Sequence[Structure], simulate: Sequence[bool] | None = None
) -> NumpySweep:
    """MATLAB's ``arxstruc`` in vectorised numpy, with lfilter free runs: a sweep's reference.

    Parameters
    ----------
    est, val : IOData
        Estimation and validation records (complete: no missing samples).
    structures : sequence of (int, tuple of int, tuple of int)
        The structures, nb and nk with one entry per input.
    simulate : sequence of bool, optional
        Which structures to simulate in free run on the validation record (default: every one).

    Returns
    -------
    NumpySweep
        One-step losses of every structure and free-run errors of the simulated ones.

    Raises
    ------
    DataError
        When a record has missing samples or fewer rows than the largest regressor has columns.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from arxid.selection.baseline import numpy_sweep
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(400)
    >>> y = np.zeros(400)
    >>> for t in range(2, 400):
    ...     y[t] = 0.5 * y[t - 1] + u[t - 1]
    >>> d = arxid.IOData(y, u, ts=1.0)
    >>> ref = numpy_sweep(d, d, [(1, (1,), (1,)), (2, (2,), (0,))])
    >>> bool(ref.loss_one_step[0] < 1e-20)
    True
    """
    grid = ArxGrid.of(structures)
    for d in (est, val):
        if not (np.isfinite(d.y).all() and np.isfinite(d.u).all()):
            raise DataError("the numpy reference needs complete records: fill or cut the missing samples first")
        if d.n_samples - grid.lag <= grid.na_max + grid.n_inputs * grid.span:
            raise DataError(f"a record of {d.n_samples} samples is too short for the grid's largest regressor")
    ue, uv = est.u.reshape(est.n_samples, -1), val.u.reshape(val.n_samples, -1)
    g, gv = grid.gram(est.y, ue), grid.gram(val.y, uv)
    thetas, losses = arxstruc(g, gv, grid, structures)
    sim = np.full(len(structures), np.nan)
    for i, s in enumerate(structures):
        if simulate is None or simulate[i]:
            sim[i] = free_run_rms(thetas[i], s, val.y, uv, grid.lag)
    return NumpySweep(loss_one_step=losses / (val.n_samples - grid.lag), rms_free_run=sim)
