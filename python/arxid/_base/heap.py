"""Large arrays mapped from the system, not carved out of the heap.

glibc's allocator serves a request below its mmap threshold from the heap, and raises that threshold
to the size of each mapped block that is freed (up to 32 MiB). After the first few columns of a long
record are freed, every later column of up to 32 MiB (4M samples of float64) comes from the heap,
whose holes between live blocks are not given back: a 4M-sample analysis left about 0.3 GiB of them
resident at its peak. A fixed threshold keeps such arrays mapped, so their pages return to the
system when they are freed. It is the process's setting, and it stays.
"""

from __future__ import annotations

import ctypes
import os

__all__ = ["map_large_arrays", "MAPPED_FROM"]

#: Requests of at least this many bytes are mapped (a column of 512k float64 samples).
MAPPED_FROM = 4 * 2**20

#: glibc's mallopt parameter for the mmap threshold.
_M_MMAP_THRESHOLD = -3

_done: list[bool] = []


def map_large_arrays() -> bool:
    """Fix the allocator's mmap threshold at :data:`MAPPED_FROM` (once per process; glibc only).

    Returns
    -------
    bool
        Whether the threshold is fixed (False on other C libraries, where nothing changes).

    Examples
    --------
    >>> isinstance(map_large_arrays(), bool)
    True
    """
    if not _done:
        _done.append(_set_threshold())
    return _done[0]


def _set_threshold() -> bool:
    try:
        if not os.confstr("CS_GNU_LIBC_VERSION"):  # glibc's answer; other C libraries raise or give None
            return False
        libc = ctypes.CDLL(None)  # the process's own symbols: its C library's mallopt
        return bool(libc.mallopt(_M_MMAP_THRESHOLD, MAPPED_FROM))
    except (OSError, AttributeError, ValueError):
        return False
