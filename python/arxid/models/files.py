"""The model file: a versioned JSON schema for a fitted :class:`~arxid.ArxModel`, read strictly, and
the model written to it (:func:`model_content`) and rebuilt from it (:func:`model_of`).

Version 1 holds these fields (all required unless marked optional):

================  ==========================================================================
field             content
================  ==========================================================================
format            ``"arxid.ArxModel"``
version           ``1``
na                int >= 0
nb, nk            one int >= 0 per input
effects           list of effect strings (see :mod:`arxid.effects`)
ts                sampling time in seconds, finite and > 0
output_name       str; ``input_names``: one distinct str per input
output_unit       str (optional); ``input_units``: one str per input (optional)
parameters        p finite numbers: the a's, each input's b's, the effect terms
covariance        p × p numbers
regressor_names   p str
n_rows            int > p (regression rows of the fit); ``n_skipped``: int >= 0
first_lag         int >= 0; ``rss``: finite number >= 0; ``fit_percent``: number
layout            the effect layout: ``nb``, ``nk`` (one int per column; the inputs first, equal
                  to ``nb``, ``nk``), ``output_terms`` (``[kind, power, carrier]`` with kind
                  ``pow``, ``abs``, ``sign`` or ``signdiff``), and optional ``column_labels``,
                  ``effect_of_column``, ``effect_of_term``; it must be what the effects build
================  ==========================================================================

Unknown fields are refused. A file that breaks any rule raises one :class:`DataError` that names
the field (``corrupt model file: layout.nk[0] ...``). Files are read only when they are regular
files of at most :data:`MAX_FILE_BYTES`.
"""

from __future__ import annotations

import json
import math
import os
import re
import stat
from collections.abc import Callable
from typing import Any

import numpy as np

from .._base.limits import MAX_ORDER
from ..data.iodata import IOData
from ..data.samples import MAX_TS, MIN_TS
from ..exceptions import ArxidError, DataError
from .effects import compile_effects
from .fitted_layout import FittedLayout

__all__ = [
    "FORMAT",
    "VERSION",
    "MAX_FILE_BYTES",
    "read_text",
    "parse",
    "validate",
    "model_content",
    "model_of",
    "write_atomically",
]

FORMAT = "arxid.ArxModel"
VERSION = 1
#: Largest model file read (a model with 1000 parameters takes about 40 MB with its covariance).
MAX_FILE_BYTES = 256 * 2**20
_TERM_KINDS = ("pow", "abs", "sign", "signdiff")
_OPTIONAL = {"output_unit", "input_units"}
_FIELDS = {
    "format", "version", "na", "nb", "nk", "effects", "ts", "output_name", "input_names", "output_unit",
    "input_units", "parameters", "covariance", "regressor_names", "n_rows", "n_skipped", "first_lag", "rss",
    "fit_percent", "layout",
}  # fmt: skip
_LAYOUT_FIELDS = {"nb", "nk", "output_terms", "column_labels", "effect_of_column", "effect_of_term"}


class _Corrupt(Exception):
    """A rule of the schema is broken at ``field``."""

    def __init__(self, field: str, what: str):
        super().__init__(f"{field} {what}")


def read_text(path: Any) -> str:
    """The text of a model file, refusing anything but a regular file of at most
    :data:`MAX_FILE_BYTES` (a FIFO, ``/dev/zero``, a directory, a file descriptor number).

    Parameters
    ----------
    path : str or os.PathLike
        The file.

    Returns
    -------
    str
    """
    if not isinstance(path, (str, os.PathLike)):
        raise DataError(f"a model file path must be a str or path, got {type(path).__name__}")
    try:
        info = os.stat(path)
        if not stat.S_ISREG(info.st_mode):
            raise DataError(f"cannot read model file {str(path)!r}: it is not a regular file")
        if info.st_size > MAX_FILE_BYTES:
            raise DataError(f"cannot read model file {str(path)!r}: {info.st_size} bytes is too large for a model")
        with open(path, "rb") as fh:
            raw = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise DataError(f"cannot read model file {str(path)!r}: {exc.strerror or exc}") from None
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise DataError(f"corrupt model file: not UTF-8 text ({exc.reason} at byte {exc.start})") from None


