"""Large temporaries of an analysis reuse the blocks freed before them.

An analysis of a long record makes many arrays of one length (16 MB each at 2M samples) and frees
them soon after. Freed to the system, each comes back as fresh pages the kernel must zero, and in a
virtual machine that reports free pages to its host, map again: a third of the CPU time of a
4M-sample analysis went there. Inside :func:`kept_blocks`, numpy's freed blocks of 1 MiB or more are
kept, up to :data:`KEPT_BYTES`, for the next array of the same size (numpy's per-context memory
handler, NEP 49; the Rust core's ``keep_array_blocks``). The blocks are freed when the outermost
block ends; arrays that outlive it are freed as usual.

The memory an analysis holds grows by at most :data:`KEPT_BYTES`, and less in practice: an array
that fits no kept block first frees the oldest ones, enough for its size. The answers do not change
(an array's values never depend on where it lives). Threads started by :class:`~.background.Background`
run in their starter's context, so its stages share the handler.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from . import _core

__all__ = ["KEPT_BYTES", "kept_blocks"]

#: Bytes of freed blocks kept at most: three columns of a 2M-sample record (64 MiB took the memory
#: a 4M-sample record with gaps adds to 0.73–0.74 GiB, 48 MiB to 0.70 GiB, as fast).
KEPT_BYTES = 48 * 2**20


@contextmanager
def kept_blocks(limit: int = KEPT_BYTES) -> Iterator[None]:
    """numpy's freed blocks of 1 MiB or more kept for the arrays made inside the block (and in the
    threads it starts with :class:`~.background.Background`), up to ``limit`` bytes.

    Examples
    --------
    >>> import numpy as np
    >>> with kept_blocks():
    ...     a = np.ones(1_000_000)
    ...     del a
    ...     b = np.zeros(1_000_000)  # the block of ``a``, zeroed
    ...     float(b.sum())
    0.0
    """
    previous = _core.keep_array_blocks(limit)
    try:
        yield
    finally:
        _core.release_array_blocks(previous)
