"""numpy's freed blocks kept for the next array of the same size while an analysis runs
(arxid._base.array_memory): reused, zeroed where numpy asks for zeros, bounded, and all freed when
the outermost block ends."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from arxid._base import _core
from arxid._base.array_memory import KEPT_BYTES, kept_blocks
from arxid._base.background import Background, in_two

try:
    from numpy._core.multiarray import get_handler_name
except ImportError:  # numpy 1.x
    from numpy.core.multiarray import get_handler_name

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="blocks are kept on Linux only")

N = 1 << 18  # 2 MiB of float64: a block that is kept


def test_a_freed_block_serves_the_next_array_of_its_size_and_zeros_are_zeros():
    with kept_blocks():
        assert get_handler_name() == "arxid_kept_blocks"
        a = np.full(N, 7.0)
        address = a.ctypes.data
        del a
        count, kept = _core.kept_array_blocks()
        assert count == 1 and 8 * N <= kept <= 8 * N + 2 * 4096
        b = np.zeros(N)  # numpy's calloc: the kept block, written with zeros
        assert b.ctypes.data == address
        assert not b.any()
        assert _core.kept_array_blocks() == (0, 0)
        del b
        c = np.empty(N // 2)  # far smaller than the kept block: a block of its own
        assert c.ctypes.data != address
    assert get_handler_name() == "default_allocator"
    assert _core.kept_array_blocks() == (0, 0)


def test_small_blocks_are_never_kept_and_arrays_outliving_the_block_are_freed_as_usual():
    with kept_blocks():
        small = [np.ones(1000) for _ in range(50)]
        del small
        assert _core.kept_array_blocks() == (0, 0)
        survivor = np.arange(float(N))
    assert _core.kept_array_blocks() == (0, 0)
    assert survivor[-1] == N - 1
    del survivor  # freed by its own handler outside every block: not kept
    assert _core.kept_array_blocks() == (0, 0)


def test_the_kept_bytes_stay_within_the_limit_oldest_freed_first():
    limit = 3 * 8 * N + 3 * 4096
    with kept_blocks(limit):
        arrays = [np.ones(N) for _ in range(6)]
        del arrays
        count, kept = _core.kept_array_blocks()
        assert count == 3 and kept <= limit
    assert _core.kept_array_blocks() == (0, 0)


def test_an_array_no_kept_block_fits_takes_the_place_of_the_oldest_kept_ones():
    """What the process holds, arrays and kept blocks together, grows no more than without keeping."""
    with kept_blocks():
        a, b = np.ones(N), np.ones(N)
        del a, b
        assert _core.kept_array_blocks()[0] == 2
        c = np.ones(N // 2 + N // 4)  # 1.5 MiB fits no kept block: the oldest, enough for it, is freed
        assert _core.kept_array_blocks()[0] == 1
        d = np.ones(4 * N)  # the last kept block is freed too
        assert _core.kept_array_blocks() == (0, 0)
        assert c.sum() == N // 2 + N // 4 and d.sum() == 4 * N


def test_nested_blocks_free_the_kept_blocks_when_the_outermost_ends():
    with kept_blocks():
        with kept_blocks():
            a = np.ones(N)
            del a
        assert _core.kept_array_blocks()[0] == 1
        assert get_handler_name() == "arxid_kept_blocks"
    assert _core.kept_array_blocks() == (0, 0)


def test_stages_on_other_threads_share_the_handler_and_compute_the_same():
    x = np.random.default_rng(0).standard_normal(N)
    want = [float(np.sum(x * k)) for k in range(1, 5)]
    with kept_blocks():
        assert Background(get_handler_name).result() == "arxid_kept_blocks"
        got = in_two(lambda k: float(np.sum(x * k)), [1, 2, 3, 4])
    assert got == want
    assert Background(get_handler_name).result() == "default_allocator"


def test_an_error_inside_the_block_still_frees_the_kept_blocks():
    with pytest.raises(ValueError, match="inside"):
        with kept_blocks():
            a = np.ones(N)
            del a
            raise ValueError("raised inside")
    assert _core.kept_array_blocks() == (0, 0)
    assert get_handler_name() == "default_allocator"


def test_the_default_limit_holds_a_few_columns_of_a_long_record():
    assert 3 * 8 * 2_000_000 <= KEPT_BYTES <= 64 * 2**20
