"""Long arrays handed back to the system when they are freed (glibc's allocator, Linux).

glibc gives an allocation above its *mmap threshold* a mapping of its own, returned to the system
when it is freed. But each time such a block is freed, glibc raises the threshold to that block's
size (up to 32 MiB), so later arrays of a few MiB (a signal of 2M samples is 16 MB) come from its
heaps instead. Freed there, they stay with the process, and each thread has heaps of its own
(arenas) that the other threads do not reuse. An analysis frees hundreds of such arrays on two
threads: at 4M samples the resident size rose about 200 MiB above what the analysis held.

:func:`return_large_frees` fixes the threshold at :data:`THRESHOLD` (glibc then stops moving it),
so every array of a MiB or more has its own mapping, for the rest of the process. It does nothing
when ``MALLOC_MMAP_THRESHOLD_`` is set (the user's choice stands) or the C library is not glibc.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
import threading

__all__ = ["THRESHOLD", "return_large_frees"]

#: Allocations of this many bytes or more are mapped on their own (glibc's first default is 128 KiB).
THRESHOLD = 1 << 20

_M_MMAP_THRESHOLD = -3  # mallopt's parameter number in glibc's malloc.h
_lock = threading.Lock()
_state: list[bool] = []  # [whether it was set], once asked


def return_large_frees() -> bool:
    """Fix glibc's mmap threshold at :data:`THRESHOLD` bytes, once per process.

    Returns
    -------
    bool
        Whether the threshold is fixed (False off glibc, or when ``MALLOC_MMAP_THRESHOLD_`` is set).

    Examples
    --------
    >>> isinstance(return_large_frees(), bool)
    True
    """
    with _lock:
        if not _state:
            _state.append(_fix_threshold())
        return _state[0]


def _fix_threshold() -> bool:
    if not sys.platform.startswith("linux") or "MALLOC_MMAP_THRESHOLD_" in os.environ:
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl and others have no mallopt
        return False
    mallopt.argtypes, mallopt.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(mallopt(_M_MMAP_THRESHOLD, THRESHOLD))
