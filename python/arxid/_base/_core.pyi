"""Type stub of the Rust extension ``arxid._core`` (private: use the public ``arxid`` API)."""

import os
from collections.abc import Callable, Sequence
from typing import Any, Final, final

import numpy as np
import numpy.typing as npt

_F = npt.NDArray[np.float64]
_B = npt.NDArray[np.bool_]
_Term = tuple[str, int, int]
_Orders = tuple[int, tuple[int, ...], tuple[int, ...]]

__all__ = [
    "keep_array_blocks",
    "release_array_blocks",
    "kept_array_blocks",
    "divergence_limit",
    "finite_peak",
    "finite_squares",
    "finite_squares_of_difference",
    "fit_pass",
    "fit_squares",
    "group_sums",
    "peak_magnitude",
    "iv_sweep",
    "fma_limit",
    "grid_factor",
    "simulate_structures",
    "sweep_factors",
    "fit",
    "fit_from_factor",
    "envelope_factor",
    "fit_memory",
    "free_run_variance",
    "grid_envelope",
    "max_lag",
    "predict",
    "sweep",
    "sweep_memory",
    "FitOutput",
    "SweepOutput",
    "DIVERGENCE_FACTOR",
    "pem_fit",
    "pem_predict",
    "pem_gradient",
    "pem_max_lag",
    "PemOutput",
    "csv_read",
    "blackbox_fields",
    "blackbox_read",
    "dataflash_read",
    "srivc_filter",
    "procest_refine",
    "procest_simulate",
    "threshold_products",
    "dead_zone_and_saturation_products",
    "tested_products",
    "fit_residual",
    "refine_fit_residual",
    "regressor_rows",
    "lagged_products",
    "loss_difference",
    "lagged_r",
    "projected_r",
    "shaped_projected_r",
    "state_space_response",
    "subspace_identify",
    "subspace_input_matrices",
    "subspace_kalman_gain",
    "subspace_refine",
    "ar_filter_rows",
    "lfilter",
]

#: A prediction beyond this many times the largest measured |y| has diverged.
DIVERGENCE_FACTOR: Final[float]

@final
class FitOutput:
    """What :func:`fit` returns."""

    @property
    def theta(self) -> _F: ...
    @property
    def rss(self) -> float: ...
    @property
    def n_rows(self) -> int: ...
    @property
    def n_skipped(self) -> int: ...
    @property
    def inv_gram(self) -> _F: ...

@final
class SweepOutput:
    """What :func:`sweep` returns: one entry per structure of the grid, in grid order."""

    @property
    def theta(self) -> _F: ...
    @property
    def rss_est(self) -> _F: ...
    @property
    def rss_val(self) -> _F: ...
    @property
    def rms_sim_est(self) -> _F: ...
    @property
    def rms_sim_val(self) -> _F: ...
    @property
    def n_sim_est(self) -> _F: ...
    @property
    def n_sim_val(self) -> _F: ...
    @property
    def norm_sim_est(self) -> _F: ...
    @property
    def norm_sim_val(self) -> _F: ...
    @property
    def diverged_est(self) -> _B: ...
    @property
    def diverged_val(self) -> _B: ...
    @property
    def errors(self) -> list[str | None]: ...
    @property
    def n_est(self) -> int: ...
    @property
    def n_val(self) -> int: ...
    @property
    def first_lag(self) -> int: ...
    @property
    def envelope(self) -> _Orders: ...
    @property
    def stage(self) -> npt.NDArray[np.uint8]: ...
    @property
    def r_est(self) -> _F: ...

