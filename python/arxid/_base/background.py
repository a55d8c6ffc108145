"""Stages of an analysis run beside each other on a second core.

numpy's large operations, BLAS and the Rust core release the GIL, so a stage that depends only on
the data (the feedback test, the checks of where the models fail) can run on another thread
while the caller goes on with the stages that need each other's results. The answer is the same as
when the stages run one after the other: each stage reads only immutable inputs.

Ctrl-C reaches the caller's thread at once (its wait polls); the background stage is a daemon
thread, so the interpreter does not wait for it on the way out.

While stages run beside each other, BLAS runs on one thread (:func:`one_blas_thread`): its own
threads would compete with the stages for the same cores (threaded OpenBLAS made a 4M-sample analysis
a quarter slower on two cores).
"""

from __future__ import annotations

import contextvars
import itertools
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from typing import Any, Generic, TypeVar

from threadpoolctl import threadpool_limits

__all__ = ["Background", "in_two", "in_row_halves", "one_blas_thread"]

T = TypeVar("T")
X = TypeVar("X")

#: Seconds between two looks at Ctrl-C while waiting for a stage.
_POLL = 0.05


class Background(Generic[T]):
    """``fn(*args, **kwargs)`` started on its own thread; :meth:`result` waits for it.

    Parameters
    ----------
    fn : callable
    *args, **kwargs
        Its arguments.

    Examples
    --------
    >>> job = Background(sum, [1, 2, 3])
    >>> job.result()
    6
    """

    def __init__(self, fn: Callable[..., T], *args: Any, **kwargs: Any):
        self._value: T | None = None
        self._error: BaseException | None = None

        context = contextvars.copy_context()  # numpy's settings and memory handler go with the stage

        def run() -> None:
            try:
                self._value = context.run(fn, *args, **kwargs)
            except BaseException as exc:  # handed to the caller by result()
                self._error = exc

        self._thread = threading.Thread(target=run, name=f"arxid-{getattr(fn, '__name__', 'stage')}", daemon=True)
        self._thread.start()

    def result(self) -> T:
        """The stage's return value, once it has finished (its exception, raised here).

        Returns
        -------
        object
            What ``fn`` returned.
        """
        while self._thread.is_alive():
            self._thread.join(_POLL)
        if self._error is not None:
            raise self._error
        return self._value  # type: ignore[return-value]


def in_two(fn: Callable[[X], T], items: Sequence[X]) -> list[T]:
    """``[fn(x) for x in items]`` on this thread and a second one, each taking the next item when it
    is done with its last (validations of refitted models: each a free run, which releases the GIL).

    ``fn`` must read only immutable inputs. When calls fail, the error of the first failing item is
    raised (as in the loop) once both threads have stopped; no item is started after a failure.

    Examples
    --------
    >>> in_two(lambda x: x * x, [1, 2, 3])
    [1, 4, 9]
    """
    out: list[Any] = [None] * len(items)
    failed: dict[int, BaseException] = {}
    taken = itertools.count()  # next() of a count is atomic under the GIL

    def work() -> None:
        for i in taken:
            if i >= len(items) or failed:
                return
            try:
                out[i] = fn(items[i])
            except BaseException as exc:  # raised by the caller, first item first
                failed[i] = exc
                return

    if len(items) > 1:
        second = Background(work)
        work()
        second.result()
    else:
        work()
    if failed:
        raise failed[min(failed)]
    return out


#: Rows from which :func:`in_row_halves` splits the work over two threads.
ROWS_IN_HALVES = 1 << 18


def in_row_halves(fill: Callable[[tuple[int, int]], None], n_rows: int, block: int) -> None:
    """``fill((lo, hi))`` over the rows 0 to ``n_rows``: from :data:`ROWS_IN_HALVES` rows on, the
    two halves (split at a multiple of ``block``) on two threads; fewer, all of them at once.

    For writing a long matrix: numpy copies without holding the GIL, and the first writes into
    fresh memory (the kernel mapping and zeroing its pages) run on both cores. Each half must
    write only its own rows.

    Examples
    --------
    >>> spans = []
    >>> in_row_halves(spans.append, 10, 4)
    >>> spans
    [(0, 10)]
    """
    half = n_rows // 2 // block * block
    if n_rows < ROWS_IN_HALVES or not half:
        fill((0, n_rows))
    else:
        in_two(fill, [(0, half), (half, n_rows)])


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """BLAS (numpy's products and factorizations) on one thread inside the block, restored after.

    The limit is the process's: other threads' BLAS calls run on one thread too meanwhile. Blocks
    inside it (a ladder's diagnoses inside an analysis, on any thread) keep it: only the first
    sets it and the last restores it (each setting looks up the process's libraries, ~1 ms).

    Examples
    --------
    >>> import numpy as np
    >>> with one_blas_thread():
    ...     float(np.ones(3) @ np.ones(3))
    3.0
    """
    global _LIMITED, _OPEN
    with _LIMIT_LOCK:
        if _OPEN == 0:
            _LIMITED = threadpool_limits(limits=1, user_api="blas")
        _OPEN += 1
    try:
        yield
    finally:
        with _LIMIT_LOCK:
            _OPEN -= 1
            if _OPEN == 0 and _LIMITED is not None:
                _LIMITED.restore_original_limits()
                _LIMITED = None


#: The limit :func:`one_blas_thread` set, and how many of its blocks are open.
_LIMITED: threadpool_limits | None = None
_OPEN = 0
_LIMIT_LOCK = threading.Lock()