def write_atomically(path: Any, text: str) -> None:
    """Write ``text`` to ``path`` so that the file is either the old one or the whole new one, even
    when the process is killed mid-write.

    The bytes go to an unnamed temporary file in the same folder (Linux ``O_TMPFILE``; a hidden
    ``.name.PID.*.tmp`` file elsewhere), which is flushed to disk, given that hidden name and moved
    over ``path`` with :func:`os.replace` (atomic on POSIX and Windows). A kill between the naming
    and the move leaves the whole new file under its hidden name (without ``O_TMPFILE``, a kill
    mid-write leaves a partial one); the next write of ``path`` removes those of writers that are
    gone.

    Parameters
    ----------
    path : str or os.PathLike
        The file to write.
    text : str
        Its new content (UTF-8).
    """
    if not isinstance(path, (str, os.PathLike)):
        raise DataError(f"a model file path must be a str or path, got {type(path).__name__}")
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    data = text.encode("utf-8")
    tmp = os.path.join(folder, f".{os.path.basename(path)}.{os.getpid()}.{os.urandom(4).hex()}.tmp")
    _remove_stale_temporaries(folder, os.path.basename(path))
    try:
        fd, named = _temporary(folder, tmp)
        try:
            for start in range(0, len(data), 1 << 16):
                os.write(fd, data[start : start + (1 << 16)])
            os.fsync(fd)
            if not named:  # linkat(AT_SYMLINK_FOLLOW) through /proc names the unnamed file
                fds = os.open("/proc/self/fd", os.O_RDONLY | os.O_DIRECTORY)
                try:
                    os.link(str(fd), tmp, src_dir_fd=fds, follow_symlinks=True)
                finally:
                    os.close(fds)
                os.replace(tmp, path)  # at once: the name is visible only between these two calls
        finally:
            os.close(fd)
        if named:  # after the close: Windows does not move an open file
            os.replace(tmp, path)
    except OSError as exc:
        if os.path.lexists(tmp):
            os.unlink(tmp)
        raise DataError(f"cannot write model file {path!r}: {exc.strerror or exc}") from None


def _remove_stale_temporaries(folder: str, name: str) -> None:
    """Removes the hidden temporaries of ``name`` (``.name.PID.*.tmp``) whose writer is no longer
    running: what a kill left behind. Those of running writers stay."""
    pattern = re.compile(rf"\.{re.escape(name)}\.(\d+)\.[0-9a-f]+\.tmp")
    try:
        entries = os.listdir(folder)
    except OSError:
        return  # the write reports what is wrong with the folder
    for entry in entries:
        m = pattern.fullmatch(entry)
        if m is None or _running(int(m[1])):
            continue
        try:
            os.unlink(os.path.join(folder, entry))
        except OSError:
            pass  # another writer removed it first


def _running(pid: int) -> bool:
    """Whether process ``pid`` exists (this process included; on Windows, always: its ``os.kill``
    would end the process)."""
    if pid == os.getpid() or os.name == "nt":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (OverflowError, OSError):  # PermissionError among them
        return True  # someone else's process, or a number that cannot be checked: keep the file
    return True


def _temporary(folder: str, tmp: str) -> tuple[int, bool]:
    """A file descriptor to write the new content to, and whether it already has the name ``tmp``
    (an ``O_TMPFILE`` file has no name until it is linked, so a kill leaves nothing behind)."""
    flag = getattr(os, "O_TMPFILE", 0)
    if flag and os.path.exists("/proc/self/fd"):
        try:
            return os.open(folder, flag | os.O_WRONLY, 0o666), False
        except OSError:
            pass  # a file system without O_TMPFILE support: a named temporary instead
    return os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666), True


def parse(text: Any) -> dict:
    """The validated content of model-file text (see :func:`validate`).

    Parameters
    ----------
    text : str
        JSON text (a leading byte-order mark is allowed).

    Returns
    -------
    dict
    """
    if not isinstance(text, str):
        raise DataError(f"model JSON text must be a str, got {type(text).__name__}")
    try:
        content = json.loads(text.removeprefix("\ufeff"))
    except RecursionError:
        raise DataError("corrupt model file: the JSON is nested too deeply") from None
    except ValueError as exc:
        raise DataError(f"corrupt model file: not JSON ({exc}); write models with ArxModel.to_json()") from None
    return validate(content)


def validate(content: Any) -> dict:
    """Check model-file content against the schema of version :data:`VERSION`.

    Parameters
    ----------
    content : Any
        What ``json.loads`` made of the file.

    Returns
    -------
    dict
        ``content`` itself, every rule checked.
    """
    try:
        _check(content)
    except _Corrupt as exc:
        raise DataError(f"corrupt model file: {exc}; write models with ArxModel.to_json()") from None
    return content


