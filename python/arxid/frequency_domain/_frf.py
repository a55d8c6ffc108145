"""The frequency response from data, without a model: :func:`frf` (MATLAB's ``spa``, Welch's H1).

Both estimators form the cross-spectral matrix of the output, the inputs and (in closed loop) the
references, then solve it at each frequency. With an instrument z (the inputs in open loop, the
references in closed loop):

* Ĥ = S_zu⁻¹ S_zy (one input: S_uy / S_uu, the H1 estimate; with a reference: S_ry / S_ru);
* the unexplained part v = y − Σ Ĥ_i u_i has the spectrum S_vv = [1, −Ĥ]ᴴ S_[y,u] [1, −Ĥ];
* var Ĥ_i = S_vv [S_zu⁻¹ S_zz S_zu⁻ᴴ]_ii / n (Bendat & Piersol; n the effective averages);
* γ² = E / (E + S_vv), with E = S_yz S_zz⁻¹ S_zy the output power z explains.

In open loop γ² is the ordinary (multiple) coherence and var Ĥ = |Ĥ|² (1 − γ²) / (γ² n). With a
reference, γ² is the value for which the same formula gives the variance of S_ry / S_ru: it combines
the coherences of r→y and r→u, and their correlation (the feedback brings the same noise into y and u).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .._base.limits import check_order
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError, IdentifiabilityError
from ._blackman_tukey import default_lag_width, lag_spectra
from ._response import FrequencyResponse
from ._spectra import default_segment_length, effective_averages, finite_runs, spectra

__all__ = ["frf", "METHODS"]

METHODS = ("welch", "blackman-tukey")


def _references(data: IOData, reference: str | Sequence[str] | None) -> tuple[str, ...]:
    if reference is None:
        return ()
    names = (reference,) if isinstance(reference, str) else tuple(reference)
    if len(names) != data.n_inputs:
        raise DataError(
            f"a closed-loop frequency response needs one reference per input: {len(names)} given for "
            f"{data.n_inputs} inputs {list(data.input_names)}; pass reference=[...] with {data.n_inputs} names"
        )
    for name in names:
        data.signal(name)  # a DataError naming the signals when unknown
        if name in (data.output_name, "y") or name in data.input_names:
            raise DataError(
                f"the reference {name!r} is the output or an input; give the setpoint (an extra signal, "
                "e.g. IOData(..., extra={'setpoint': r})), which the feedback does not reach"
            )
    return names


def _check_confidence(confidence: float) -> float:
    c = float(confidence)
    if not 0.0 < c < 1.0:
        raise ArxidError(f"confidence must be between 0 and 1 (e.g. 0.99), got {confidence!r}")
    return c


def _check_excited(s: np.ndarray, rows: list[int], names: Sequence[str], what: str) -> None:
    for i, name in zip(rows, names):
        if not np.any(np.real(s[:, i, i]) > 1e-300):
            raise IdentifiabilityError(
                f"the {what} {name!r} is constant where the data are finite: it excites nothing, so no "
                "frequency response can be estimated; use data where it moves",
                (name,),
            )


def _estimate(s: np.ndarray, m: int, z: list[int], n_avg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Ĥ, γ² and var Ĥ from the spectral matrix of [y, u_1..u_m, ...] with instrument rows ``z``."""
    u = list(range(1, m + 1))
    s_zu, s_zy, s_zz = s[:, z][:, :, u], s[:, z, 0], s[:, z][:, :, z]
    h = np.linalg.solve(s_zu, s_zy[..., None])[..., 0]
    a = np.concatenate([np.ones((len(h), 1)), -h], axis=1)
    s_yu = s[:, [0, *u]][:, :, [0, *u]]
    s_vv = np.maximum(np.real(np.einsum("fi,fij,fj->f", np.conj(a), s_yu, a)), 0.0)
    explained = np.maximum(np.real(np.einsum("fi,fij,fj->f", np.conj(s_zy), np.linalg.inv(s_zz), s_zy)), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        coherence = np.clip(np.nan_to_num(explained / (explained + s_vv)), 0.0, 1.0)
    inv = np.linalg.inv(s_zu)
    p = np.real(np.einsum("fij,fjk,flk->fil", inv, s_zz, np.conj(inv)).diagonal(axis1=1, axis2=2))
    return h, coherence, s_vv[:, None] * p / n_avg


def _welch(x: np.ndarray, data: IOData, segment_length: int | None) -> tuple[np.ndarray, np.ndarray, float, int]:
    finite = np.isfinite(x).all(axis=0)
    nseg = check_order("segment_length", segment_length) if segment_length is not None else 0
    if nseg == 0:
        nseg = default_segment_length(int(finite.sum()))
    if nseg < 8:
        raise ArxidError(f"segment_length must be at least 8 samples, got {segment_length!r}")
    runs = finite_runs(finite, data.segments, nseg)
    if not runs:
        raise DataError(
            f"frf needs a gap-free stretch of at least {nseg} samples (one Welch segment) inside one experiment; "
            "give longer data or a smaller segment_length"
        )
    freq, s, count = spectra(x, runs, data.ts, nseg)
    keep = freq > 0
    return freq[keep], s[keep], effective_averages(count), nseg


def _blackman_tukey(
    x: np.ndarray, data: IOData, lag_width: int | None, n_frequencies: int
) -> tuple[np.ndarray, np.ndarray, float, int]:
    finite = np.isfinite(x).all(axis=0)
    width = check_order("lag_width", lag_width) if lag_width is not None else default_lag_width(int(finite.sum()))
    if width < 2:
        raise DataError(
            f"the lag window's width M must be at least 2 (got {width}); Blackman–Tukey needs at least 20 "
            "finite samples (M = min(30, N/10)), or give lag_width"
        )
    runs = finite_runs(finite, data.segments, width + 1)
    if not runs:
        raise DataError(f"frf needs a gap-free stretch longer than the lag window ({width} samples)")
    nf = check_order("n_frequencies", n_frequencies)
    freq = np.arange(1, nf + 1) / nf * 0.5 / data.ts
    s, n_avg = lag_spectra(x, runs, data.ts, width, freq)
    return freq, s, n_avg, width


def frf(
    data: IOData,
    *,
    method: str = "welch",
    reference: str | Sequence[str] | None = None,
    segment_length: int | None = None,
    lag_width: int | None = None,
    n_frequencies: int = 128,
    confidence: float = 0.99,
) -> FrequencyResponse:
    """Frequency response from the inputs to the output, with its coherence and confidence band.

    Parameters
    ----------
    data : IOData
        Measured data. NaN gaps and several experiments are handled: Welch segments (and
        Blackman–Tukey's lagged products) lie inside one gap-free run of one experiment, so a
        segment that would hold a NaN is dropped.
    method : {"welch", "blackman-tukey"}
        ``"welch"`` (default): the H1 estimate S_uy / S_uu from Hann-windowed segments with 50 %
        overlap, each segment's mean removed (as ``scipy.signal.csd``). ``"blackman-tukey"``: MATLAB
        ``spa``, sample covariances up to lag M weighted by a Hann lag window, evaluated at
        ``n_frequencies`` frequencies.
    reference : str or sequence of str, optional
        Closed loop: the name of the reference (setpoint) signal, one per input, an extra signal of
        ``data``. The plant's response is then S_ry / S_ru (the feedback makes S_uy / S_uu biased
        towards minus the inverse of the controller where the noise dominates).
    segment_length : int, optional
        Welch: samples per segment (default: a power of two near N/16, 32 to 4096). Longer
        segments resolve finer frequencies but average fewer times.
    lag_width : int, optional
        Blackman–Tukey: width M of the lag window (default min(30, N/10), ``spa``'s documented
        rule). Larger M: finer resolution, more variance.
    n_frequencies : int
        Blackman–Tukey: frequencies k / n · f_Nyquist, k = 1..n (``spa``'s default 128).
    confidence : float
        Level of the band (default 0.99).

    Returns
    -------
    FrequencyResponse
        ``frequency`` [Hz], ``response`` (complex), ``magnitude_db``, ``phase_deg``, ``coherence``,
        ``magnitude_band_db``, ``phase_band_deg``, ``relative_error``; ``to_dict()``, ``plot``
        through :func:`arxid.plots.plot_bode`.

    Raises
    ------
    DataError
        When ``data`` is not an IOData, too short for one segment, or a reference is unknown or is
        the output or an input.
    IdentifiabilityError
        When an input (or a reference) is constant.

    Notes
    -----
    With instrument z (u in open loop, r in closed loop): Ĥ = S_zu⁻¹ S_zy and
    var Ĥ_i = S_vv [S_zu⁻¹ S_zz S_zu⁻ᴴ]_ii / n, with S_vv the spectrum of y − Σ Ĥ_i u_i; for one
    input in open loop this is Bendat & Piersol's normalised error of |Ĥ|,
    ε = √((1 − γ²) / (2 n γ²)). The band is the disc |H − Ĥ| ≤ r with
    r² = −ln(1 − confidence) · var Ĥ (a complex normal error). Welch's n is the number of
    segments divided by 1 + 2·0.167² (Welch 1967: the overlap of Hann segments); Blackman–Tukey's
    is N / Σ W(τ)². With several inputs, each response is the partial one (the others held) and
    γ² the multiple coherence.

    Examples
    --------
    >>> import numpy as np, arxid
    >>> from scipy.signal import lfilter, freqz
    >>> rng = np.random.default_rng(0)
    >>> u = rng.standard_normal(20000)
    >>> y = lfilter([0, 0.5], [1, -0.9], u) + 0.05 * rng.standard_normal(20000)
    >>> fr = arxid.frf(arxid.IOData(y, u, ts=0.01), segment_length=256)
    >>> _, g = freqz([0, 0.5], [1, -0.9], worN=fr.frequency, fs=100)
    >>> good = fr.coherence > 0.9
    >>> bool(np.abs(fr.magnitude_db[good, 0] - 20 * np.log10(np.abs(g[good]))).max() < 0.5)
    True
    """
    if not isinstance(data, IOData):
        raise DataError(f"frf needs an arxid.IOData, got {type(data).__name__}; build one with arxid.IOData(y, u, ts)")
    if method not in METHODS:
        raise ArxidError(f"method must be one of {METHODS}, got {method!r}")
    level = _check_confidence(confidence)
    refs = _references(data, reference)
    m = data.n_inputs
    x = np.vstack([data.y, data.u.T, *(data.signal(r) for r in refs)])
    if method == "welch":
        freq, s, n_avg, resolution = _welch(x, data, segment_length)
    else:
        freq, s, n_avg, resolution = _blackman_tukey(x, data, lag_width, n_frequencies)
    _check_excited(s, list(range(1, m + 1)), data.input_names, "input")
    z = list(range(m + 1, m + 1 + len(refs))) if refs else list(range(1, m + 1))
    if refs:
        _check_excited(s, z, refs, "reference")
    h, coherence, variance = _estimate(s, m, z, n_avg)
    return FrequencyResponse(
        frequency=freq,
        response=h,
        coherence=coherence,
        variance=variance,
        confidence=level,
        method=method,
        resolution=int(resolution),
        n_averages=float(n_avg),
        reference=refs,
        output_name=data.output_name,
        output_unit=data.output_unit,
        input_names=tuple(data.input_names),
        input_units=tuple(data.input_units),
        ts=data.ts,
        data=data,
    )
