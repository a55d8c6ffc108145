"""Freed long arrays go back to the system (glibc): the resident size follows what is held."""

import os
import subprocess
import sys
import textwrap

import pytest

from arxid._base import allocator

pytestmark = pytest.mark.skipif(
    not sys.platform.startswith("linux") or os.confstr("CS_GNU_LIBC_VERSION") is None,
    reason="glibc's allocator only (Linux)",
)

# On a second thread: a 24 MiB block freed (glibc then raises its threshold past 16 MiB), then twenty
# 8 MiB arrays freed between live ones; the resident size above the start once all but one are freed.
_PROBE = textwrap.dedent(
    """
    import sys, threading, numpy as np
    if sys.argv[1] == "fixed":
        from arxid._base.allocator import return_large_frees
        assert return_large_frees()
    def rss():
        with open("/proc/self/status") as f:
            return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024
    base, out = rss(), []
    def work():
        big = np.ones(3 << 20)
        del big
        keep = []
        for i in range(40):
            a = np.ones(1 << 20)
            if i % 2:
                keep.append(a)
        keep[:-1] = []
        out.append(rss() - base)
    t = threading.Thread(target=work)
    t.start()
    t.join()
    print(out[0])
    """
)


def _held_mib(mode: str) -> float:
    env = {k: v for k, v in os.environ.items() if k != "MALLOC_MMAP_THRESHOLD_"}
    done = subprocess.run([sys.executable, "-c", _PROBE, mode], capture_output=True, text=True, env=env, check=True)
    return float(done.stdout.strip())


def test_freed_arrays_leave_the_resident_size_once_the_threshold_is_fixed():
    # glibc's own rule keeps the freed 8 MiB arrays (about 160 MiB); with the threshold fixed only
    # the one live array (8 MiB) remains.
    assert _held_mib("default") > 100
    assert _held_mib("fixed") < 40


def test_the_users_own_threshold_stands(monkeypatch):
    monkeypatch.setenv("MALLOC_MMAP_THRESHOLD_", "65536")
    assert allocator._fix_threshold() is False
