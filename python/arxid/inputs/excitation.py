"""The designed input signal (:class:`Excitation`): samples, sampling time, period, spectrum, CSV."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._base.metrics import rms
from ..exceptions import DataError

__all__ = ["Excitation", "crest_factor"]


def crest_factor(x) -> float:
    """Peak over RMS of a signal, ``max|x| / rms(x)`` (1 for a square wave, √2 for a sine).

    Parameters
    ----------
    x : array_like of shape (n_samples,)

    Returns
    -------
    float

    Examples
    --------
    >>> import numpy as np
    >>> round(crest_factor(np.sin(2 * np.pi * np.arange(100) / 100)), 4)
    1.4142
    """
    x = np.asarray(x, dtype=float)
    return float(np.max(np.abs(x)) / rms(x))


@dataclass(frozen=True)
class Excitation:
    """An excitation signal designed for an identification experiment.

    Parameters
    ----------
    values : ndarray of shape (n_samples,)
        The samples, to be applied with a zero-order hold.
    ts : float
        Sampling time [s].
    kind : str
        ``"prbs"``, ``"multisine"`` or ``"chirp"``.
    period : int
        Samples in one period (the whole signal for a chirp).
    description : str
        One sentence: what was designed (lines, band, levels).

    Examples
    --------
    >>> from arxid.inputs import prbs
    >>> x = prbs(5, ts=0.01)
    >>> x.period, x.n_samples, round(x.duration, 2)
    (31, 31, 0.31)
    """

    values: np.ndarray
    ts: float
    kind: str
    period: int
    description: str

    @property
    def n_samples(self) -> int:
        """Number of samples."""
        return int(self.values.shape[0])

    @property
    def duration(self) -> float:
        """Length of the signal in seconds."""
        return self.n_samples * self.ts

    @property
    def time(self) -> np.ndarray:
        """Sample times [s], from 0."""
        return np.arange(self.n_samples) * self.ts

    @property
    def crest_factor(self) -> float:
        """Peak over RMS (:func:`crest_factor`)."""
        return crest_factor(self.values)

    def __array__(self, dtype=None, copy=None):
        return np.asarray(self.values, dtype=dtype)

    def __len__(self) -> int:
        return self.n_samples

    def spectrum(self) -> tuple[np.ndarray, np.ndarray]:
        """Power of each frequency line over one period.

        The discrete Fourier transform of one period: the power at ``k / (period * ts)`` Hz is
        ``|X_k|^2 / period^2`` doubled for the one-sided spectrum, so the powers add up to the mean
        square of the signal (Parseval). A PRBS spreads its power evenly up to its band; a
        multisine puts it on its lines only; a chirp over the band it sweeps.

        Returns
        -------
        frequency : ndarray of shape (period // 2 + 1,)
            [Hz].
        power : ndarray of shape (period // 2 + 1,)
            [unit^2] per line.

        Examples
        --------
        >>> import numpy as np
        >>> from arxid.inputs import multisine
        >>> x = multisine(64, lines=[2, 5])
        >>> f, p = x.spectrum()
        >>> [int(k) for k in np.flatnonzero(p > 1e-12)]
        [2, 5]
        """
        n = self.period
        one = self.values[:n]
        spec = np.fft.rfft(one) / n
        power = np.abs(spec) ** 2
        power[1:] *= 2.0
        if n % 2 == 0:
            power[-1] /= 2.0
        return np.fft.rfftfreq(n, self.ts), power

    def to_csv(self, path, *, name: str = "u", unit: str = "") -> Path:
        """Write the signal as a CSV file with a time column, for a flight controller or test stand.

        The header is ``time[s],<name>[<unit>]``, the convention :meth:`arxid.IOData.from_csv`
        reads back; one row per sample, times from 0.

        Parameters
        ----------
        path : str or Path
        name : str
            Column name of the signal.
        unit : str
            Its unit (empty: no brackets).

        Returns
        -------
        Path
            The file written.

        Examples
        --------
        >>> import tempfile, pathlib
        >>> from arxid.inputs import prbs
        >>> p = prbs(3).to_csv(pathlib.Path(tempfile.mkdtemp()) / "u.csv", name="roll_sp", unit="rad")
        >>> p.read_text().splitlines()[:2]
        ['time[s],roll_sp[rad]', '0,-1']
        """
        if not name or any(c in name for c in ",\n\r[]"):
            raise DataError(f"column name {name!r} cannot be written to a CSV header; use letters, digits and _")
        path = Path(path)
        header = f"time[s],{name}[{unit}]" if unit else f"time[s],{name}"
        lines = [header] + [f"{t:.9g},{v:.17g}" for t, v in zip(self.time, self.values, strict=True)]
        path.write_text("\n".join(lines) + "\n", encoding="utf-8")
        return path

    def __str__(self) -> str:
        return (
            f"{self.kind}: {self.n_samples} samples at {self.ts:g} s ({self.duration:g} s), "
            f"period {self.period} samples, crest factor {self.crest_factor:.2f}. {self.description}"
        )


def check_ts(ts: float) -> float:
    """A positive finite sampling time, or a DataError."""
    try:
        value = float(ts)
    except (TypeError, ValueError):
        raise DataError(f"ts must be a number of seconds, got {ts!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise DataError(f"ts must be a positive sampling time in seconds, got {ts!r}")
    return value


def check_periods(periods: int) -> int:
    """A whole number of periods >= 1, or a DataError."""
    if isinstance(periods, bool) or not isinstance(periods, (int, np.integer)) or periods < 1:
        raise DataError(f"periods must be a whole number >= 1, got {periods!r}")
    return int(periods)
