"""``.npz`` archives of named arrays as the CLI's data (:func:`read_npz`)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..exceptions import DataError

__all__ = ["read_npz"]


def read_npz(p: Path, wanted: Sequence[str], ts: float | None, time_col: str | None) -> tuple[dict, float | None]:
    """The real 1-D arrays of an archive by name, and its sampling time.

    The sampling time is ``ts``, else a scalar array ``ts`` in the archive (unless ``time_col`` names
    a time array). The arrays in ``wanted`` must be real 1-D signals; others that are not are skipped.

    Parameters
    ----------
    p : Path
    wanted : sequence of str
        The signals the command reads.
    ts : float or None
    time_col : str or None

    Returns
    -------
    columns : dict of str to ndarray
    ts : float or None

    Raises
    ------
    DataError
        On an unreadable archive or a wanted array that is not a real 1-D signal.
    """
    try:
        with np.load(p, allow_pickle=False) as z:
            arrays = {k: np.asarray(z[k]) for k in z.files}
    except Exception as exc:  # any failure to read the archive: BadZipFile, zlib.error, EOFError, ...
        raise DataError(f"{p.name} is not a readable .npz archive ({' '.join(str(exc).split()[:12])})") from None
    if ts is None and time_col is None and "ts" in arrays and arrays["ts"].size == 1:
        if not np.issubdtype(arrays["ts"].dtype, np.number) or np.iscomplexobj(arrays["ts"]):
            raise DataError(
                f"{p.name}: the array 'ts' holds {arrays['ts'].reshape(-1)[0]!r}, not a sampling "
                "time in seconds; store a number or pass --ts"
            )
        ts = float(arrays["ts"].reshape(-1)[0])
    columns = {}
    for k, v in arrays.items():
        if v.ndim == 0 or v.size <= 1:
            continue
        numeric = np.issubdtype(v.dtype, np.number) or v.dtype == bool
        if k not in wanted:
            if numeric and not np.iscomplexobj(v) and v.ndim == 1:
                columns[k] = v.astype(float)
            continue
        if not numeric or np.iscomplexobj(v):
            raise DataError(f"{p.name}: the array {k!r} holds {v.dtype} values, not real numbers")
        if v.ndim != 1:
            raise DataError(
                f"{p.name}: the array {k!r} has shape {v.shape}; store each signal as a 1-D "
                "array of samples under its own name"
            )
        columns[k] = v.astype(float)
    return columns, ts
