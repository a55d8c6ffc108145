"""What a computation may cost: bounds on orders, the memory this process can still allocate, and
the one check that refuses work too large for the machine before anything is allocated.

The memory available is the least of three limits, because any of them ends the process: the
free memory of the machine (``MemAvailable`` in ``/proc/meminfo``), the address-space limit of the
process (``ulimit -v``, ``RLIMIT_AS``) minus what it already maps, and the memory limit of its
control group (cgroup v2 ``memory.max``, v1 ``memory.limit_in_bytes``) minus what the group uses.
"""

from __future__ import annotations

import numbers
from pathlib import Path
from typing import Any

from ..exceptions import DataError, OrderError

__all__ = [
    "MAX_ORDER",
    "MAX_WORK",
    "UNCHECKED_MEMORY",
    "available_memory",
    "check_memory",
    "check_order",
    "check_work",
    "describe_bytes",
]

#: Largest order, delay, horizon or thread count accepted (the Rust core's bound): larger values
#: cannot describe sampled data and would overflow lag arithmetic.
MAX_ORDER = 2**40

#: Multiply-adds a single prediction may cost (about a minute of one core); beyond it arxid refuses
#: instead of running for hours without a way to stop it.
MAX_WORK = 10**11

# Memory assumed when no limit can be read (not Linux, no /proc).
_FALLBACK_MEMORY = 4 * 2**30


def check_order(name: str, value: Any) -> int:
    """``value`` as an int in ``[0, MAX_ORDER]``, else an :class:`OrderError` naming ``name``.

    Parameters
    ----------
    name : str
        The argument's name, for the message.
    value : Any
        What the user passed.

    Returns
    -------
    int
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise OrderError(f"{name} must be a non-negative integer, got {value!r}")
    value = int(value)
    if value < 0:
        raise OrderError(f"{name} must be >= 0, got {value}")
    if value > MAX_ORDER:
        raise OrderError(f"{name} = {value} is too large (at most {MAX_ORDER}); orders and delays count samples")
    return value


def describe_bytes(n: float) -> str:
    """``1.50 GiB`` or ``12.0 MiB``.

    Parameters
    ----------
    n : float
        A number of bytes.

    Returns
    -------
    str
    """
    return f"{n / 2**30:.2f} GiB" if n >= 2**28 else f"{n / 2**20:.1f} MiB"


def _read_int(path: Path) -> int | None:
    """The integer in a one-line kernel file; None when absent, unreadable or ``max``."""
    try:
        text = path.read_text().split()[0]
    except (OSError, IndexError):
        return None
    return int(text) if text.isdigit() else None


def _meminfo_available() -> int | None:
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _address_space_left() -> int | None:
    """``RLIMIT_AS`` minus the address space this process already maps (``VmSize``)."""
    try:
        import resource
    except ImportError:  # not on POSIX
        return None
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    if soft == resource.RLIM_INFINITY or soft < 0:
        return None
    used = 0
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("VmSize:"):
                    used = int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return max(soft - used, 0)


def _cgroup_left(root: Path = Path("/sys/fs/cgroup")) -> int | None:
    """The memory limit of this process's control group minus its usage (v2, then v1)."""
    for limit_file, usage_file in (
        ("memory.max", "memory.current"),
        ("memory/memory.limit_in_bytes", "memory/memory.usage_in_bytes"),
    ):
        limit = _read_int(root / limit_file)
        # cgroup v1 writes "no limit" as a huge number (about 2^63).
        if limit is not None and limit < 2**60:
            return max(limit - (_read_int(root / usage_file) or 0), 0)
    return None


def available_memory() -> int:
    """Bytes this process can still allocate: the least of the machine's free memory, the
    address-space limit and the control group's limit (see the module notes).

    Returns
    -------
    int
    """
    limits = [v for v in (_meminfo_available(), _address_space_left(), _cgroup_left()) if v is not None]
    return min(limits) if limits else _FALLBACK_MEMORY


#: Bytes a computation may need without asking the kernel what is left (a short record's fit).
UNCHECKED_MEMORY = 32 * 2**20


def check_memory(need: int, what: str, fix: str, max_memory: int | None = None) -> None:
    """Refuse, before allocating, a computation needing more than ``max_memory`` bytes (default:
    half of :func:`available_memory`, for a need above :data:`UNCHECKED_MEMORY`).

    Parameters
    ----------
    need : int
        Estimated bytes.
    what : str
        What needs them, e.g. ``"the fit of ARX(2000,2000,0) on 1,000,000 samples"``.
    fix : str
        How to make it smaller.
    max_memory : int, optional
        The limit in bytes.

    Returns
    -------
    None
    """
    if max_memory is None and need <= UNCHECKED_MEMORY:
        return  # asking the kernel (four files) would take longer than such a computation
    limit = int(max_memory) if max_memory is not None else available_memory() // 2
    if need > limit:
        raise DataError(
            f"{what} needs about {describe_bytes(need)}, more than the limit of {describe_bytes(limit)} "
            f"(half the memory this process can still allocate, or max_memory); {fix}"
        )


def check_work(operations: int, what: str, fix: str) -> None:
    """Refuse a computation of more than :data:`MAX_WORK` multiply-adds.

    Parameters
    ----------
    operations : int
        Estimated multiply-adds.
    what : str
        What would cost them.
    fix : str
        How to make it cheaper.

    Returns
    -------
    None
    """
    if operations > MAX_WORK:
        raise DataError(
            f"{what} would cost about {operations:.2g} multiply-adds (hours of computing), more than the "
            f"limit of {MAX_WORK:.0e}; {fix}"
        )