def fit(
    y: _F,
    u: _F,
    starts: Sequence[int],
    na: int,
    nb: Sequence[int],
    nk: Sequence[int],
    output_terms: Sequence[_Term],
    first_lag: int = 0,
    n_threads: int = 0,
    rows_like: tuple[int, Sequence[int], Sequence[int]] | None = None,
) -> FitOutput: ...
def fit_from_factor(
    r_est: _F,
    n_rows: int,
    envelope: tuple[int, Sequence[int], Sequence[int]],
    structure: tuple[int, Sequence[int], Sequence[int]],
    output_terms: Sequence[_Term],
) -> FitOutput: ...
def envelope_factor(
    y: _F,
    columns: Sequence[_F],
    starts: Sequence[int],
    envelope: tuple[int, Sequence[int], Sequence[int]],
    first_lag: int,
    n_threads: int = 0,
) -> tuple[_F, int]: ...
def free_run_variance(
    y: _F,
    u: _F,
    starts: Sequence[int],
    na: int,
    nb: Sequence[int],
    nk: Sequence[int],
    thetas: _F,
    step: float,
    first_lag: int = 0,
) -> _F | None: ...
def predict(
    y: _F,
    u: _F,
    starts: Sequence[int],
    na: int,
    nb: Sequence[int],
    nk: Sequence[int],
    output_terms: Sequence[_Term],
    theta: _F,
    horizon: int | None = None,
    first_lag: int = 0,
) -> _F: ...
def sweep(
    y: _F,
    u: _F,
    starts: Sequence[int],
    structures: npt.NDArray[np.int64],
    output_terms: Sequence[_Term],
    yv: _F | None = None,
    uv: _F | None = None,
    starts_v: Sequence[int] | None = None,
    simulate_estimation: bool = True,
    horizon: int | None = None,
    n_threads: int = 0,
    chunk: int = 64,
    progress: Callable[[int], object] | None = None,
    top: int | None = None,
) -> SweepOutput: ...
def grid_envelope(structures: npt.NDArray[np.int64], output_terms: Sequence[_Term]) -> tuple[int, _Orders]: ...
def max_lag(na: int, nb: Sequence[int], nk: Sequence[int], output_terms: Sequence[_Term]) -> int: ...
def sweep_memory(n_structures: int, p_max: int, q: int, n_est: int, n_val: int, n_cols: int, n_threads: int) -> int: ...
def fit_memory(n_rows: int, n_params: int, n_threads: int) -> int: ...
def divergence_limit(y: _F) -> float: ...
def finite_squares(x: _F) -> tuple[float, int]: ...
def finite_squares_of_difference(y: _F, p: _F) -> tuple[float, int]: ...
def fit_pass(y: _F, p: _F) -> tuple[int, float, float, bool, float, float]: ...
def fit_squares(y: _F, p: _F, mean: float, scale: float) -> tuple[float, float]: ...
def group_sums(
    group: npt.NDArray[np.uint8], groups: int, series: Sequence[_F]
) -> tuple[npt.NDArray[np.uint64], _F, npt.NDArray[np.bool_]]: ...
def peak_magnitude(x: _F) -> float: ...
def finite_peak(x: _F) -> float: ...

# ---------------------------------------------------------------- numpy's memory handler of an analysis
def keep_array_blocks(limit: int) -> Any: ...
def release_array_blocks(previous: Any) -> None: ...
def kept_array_blocks() -> tuple[int, int]: ...

# ---------------------------------------------------------------- prediction-error models
_PolyOrders = tuple[int, Sequence[int], int, int, Sequence[int], Sequence[int]]

@final
class PemOutput:
    """What :func:`pem_fit` returns."""

    @property
    def theta(self) -> _F: ...
    @property
    def start(self) -> _F: ...
    @property
    def rss(self) -> float: ...
    @property
    def start_rss(self) -> float: ...
    @property
    def n_rows(self) -> int: ...
    @property
    def inv_gram(self) -> _F: ...
    @property
    def iterations(self) -> int: ...
    @property
    def losses(self) -> _F: ...
    @property
    def termination(self) -> str: ...
    @property
    def converged(self) -> bool: ...
    @property
    def initial_segments(self) -> list[tuple[int, int]]: ...
    @property
    def initial_states(self) -> list[list[float]]: ...

