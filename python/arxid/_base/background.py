"""Stages of an analysis run beside each other on a second core.

numpy's large operations, BLAS and the Rust core release the GIL, so a stage that depends only on
the data (the feedback test, the checks of where the models fail) can run on another thread
while the caller goes on with the stages that need each other's results. The answer is the same as
when the stages run one after the other: each stage reads only immutable inputs.

Ctrl-C reaches the caller's thread at once (its wait polls); the background stage is a daemon
thread, so the interpreter does not wait for it on the way out.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any, Generic, TypeVar

__all__ = ["Background"]

T = TypeVar("T")

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

        def run() -> None:
            try:
                self._value = fn(*args, **kwargs)
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
