"""State-space models of several inputs and outputs by subspace identification: :func:`ssest`.

The numerical work (the LQ factor of the block-Hankel data, the weighted SVD, A and C, then B, D
and the initial states by least squares) is done in the Rust core; this module gathers the data,
enforces stability when asked and estimates the Kalman gain.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from .._base import _core
from ..exceptions import DataError, IdentifiabilityError, OrderError
from .mimo_data import gather
from .state_space import Refinement, StateSpaceModel

__all__ = ["ssest", "METHODS", "DEFAULT_HORIZON"]

METHODS = ("n4sid", "moesp", "cva")
DEFAULT_HORIZON = 10  # past and future block rows; orders up to 9·n_outputs fit in it
_MAX_ORDER = 20


def _horizons(horizon: Any) -> tuple[int, int]:
    if horizon is None:
        return DEFAULT_HORIZON, DEFAULT_HORIZON
    pair = (horizon, horizon) if np.ndim(horizon) == 0 else tuple(horizon)
    if len(pair) != 2 or not all(float(h) == int(h) for h in pair):
        raise OrderError(f"horizon must be a whole number of samples or a (past, future) pair, got {horizon!r}")
    past, future = int(pair[0]), int(pair[1])
    if past < 1 or future < 2:
        raise OrderError(f"the horizons must be at least 1 (past) and 2 (future) samples, got {past} and {future}")
    return past, future


def _stabilise(a: np.ndarray) -> np.ndarray:
    """A with each eigenvalue outside the unit circle reflected to 1/λ̄ (same frequency, same
    decay rate mirrored), through the eigendecomposition; conjugate pairs stay pairs, so A stays
    real."""
    values, vectors = np.linalg.eig(a)
    outside = np.abs(values) >= 1.0
    if not outside.any():
        return a
    values = np.where(outside, 0.995 / np.conj(values), values)
    return np.real(vectors @ np.diag(values) @ np.linalg.inv(vectors))


def _kalman_gain(
    model: StateSpaceModel, u: np.ndarray, y: np.ndarray, segments: list[tuple[int, int]], lags: int, n_threads: int
) -> np.ndarray:
    """K of the innovation form, by two linear regressions on the output error v = y − ŷ_sim.

    First the innovations e are estimated by a long vector autoregression of v (Hannan–Rissanen);
    then v − e = C (zI − A)⁻¹ K e is linear in K, the same least squares as B with e as input
    (both in the Rust core, ``rust/subspace/kalman_gain.rs``). K is halved until A − KC is stable
    (zero if it never is).
    """
    a, b, c, d, x0 = (np.ascontiguousarray(m) for m in (model.a, model.b, model.c, model.d, model.initial_states))
    gain = _core.subspace_kalman_gain(a, b, c, d, x0, u, y, segments, lags, n_threads)
    for _ in range(12):
        if np.all(np.abs(np.linalg.eigvals(model.a - gain @ model.c)) < 1.0):
            return gain
        gain = gain / 2
    return np.zeros((model.order, model.n_outputs))


def _input_matrices(a, c, u, y, segments, estimate_x0: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """B, D and the initial states by least squares in the Rust core, with advice when the
    simulation of an unstable A swamps the regression."""
    try:
        return _core.subspace_input_matrices(a, c, u, y, segments, feedthrough=True, initial_state=estimate_x0)
    except IdentifiabilityError as exc:
        radius = float(np.max(np.abs(np.linalg.eigvals(a))))
        if radius < 1.0:
            raise
        raise IdentifiabilityError(
            f"the identified dynamics are unstable (a pole of magnitude {radius:.4f}), and simulating them over "
            "the records leaves B and D undetermined; pass stable=True, or detrend the data (an offset "
            "or drift needs an unstable or integrating state)"
        ) from exc


def _refine(
    model: StateSpaceModel,
    u: np.ndarray,
    y: np.ndarray,
    segments: list[tuple[int, int]],
    *,
    estimate_initial: bool,
    stable: bool,
    n_threads: int,
) -> StateSpaceModel:
    """The prediction-error refinement of ``model`` in the Rust core (see ``rust/subspace/refine.rs``)."""
    a, b, c, d, k, x0 = (
        np.ascontiguousarray(m) for m in (model.a, model.b, model.c, model.d, model.k, model.initial_states)
    )
    out = _core.subspace_refine(
        a, b, c, d, k, x0, u, y, segments, estimate_initial=estimate_initial, stable=stable, n_threads=n_threads
    )
    report = Refinement(
        start_loss=float(out["start_loss"]),
        loss=float(out["loss"]),
        iterations=int(out["iterations"]),
        converged=bool(out["converged"]),
        termination=str(out["termination"]),
    )
    return replace(
        model, a=out["a"], b=out["b"], c=out["c"], d=out["d"], k=out["k"], initial_states=out["x0"], refinement=report
    )


def ssest(
    data: Any,
    order: int | None = None,
    *,
    method: str = "n4sid",
    initial: str = "estimate",
    stable: bool = False,
    horizon: int | tuple[int, int] | None = None,
    max_order: int | None = None,
    refine: bool = False,
    n_threads: int = 0,
) -> StateSpaceModel:
    """Estimate a state-space model of several inputs and outputs by subspace identification.

    Parameters
    ----------
    data : IOData or sequence of IOData
        Estimation data; for several outputs, one IOData per output with the same inputs,
        sampling time and experiments. Missing samples (NaN) split an experiment into stretches.
    order : int, optional
        Number of states. None chooses it by the singular value criterion (see Notes).
    method : {"n4sid", "moesp", "cva"}
        Weighting of the projection: N4SID (Van Overschee & De Moor), PO-MOESP (Verhaegen) or CVA
        (Larimore).
    initial : {"estimate", "zero"}
        Initial state of each stretch: estimated by least squares (for records that start
        mid-transient) or zero.
    stable : bool
        Enforce a stable model: poles outside the unit circle are reflected inside (to 0.995/λ̄),
        then B, D and the initial states are re-estimated.
    horizon : int or (int, int), optional
        Past and future horizons of the block-Hankel data in samples (default 10, 10). The order
        can be at most (future − 1) · n_outputs.
    max_order : int, optional
        Largest order the criterion considers (default 20, capped by the horizon).
    refine : bool
        Refine the subspace estimate by the prediction-error method: A, B, C, D, K and the initial
        states minimising the sum of squared one-step prediction errors (see Notes). Slower (a few
        iterations of a full pass over the data each), and most useful with coloured noise.
    n_threads : int
        Threads for the Hankel factorisation (0: all cores).

    Returns
    -------
    StateSpaceModel

    Notes
    -----
    The model is ``x(t+1) = A x(t) + B u(t) + K e(t)``, ``y(t) = C x(t) + D u(t) + e(t)``.
    A and C come from the weighted SVD of the oblique projection of future outputs on past data;
    B, D and x0 minimise the simulation error with A and C fixed; K comes from the output error
    (see ``_kalman_gain``). The order minimises Bauer's singular value criterion
    ``SVC(n) = ρ²(n+1) + n (2 ny + nu) ln(N) / N`` over the canonical correlations ρ of future
    outputs and past data (scale-free, the same for every method), N the Hankel columns.

    With ``refine=True`` the estimate starts a Levenberg–Marquardt search over every entry of A,
    B, C, D and K (and the initial states, unless ``initial="zero"``), moving only across the
    directions a change of state coordinates leaves unchanged (data-driven local coordinates).
    Every step keeps the one-step predictor stable (the eigenvalues of A − KC inside the unit
    circle), and A stable too with ``stable=True``. ``model.refinement`` says how it went.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.choice([-1.0, 1.0], size=2000)
    >>> y = np.zeros(2000)
    >>> for t in range(1, 2000):
    ...     y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1]
    >>> model = arxid.ssest(arxid.IOData(y, u, ts=0.01))
    >>> model.order, round(float(model.poles[0].real), 6)
    (1, 0.9)
    """
    if method not in METHODS:
        raise OrderError(f"method must be one of {list(METHODS)}, got {method!r}")
    if initial not in ("estimate", "zero"):
        raise OrderError(f'initial must be "estimate" or "zero", got {initial!r}')
    if order is not None and (isinstance(order, bool) or not float(order).is_integer() or order < 1):
        raise OrderError(f"order must be a whole number of states >= 1 or None, got {order!r}")
    signals = gather(data)
    past, future = _horizons(horizon)
    segments = [(lo, hi) for lo, hi in signals.segments if hi - lo > 2 * (past + future)]
    if not segments:
        raise DataError(
            f"no stretch of the data without missing samples is longer than {2 * (past + future)} samples, "
            "what the horizons need; use longer records or a shorter horizon"
        )
    u, y = np.ascontiguousarray(signals.u), np.ascontiguousarray(signals.y)
    limit = _MAX_ORDER if max_order is None else int(max_order)
    found = _core.subspace_identify(
        u, y, segments, past, future, method, None if order is None else int(order), limit, n_threads
    )
    a, c = found["a"], found["c"]
    if stable:
        a = np.ascontiguousarray(_stabilise(a))
    b, d, x0 = _input_matrices(a, c, u, y, segments, initial == "estimate")
    model = StateSpaceModel(
        a=a,
        b=b,
        c=c,
        d=d,
        k=np.zeros((a.shape[0], y.shape[1])),
        initial_states=x0,
        ts=signals.ts,
        input_names=signals.input_names,
        output_names=signals.output_names,
        method=method,
        singular_values=found["singular_values"],
        canonical_correlations=found["canonical_correlations"],
        order_criterion=found["criterion"],
        horizon=(past, future),
        order_fixed=order is not None,
    )
    lags = past
    if all(hi - lo > 2 * lags for lo, hi in segments):
        model = replace(model, k=_kalman_gain(model, u, y, segments, lags, n_threads))
    if refine:
        model = _refine(
            model, u, y, segments, estimate_initial=initial == "estimate", stable=stable, n_threads=n_threads
        )
    return model
