"""Long arrays are mapped from the system once the analysis fixes the allocator's threshold: a
block freed and asked for again does not come from the heap, whose holes stay resident."""

from __future__ import annotations

import os

import numpy as np
import pytest

from arxid._base.heap import MAPPED_FROM, map_large_arrays


def _heap_ranges() -> list[tuple[int, int]]:
    spans = []
    with open("/proc/self/maps") as f:
        for line in f:
            if line.rstrip().endswith("[heap]"):
                lo, hi = line.split()[0].split("-")
                spans.append((int(lo, 16), int(hi, 16)))
    return spans


@pytest.mark.skipif(not hasattr(os, "confstr") or not os.path.exists("/proc/self/maps"), reason="Linux only")
def test_a_long_array_after_a_freed_one_is_mapped_not_carved_from_the_heap():
    try:
        glibc = bool(os.confstr("CS_GNU_LIBC_VERSION"))
    except ValueError:
        glibc = False
    if not glibc:
        assert map_large_arrays() is False
        return
    assert map_large_arrays() is True
    # Without the fixed threshold, freeing this mapped block would raise glibc's threshold past
    # the next array's size, and that array would come from the heap.
    first = np.ones(5 * MAPPED_FROM // 8)
    del first
    second = np.ones(4 * MAPPED_FROM // 8)
    at = second.__array_interface__["data"][0]
    assert not any(lo <= at < hi for lo, hi in _heap_ranges())