def model_content(model: Any) -> dict:
    """The model-file content of a fitted ARX model (what :meth:`ArxModel.to_dict` gives).

    Parameters
    ----------
    model : ArxModel
        Fitted.

    Returns
    -------
    dict
    """
    model.check_fitted()
    return {
        "format": FORMAT,
        "version": VERSION,
        "na": model.na_,
        "nb": list(model.nb_),
        "nk": list(model.nk_),
        "effects": list(model.effects),
        "ts": model.ts_,
        "output_name": model.output_name_,
        "input_names": list(model.input_names_),
        "output_unit": model.output_unit_,
        "input_units": list(model.input_units_),
        "parameters": [float(x) for x in model.parameters_],
        "covariance": [[float(x) for x in row] for row in model.covariance_],
        "regressor_names": list(model.regressor_names_),
        "n_rows": model.n_rows_,
        "n_skipped": model.n_skipped_,
        "first_lag": model.first_lag_,
        "rss": model.rss_,
        "fit_percent": model.fit_percent_,
        "layout": model.layout_.to_dict(),
    }


def model_of(cls: Callable[..., Any], d: dict) -> Any:
    """The model of validated model-file content (:func:`validate`); it keeps no data.

    Parameters
    ----------
    cls : type
        :class:`~arxid.ArxModel` (or a subclass).
    d : dict
        Content checked by :func:`validate`.

    Returns
    -------
    ArxModel
    """
    na, nb, nk = d["na"], tuple(d["nb"]), tuple(d["nk"])
    model = cls(na=na, nb=nb, nk=nk, effects=tuple(d["effects"]))
    model.na_, model.nb_, model.nk_ = na, nb, nk
    model.ts_, model.output_name_ = float(d["ts"]), d["output_name"]
    model.input_names_ = tuple(d["input_names"])
    model.output_unit_ = d.get("output_unit", "")
    model.input_units_ = tuple(d.get("input_units", ("",) * len(model.input_names_)))
    model.parameters_ = np.array(d["parameters"], dtype=float)
    p = len(model.parameters_)
    model.covariance_ = np.array(d["covariance"], dtype=float).reshape(p, p)
    model.regressor_names_ = tuple(d["regressor_names"])
    model.n_rows_, model.n_skipped_ = d["n_rows"], d["n_skipped"]
    model.first_lag_, model.rss_ = d["first_lag"], float(d["rss"])
    model.fit_percent_ = float(d["fit_percent"])
    model.layout_ = FittedLayout.from_dict(d["layout"], model.input_names_, model.effects)
    model.data_ = None
    return model


# ---------------------------------------------------------------------------------------------- rules
def _int(field: str, v: Any, low: int = 0, high: int = MAX_ORDER) -> int:
    if isinstance(v, bool) or not isinstance(v, int):
        raise _Corrupt(field, f"must be an integer, got {v!r:.60}")
    if not low <= v <= high:
        raise _Corrupt(field, f"= {v} is out of range [{low}, {high}]" + (" (too large)" if v > high else ""))
    return v


def _number(field: str, v: Any, finite: bool = True) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _Corrupt(field, f"must be a number, got {v!r:.60}")
    if finite and not math.isfinite(v):
        raise _Corrupt(field, f"must be finite, got {v!r}")
    return float(v)


def _str(field: str, v: Any) -> str:
    if not isinstance(v, str):
        raise _Corrupt(field, f"must be a string, got {v!r:.60}")
    return v


def _list(field: str, v: Any, item: Callable[[str, Any], Any], length: int | None = None) -> list:
    if not isinstance(v, list):
        raise _Corrupt(field, f"must be a list, got {type(v).__name__}")
    if length is not None and len(v) != length:
        raise _Corrupt(field, f"must have {length} entries, has {len(v)}")
    return [item(f"{field}[{i}]", x) for i, x in enumerate(v)]


def _check(d: Any) -> None:
    if not isinstance(d, dict):
        raise _Corrupt("the file", f"must hold a JSON object, got {type(d).__name__}")
    if d.get("format") != FORMAT:
        raise _Corrupt("format", f"must be {FORMAT!r}, got {d.get('format')!r:.60} (not an arxid model)")
    if d.get("version") != VERSION:
        raise _Corrupt("version", f"must be {VERSION}, got {d.get('version')!r:.60} (unsupported version)")
    unknown = sorted(set(d) - _FIELDS)
    if unknown:
        raise _Corrupt(unknown[0], "is not a field of a version-1 model file")
    missing = sorted(_FIELDS - _OPTIONAL - set(d))
    if missing:
        raise _Corrupt(missing[0], "is missing")
    names = _list("input_names", d["input_names"], _str)
    m = len(names)
    if m == 0 or len(set(names)) != m:
        raise _Corrupt("input_names", "must name at least one input, each once")
    na = _int("na", d["na"])
    nb, nk = _list("nb", d["nb"], _int, m), _list("nk", d["nk"], _int, m)
    _list("effects", d["effects"], _str)
    if not MIN_TS <= _number("ts", d["ts"]) <= MAX_TS:
        raise _Corrupt("ts", f"must be a sampling time in seconds from {MIN_TS:g} to {MAX_TS:g}, got {d['ts']!r}")
    _str("output_name", d["output_name"])
    _str("output_unit", d.get("output_unit", ""))
    _list("input_units", d.get("input_units", [""] * m), _str, m)
    p = len(_list("parameters", d["parameters"], _number))
    _list("covariance", d["covariance"], lambda f, row: _list(f, row, lambda g, x: _number(g, x, False), p), p)
    _list("regressor_names", d["regressor_names"], _str, p)
    _int("n_rows", d["n_rows"], p + 1, 2**62)
    _int("n_skipped", d["n_skipped"], 0, 2**62)
    _int("first_lag", d["first_lag"])
    if _number("rss", d["rss"]) < 0:
        raise _Corrupt("rss", "must be >= 0")
    _number("fit_percent", d["fit_percent"], False)
    _check_layout(d, na, nb, nk, p)


