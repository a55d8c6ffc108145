"""Type stub of the Rust extension ``arxid._core`` (private: use the public ``arxid`` API)."""

from typing import Any, Callable, Sequence

import numpy as np
import numpy.typing as npt

_F = npt.NDArray[np.float64]
_Term = tuple[str, int, int]

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
) -> dict[str, Any]: ...
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
    divergence_limit: float = 1e6,
    n_threads: int = 0,
    chunk: int = 64,
    progress: Callable[[int], object] | None = None,
) -> dict[str, Any]: ...
