"""Long arrays are mapped from the system once the analysis fixes the allocator's threshold: a
block freed and asked for again does not come from the heap, whose holes stay resident."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

# Run in a fresh interpreter: in a long test process the heap may already hold free chunks of this
# size (freed before any threshold was fixed), and malloc serves a request from those before it
# ever considers mapping, whatever the threshold.
_SCRIPT = """
import numpy as np
from arxid._base.heap import MAPPED_FROM, map_large_arrays

def heap_ranges():
    spans = []
    with open("/proc/self/maps") as f:
        for line in f:
            if line.rstrip().endswith("[heap]"):
                lo, hi = line.split()[0].split("-")
                spans.append((int(lo, 16), int(hi, 16)))
    return spans

assert map_large_arrays() is True
# Without the fixed threshold, freeing this mapped block would raise glibc's threshold past the
# next array's size, and that array would come from the heap.
first = np.ones(5 * MAPPED_FROM // 8)
del first
second = np.ones(4 * MAPPED_FROM // 8)
at = second.__array_interface__["data"][0]
print("heap" if any(lo <= at < hi for lo, hi in heap_ranges()) else "mapped")
"""


def _glibc() -> bool:
    try:
        return bool(os.confstr("CS_GNU_LIBC_VERSION"))
    except (ValueError, OSError):
        return False


@pytest.mark.skipif(not os.path.exists("/proc/self/maps"), reason="Linux only")
def test_a_long_array_after_a_freed_one_is_mapped_not_carved_from_the_heap():
    if not _glibc():
        from arxid._base.heap import map_large_arrays

        assert map_large_arrays() is False
        return
    out = subprocess.run([sys.executable, "-c", _SCRIPT], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "mapped"