def _term(field: str, v: Any) -> tuple[str, int, int]:
    if not isinstance(v, list) or len(v) != 3:
        raise _Corrupt(field, "must be [kind, power, carrier]")
    if v[0] not in _TERM_KINDS:
        raise _Corrupt(f"{field}[0]", f"must be one of {list(_TERM_KINDS)}, got {v[0]!r:.40}")
    return v[0], _int(f"{field}[1]", v[1], 0, 64), _int(f"{field}[2]", v[2], -1, 2**20)


def _check_layout(d: dict, na: int, nb: list[int], nk: list[int], p: int) -> None:
    lay = d["layout"]
    if not isinstance(lay, dict):
        raise _Corrupt("layout", "must be an object")
    unknown = sorted(set(lay) - _LAYOUT_FIELDS)
    if unknown:
        raise _Corrupt(f"layout.{unknown[0]}", "is not a field of a model layout")
    for key in ("nb", "nk", "output_terms"):
        if key not in lay:
            raise _Corrupt(f"layout.{key}", "is missing")
    cols = len(_list("layout.nb", lay["nb"], _int))
    lay_nk = _list("layout.nk", lay["nk"], _int, cols)
    terms = _list("layout.output_terms", lay["output_terms"], _term)
    for key, item in (("column_labels", _str), ("effect_of_column", _optional_str)):
        if lay.get(key):
            _list(f"layout.{key}", lay[key], item, cols)
    if lay.get("effect_of_term"):
        _list("layout.effect_of_term", lay["effect_of_term"], _str, len(terms))
    if p != na + sum(lay["nb"]) + len(terms):
        raise _Corrupt("parameters", f"has {p} entries, the structure needs {na + sum(lay['nb']) + len(terms)}")
    expected = _layout_of(d, nb, nk)
    for key, got in (("nb", lay["nb"]), ("nk", lay_nk), ("output_terms", [tuple(t) for t in terms])):
        want = list(expected[key])
        if list(got) != want:
            at = next((i for i, (a, b) in enumerate(zip(got, want)) if a != b), min(len(got), len(want)))
            raise _Corrupt(f"layout.{key}[{at}]", f"disagrees with the orders and effects (they build {want})")


def _optional_str(field: str, v: Any) -> str | None:
    return None if v is None else _str(field, v)


def _layout_of(d: dict, nb: list[int], nk: list[int]) -> dict:
    """The layout the model's effects build for its orders, on stand-in signals (the file keeps no
    data; the effects only need the signals' names)."""
    names = list(d["input_names"])
    words = {w for e in d["effects"] for w in _identifiers(e)}
    extra_names = sorted(words - set(names) - {d["output_name"], "y"} - {f"u{i + 1}" for i in range(len(names))})
    rng = np.random.default_rng(0)
    n = 64
    try:
        stand_in = IOData(
            rng.uniform(0.5, 1.5, n),
            rng.uniform(0.5, 1.5, (n, len(names))),
            float(d["ts"]),
            output_name=d["output_name"],
            input_names=tuple(names),
            extra={k: rng.uniform(0.5, 1.5, n) for k in extra_names},
        )
        lay = compile_effects(d["effects"], stand_in, nb, nk)
    except ArxidError as exc:
        raise _Corrupt("effects", f"cannot be built for these signals ({exc})") from None
    return {"nb": lay.nb, "nk": lay.nk, "output_terms": [tuple(t) for t in lay.output_terms]}


def _identifiers(effect: str) -> list[str]:
    """Signal names an effect string may use (``sign(dy)`` may name ``y`` or a signal ``dy``)."""
    words = re.findall(r"[A-Za-z_]\w*", effect)
    out = [w for w in words if w not in ("abs", "sign", "dz", "sat", "pos", "neg", "const", "time")]
    return out + [w[1:] for w in out if w.startswith("d") and len(w) > 1]