def pem_fit(
    y: _F,
    u: _F,
    segments: Sequence[tuple[int, int]],
    orders: _PolyOrders,
    start: _F | None = None,
    max_iterations: int = 100,
    tolerance: float = 1e-6,
    n_threads: int = 0,
    initial: str = "zero",
) -> PemOutput: ...
def pem_predict(
    y: _F,
    u: _F,
    segments: Sequence[tuple[int, int]],
    orders: _PolyOrders,
    theta: _F,
    horizon: int | None = None,
    initial: str = "zero",
) -> _F: ...
def pem_gradient(
    y: _F, u: _F, segments: Sequence[tuple[int, int]], orders: _PolyOrders, theta: _F
) -> tuple[_F, _F]: ...
def pem_max_lag(orders: _PolyOrders) -> int: ...

# Sweeps at scale (arxid.fleet, benches).
def grid_factor(
    y: _F,
    u: _F,
    starts: Sequence[int],
    structures: npt.NDArray[np.int64],
    output_terms: Sequence[_Term],
    n_threads: int = 1,
) -> tuple[_F, int]: ...
def sweep_factors(
    r_est: _F,
    n_est: int,
    structures: npt.NDArray[np.int64],
    output_terms: Sequence[_Term],
    r_val: _F | None = None,
    n_val: int = 0,
    top: int | None = None,
    n_threads: int = 0,
) -> tuple[SweepOutput, npt.NDArray[np.uintp]]: ...
def simulate_structures(
    y: _F,
    u: _F,
    starts: Sequence[int],
    structures: npt.NDArray[np.int64],
    output_terms: Sequence[_Term],
    theta: _F,
    first_lag: int,
    horizon: int | None = None,
    n_threads: int = 0,
    limit: float | None = None,
) -> tuple[_F, _F, _F, _F, _B]: ...
def fma_limit(n_vectors: int, n_threads: int = 0) -> float: ...
def iv_sweep(
    y: _F,
    u: _F,
    starts: Sequence[int],
    xy: _F,
    xu: _F,
    structures: npt.NDArray[np.int64],
    yv: _F | None = None,
    uv: _F | None = None,
    starts_v: Sequence[int] | None = None,
    simulate_estimation: bool = True,
    horizon: int | None = None,
    n_threads: int = 0,
    chunk: int = 64,
    progress: Callable[[int], object] | None = None,
) -> tuple[SweepOutput, list[_F], int]: ...

# (kind, line, offset, got, column, text): see rust/python/csv.rs
_CsvProblem = tuple[str, int, int, int, int, str]

def csv_read(
    path: str | os.PathLike[str], delimiter: str, n_fields: int, wanted: Sequence[int]
) -> tuple[list[_F] | None, bool, _CsvProblem | None]: ...

# flight logs: see rust/python/flight_log.rs
def blackbox_fields(path: str | os.PathLike[str], log: int) -> tuple[int, list[tuple[str, str]], list[str]]: ...
def blackbox_read(
    path: str | os.PathLike[str], log: int, wanted: Sequence[str]
) -> tuple[int, list[tuple[str, str]], list[str], _F, _F, list[_F], list[str], bool]: ...

# (time_us, instance or None, columns, units) of one message
_Message = tuple[_F, _F | None, list[_F], list[str]]

