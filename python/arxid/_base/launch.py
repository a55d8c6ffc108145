"""Ctrl-C while the ``arxid`` command is still starting: exit 130, as after it has started.

The command line's ``main`` turns a KeyboardInterrupt into exit 130, but ``arxid`` and
``python -m arxid.cli`` import the whole package (numpy, scipy, the core: a second or more) before
``main`` runs. A Ctrl-C in those imports would end the process killed by SIGINT instead (exit -2 to
a parent process). :func:`guard_startup`, run first by ``arxid/__init__.py``, installs a handler
that exits with 130 while the package of a program being launched is imported; ``main`` hands
SIGINT back to Python's KeyboardInterrupt (:func:`end_startup`) once its own handling is in place.
A program that only imports arxid as a library is left alone.
"""

from __future__ import annotations

import gc
import os
import sys
from types import FrameType

__all__ = ["EXIT_INTERRUPTED", "end_startup", "guard_startup", "leave_to_exit"]

#: Exit status after Ctrl-C (128 + SIGINT), as shells report it.
EXIT_INTERRUPTED = 130

#: Whether :func:`guard_startup` turned the garbage collector off for the program's imports.
_collection_paused = False


def _launching() -> bool:
    """The ``arxid`` script, or ``python -m arxid...`` still importing the packages of its module."""
    argv0 = sys.argv[0] if sys.argv else ""
    if argv0 == "-m" or argv0 is None:  # runpy sets the module's path (None without one) once imported
        orig = list(getattr(sys, "orig_argv", []))
        return "-m" in orig[:-1] and orig[orig.index("-m") + 1].split(".")[0] == "arxid"
    return os.path.basename(argv0) in ("arxid", "arxid.exe")  # not pathlib: its import is longer than --help


def _exit_interrupted(signum: int, frame: FrameType | None) -> None:
    sys.stderr.write("arxid: interrupted\n")
    os._exit(EXIT_INTERRUPTED)  # mid-import: nothing is written yet, no cleanup is owed


def guard_startup() -> None:
    """While a program that is ``arxid`` starts, a Ctrl-C exits with 130 (nothing else changes)."""
    if not _launching():
        return
    global _collection_paused
    if gc.isenabled():  # the imports make no garbage worth collecting: end_startup turns collection back on
        gc.disable()
        _collection_paused = True
    import signal  # here: its enums take longer to make than the rest of this module (a library never needs it)

    # Only over Python's own handler: an ignored SIGINT (a background job) or a program's own stays.
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _exit_interrupted)


guard_startup()  # on import: arxid/__init__.py imports this module before anything heavy


def end_startup() -> None:
    """Ctrl-C raises KeyboardInterrupt again (``main`` handles it from here), and the garbage
    collector runs again, past the objects the imports made: they live as long as the program, and
    a collection during the imports or the command would walk every one of them (collecting during
    the imports took a sixth of arxid's import)."""
    global _collection_paused
    if _collection_paused:
        gc.freeze()
        gc.enable()
        _collection_paused = False
    import signal

    if signal.getsignal(signal.SIGINT) is _exit_interrupted:
        signal.signal(signal.SIGINT, signal.default_int_handler)


def leave_to_exit() -> None:
    """The ``arxid`` program is about to exit: the objects it made are left to the process's end.

    The interpreter's last garbage collection would walk every object of the imported packages
    and the analysis (1.5 % of a short ``arxid diagnose``) only to free memory the exit frees
    anyway; frozen objects are not walked. A program that only imports arxid is left alone: its
    objects stay collectable."""
    if _launching():
        gc.freeze()