def dataflash_read(
    path: str | os.PathLike[str], wanted: Sequence[tuple[str, str]]
) -> tuple[list[tuple[str, _Message]], int, int, int, list[tuple[str, list[str], int]]]: ...
def srivc_filter(
    signal: _F, segments: Sequence[tuple[int, int]], phi: _F, prev: _F, cur: _F, next: _F, shift: int = 0
) -> _F: ...
def threshold_products(
    a: _F, e: _F, lagged: _F, thresholds: _F, dead_zone: bool, n_threads: int = 0
) -> tuple[_F, _F]: ...
def dead_zone_and_saturation_products(
    a: _F, e: _F, lagged: _F, thresholds: _F, n_threads: int = 0
) -> tuple[_F, _F]: ...
def tested_products(
    a: _F, e: _F, blocks: Sequence[tuple[_F, int, bool]], n_threads: int = 0
) -> list[tuple[_F, _F]]: ...
def fit_residual(a: _F, y: _F, theta: _F, n_threads: int = 0) -> tuple[_F, _F]: ...
def refine_fit_residual(a: _F, e: _F, delta: _F, n_threads: int = 0) -> float: ...
def regressor_rows(
    y: _F,
    u: _F,
    na: int,
    nb: Sequence[int],
    nk: Sequence[int],
    output_terms: Sequence[tuple[str, int, int]],
    rows: npt.NDArray[np.int64],
    out: _F,
    negate_output: bool = True,
    n_threads: int = 0,
) -> npt.NDArray[np.bool_]: ...

# The factor of lagged signals (arxid.models.lagged, the residual tests, the dependence test).
def lagged_r(
    sources: Sequence[_F],
    columns: Sequence[tuple[int, int, int]],
    segments: Sequence[tuple[int, int]],
    back: int,
    ahead: int,
    skip_missing: bool = True,
    n_threads: int = 0,
) -> tuple[_F, int]: ...
def projected_r(q: _F, y: _F, z: _F) -> tuple[_F, _F]: ...
def shaped_projected_r(
    q: _F, y: _F, series: _F, index: npt.NDArray[np.int64]
) -> tuple[_F, _F, npt.NDArray[np.bool_]]: ...
def ar_filter_rows(v: _F, a: _F, runs: Sequence[tuple[int, int, int]]) -> None: ...
def lagged_products(a: _F, b: _F, first: int, last: int) -> _F: ...
def loss_difference(y: _F, base: _F, pred: _F) -> tuple[int, float, _F]: ...
def lfilter(b: _F, a: _F, x: _F) -> _F: ...

_Process = tuple[int, bool, bool, bool, bool]

def procest_simulate(
    u: _F, segments: Sequence[tuple[int, int]], ts: float, structures: Sequence[_Process], x: _F
) -> _F: ...
def procest_refine(
    y: _F,
    u: _F,
    segments: Sequence[tuple[int, int]],
    ts: float,
    structures: Sequence[_Process],
    x0: _F,
    lower: _F,
    upper: _F,
    max_iterations: int = 100,
) -> tuple[_F, _F, _F, int, int, bool, list[bool]]: ...

# Subspace identification (rust/subspace, rust/py_subspace.rs).
def subspace_identify(
    u: _F,
    y: _F,
    segments: Sequence[tuple[int, int]],
    past: int,
    future: int,
    method: str,
    order: int | None,
    max_order: int,
    n_threads: int = 0,
) -> dict[str, Any]: ...
def subspace_input_matrices(
    a: _F,
    c: _F,
    u: _F,
    y: _F,
    segments: Sequence[tuple[int, int]],
    feedthrough: bool = True,
    initial_state: bool = True,
) -> tuple[_F, _F, _F]: ...
def subspace_kalman_gain(
    a: _F,
    b: _F,
    c: _F,
    d: _F,
    x0: _F,
    u: _F,
    y: _F,
    segments: Sequence[tuple[int, int]],
    lags: int,
    n_threads: int = 0,
) -> _F: ...
def subspace_refine(
    a: _F,
    b: _F,
    c: _F,
    d: _F,
    k: _F,
    x0: _F,
    u: _F,
    y: _F,
    segments: Sequence[tuple[int, int]],
    estimate_initial: bool = True,
    stable: bool = False,
    max_iterations: int = 50,
    tolerance: float = 1e-7,
    n_threads: int = 0,
) -> dict[str, Any]: ...
def state_space_response(a: _F, b: _F, c: _F, d: _F, x0: _F, u: _F) -> tuple[_F, _F]: ...
