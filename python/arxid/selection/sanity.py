"""Step sanity checks: does a model's step response look like the physics you expect?

A structure can win a sweep on validation error and still be physically wrong (in a published
quadrotor study, Sarıoğlu & Kural, the best-ranked ARX(2,2,0) of a quadrotor roll axis answers a
step with an amplitude that "cannot be true"; the chosen ARX(2,1,8) grows with the sign of the
step). :func:`step_sanity` applies a positive and a negative step of typical input amplitude over
the validation horizon and judges what the step itself does: the deviation ``s(±a) − s(0)`` from the
response to no step at all (:func:`step_deviation`). A constant, a drift term or a logged signal held
at its mean is not an input: it moves the output by the same amount whichever way the input steps, so
it is taken out before any check (a model of raw data with ``effects=["const"]`` is judged as the
same model of de-meaned data without it). The checks flag:

=====================  ==================================================================
flag                   meaning
=====================  ==================================================================
``not-antisymmetric``  step(−a) is not −step(a) (input or output nonlinearities; an offset
                       or other term that is not an input cancels out)
``too-small``          peak |response| < ``small`` × measured output range
``too-large``          peak |response| > ``large`` × measured output range (not checked
                       for integrating expectations, whose response grows without bound)
``unstable``           a pole on or outside the unit circle while ``expect="stable"`` (a
                       sweep checks every plant it does not call integrating this way);
                       for an integrating plant, a pole significantly outside: more than
                       ``UNIT_ROOT_CRITICAL`` standard errors (:mod:`arxid.integrator`)
``near-integrator``    a plant that is not integrating, but a pole near z = 1 so slow (time
                       constant over ``RECORD_SHARE`` of the estimation record) that the
                       data cannot tell it from an integrator
``not-growing``        ``expect="integrating"`` / ``"double-integrating"`` but the response
                       at the end of the growth horizon is less than ``growth``
                       (``growth_double``) times the response at half of it; the growth
                       horizon ends where the response first leaves the measured output
                       range (:func:`growth_horizon`)
``sign-change``        an integrating response that turns to the opposite sign after it has
                       reached ``sign_tolerance`` of its peak
``wrong-sign``         the response to a positive step ends with the sign opposite to
                       ``sign`` (only when ``sign`` is given)
=====================  ==================================================================
"""

from __future__ import annotations

import math
import numbers
from dataclasses import asdict

import numpy as np

from .._base.order_statistics import quantiles
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from ..models.arx_model import ArxModel
from .integrator import LOW_FREQUENCY, RECORD_SHARE, UNIT_ROOT_CRITICAL, pole_excess

__all__ = [
    "SanityLimits",
    "StepSanity",
    "step_sanity",
    "step_deviation",
    "step_inputs",
    "growth_horizon",
    "EXPECTATIONS",
]

EXPECTATIONS = (None, "stable", "integrating", "double-integrating")


@record
class SanityLimits:
    """Thresholds of the step sanity checks (the defaults are the documented ones).

    Parameters
    ----------
    small : float
        A peak step response below ``small`` × the measured output range is implausibly small
        (default 0.02).
    large : float
        A peak above ``large`` × the output range is implausibly large (default 50); only checked
        when the plant is not expected to integrate.
    antisymmetry : float
        Largest accepted ``max|step(a) + step(−a)| / max|step(a)|`` (default 0.05).
    growth, growth_double : float
        Required ratio |s(h)| / |s(h/2)| for integrating (default 1.5; a pure integrator gives 2)
        and double-integrating plants (default 3; a double integrator gives 4), where ``h`` is the
        growth horizon: the sample at which the response first leaves the measured output range
        (at least ``2 * dead time + 8``, at most the whole response).
    sign_tolerance : float
        Excursions of the opposite sign smaller than this share of the peak are ignored (default 0.05).
    sign : {None, 1, -1}
        Expected sign of the response to a positive step (None: not checked).
    """

    small: float = 0.02
    large: float = 50.0
    antisymmetry: float = 0.05
    growth: float = 1.5
    growth_double: float = 3.0
    sign_tolerance: float = 0.05
    sign: int | None = None


@record
class StepSanity:
    """Verdict of the step sanity checks of one model.

    Attributes
    ----------
    structure : str
        ``ARX(na,nb,nk)`` name.
    flags : tuple of str
        Short flag codes (see :mod:`arxid.sanity`); empty when the model passes.
    reasons : tuple of str
        One sentence per flag.
    amplitude : float
        Peak |response| to the positive step (largest over the inputs; inf if it overflowed).
    output_range : float
        Measured output range (1st to 99th percentile of the validation output).
    input_amplitude : tuple of float
        Step amplitude used per input (standard deviation of the measured input).
    horizon : int
        Length of the step responses in samples.
    expect : str or None
    """

    structure: str
    flags: tuple[str, ...]
    reasons: tuple[str, ...]
    amplitude: float
    output_range: float
    input_amplitude: tuple[float, ...]
    horizon: int
    expect: str | None

    @property
    def ok(self) -> bool:
        """True when no check flagged the model."""
        return not self.flags

    def __str__(self) -> str:
        head = f"{self.structure}: step sanity " + ("ok" if self.ok else "FLAGGED")
        lines = [
            head + f" (peak {self.amplitude:.4g} vs output range {self.output_range:.4g}, "
            f"{self.horizon} samples, expect={self.expect})"
        ]
        lines += [f"  - {r}" for r in self.reasons]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """The verdict as a JSON-ready dict.

        Returns
        -------
        dict
            The fields of the verdict and ``ok``.
        """
        d = asdict(self)
        d["ok"] = self.ok
        return d

    def to_json(self) -> str:
        """The verdict as JSON.

        Returns
        -------
        str
            :meth:`to_dict` serialised.
        """
        import json

        return json.dumps(self.to_dict())


def typical_amplitudes(data: IOData) -> np.ndarray:
    """Typical step amplitude per input.

    Parameters
    ----------
    data : IOData
        Measured data.

    Returns
    -------
    ndarray of shape (n_inputs,)
        The standard deviation of each measured input (its largest absolute value when it is
        constant; 1 when it is zero).
    """
    u = data.u
    amp = np.nanstd(u, axis=0)
    flat = ~(amp > 0)
    if flat.any():
        amp[flat] = np.nanmax(np.abs(u[:, flat]), axis=0)
    return np.where(amp > 0, amp, 1.0)


def operating_inputs(model, data: IOData) -> np.ndarray:
    """Where each input rests before its step: zero, or the measured mean for an input the model
    feeds through a shape (``through(u^2)``): a static nonlinearity is stepped about the operating
    point, inside the range where its law holds (a power law is not defined below zero).

    Parameters
    ----------
    model : ArxModel
    data : IOData

    Returns
    -------
    ndarray of shape (n_inputs,)
    """
    at = np.zeros(data.n_inputs)
    layout = getattr(model, "layout_", None)
    labels = list(layout.column_labels) if layout is not None else []
    for i in range(data.n_inputs):
        if i < len(labels) and labels[i].startswith("through("):
            at[i] = float(np.nanmean(data.u[:, i]))
    return at


def output_range(data: IOData) -> float:
    """Measured output range, 99th minus 1st percentile (robust to a few spikes).

    Parameters
    ----------
    data : IOData
        Measured data.

    Returns
    -------
    float
        NaN when the output has no finite sample.
    """
    y = data.y[np.isfinite(data.y)]
    if y.size == 0:
        return math.nan
    lo, hi = quantiles(y, np.array([1, 99]) / 100)  # np.percentile(y, [1, 99])
    return float(hi - lo)


def growth_horizon(response: np.ndarray, out_range: float) -> int:
    """Samples over which an integrating step response is judged.

    Until the response first leaves the measured output range (beyond it the data say nothing, and
    an estimated integrator's pole a hair inside the unit circle levels the response off over a
    long record), but at least ``2 * dead time + 8`` samples, and at most the whole response.

    Parameters
    ----------
    response : ndarray of shape (n,)
        Step response.
    out_range : float
        Measured output range (:func:`output_range`).

    Returns
    -------
    int
        The horizon in samples, between 1 and ``n``.
    """
    n = len(response)
    moving = np.flatnonzero(response != 0)
    if not moving.size or not out_range > 0:
        return n
    out = np.flatnonzero(np.abs(response) >= out_range)
    h = int(out[0]) + 1 if out.size else n
    return int(min(n, max(h, 2 * int(moving[0]) + 8)))


def check_responses(
    structure: str,
    positive: list[np.ndarray],
    negative: list[np.ndarray],
    poles: np.ndarray,
    *,
    out_range: float,
    amplitudes,
    expect: str | None,
    limits: SanityLimits,
    pole_excess: float | None = None,
    record: int | None = None,
) -> StepSanity:
    """Apply the checks to given step responses (one positive and one negative per input).

    Parameters
    ----------
    structure : str
        Name of the model, for the verdict.
    positive, negative : list of ndarray
        Responses to the positive and the negative step, one per input, of equal length, as
        deviations from the response to no step (:func:`step_deviation`): what terms that are not
        inputs contribute is already taken out.
    poles : ndarray
        Poles of the model.
    out_range : float
        Measured output range (:func:`output_range`).
    amplitudes : sequence of float
        Step amplitude of each input.
    expect : {None, "stable", "integrating", "double-integrating"}
    limits : SanityLimits
    pole_excess : float, optional
        Standard errors by which the largest pole lies outside the unit circle
        (:func:`arxid.integrator.pole_excess`); for integrating expectations, above
        ``UNIT_ROOT_CRITICAL`` flags ``unstable``.
    record : int, optional
        Estimation rows; with ``expect="stable"``, a low-frequency pole whose time constant exceeds
        ``RECORD_SHARE`` of them flags ``near-integrator``.

    Returns
    -------
    StepSanity
    """
    if expect not in EXPECTATIONS:
        raise ArxidError(f"expect must be one of {EXPECTATIONS}, got {expect!r}")
    found: dict[str, str] = {}  # flag -> its first reason, in the order the flags were raised
    peak_all = 0.0
    horizon = 0
    with np.errstate(all="ignore"):
        for i, (pos, neg) in enumerate(zip(positive, negative, strict=True)):
            horizon = len(pos)
            label = f"input {i + 1}" if len(positive) > 1 else "the input"
            peak, flags = _input_flags(pos, neg, label, out_range=out_range, expect=expect, limits=limits)
            peak_all = max(peak_all, peak)
            for code, why in flags:
                found.setdefault(code, why)
    unstable = _stability_flag(poles, expect, pole_excess)
    if unstable:
        found.setdefault("unstable", unstable)
    elif expect == "stable" and record:
        slow = _slow_pole_flag(poles, record)
        if slow:
            found.setdefault("near-integrator", slow)
    return StepSanity(
        structure,
        tuple(found),
        tuple(found.values()),
        peak_all,
        float(out_range),
        tuple(float(a) for a in amplitudes),
        int(horizon),
        expect,
    )


def _stability_flag(poles: np.ndarray, expect: str | None, excess: float | None) -> str | None:
    """Reason for the ``unstable`` flag, or None."""
    if not poles.size:
        return None
    mag = float(np.max(np.abs(poles)))
    if expect == "stable" and mag >= 1.0:
        return (
            f"a pole at |z| = {mag:.5f} (on or outside the unit circle): the model is unstable, and the plant is "
            f"not integrating"
        )
    if expect in ("integrating", "double-integrating") and mag > 1.0 and excess is not None:
        if excess > UNIT_ROOT_CRITICAL:
            return (
                f"a pole at |z| = {mag:.5f} lies {excess:.1f} standard errors outside the unit circle (more than "
                f"{UNIT_ROOT_CRITICAL}): unstable beyond an integrator"
            )
    return None


def _slow_pole_flag(poles: np.ndarray, record: int) -> str | None:
    """Reason for ``near-integrator``: the slowest low-frequency pole outlasts the record."""
    poles = poles.astype(complex)
    with np.errstate(divide="ignore"):
        low = poles[np.abs(np.log(poles)) < LOW_FREQUENCY]
    if not low.size:
        return None
    mag = float(np.abs(low).max())
    tau = -1.0 / np.log(mag)
    if tau <= RECORD_SHARE * record:
        return None
    return (
        f"a pole at |z| = {mag:.5f} has a time constant of {tau:.4g} samples, more than {RECORD_SHARE:g} of the "
        f"{record} estimation samples: the data cannot tell it from an integrator, and the plant is not integrating"
    )


def _input_flags(
    pos: np.ndarray, neg: np.ndarray, label: str, *, out_range: float, expect: str | None, limits: SanityLimits
) -> tuple[float, list[tuple[str, str]]]:
    """Peak |response| to the positive step on one input (inf if it overflowed) and the
    ``(flag, reason)`` pairs of that input, in check order."""
    integrating = expect in ("integrating", "double-integrating")
    flags: list[tuple[str, str]] = []
    finite = np.isfinite(pos).all() and np.isfinite(neg).all()
    peak = float(np.max(np.abs(pos))) if finite else math.inf
    if finite and peak > 0:
        mismatch = float(np.max(np.abs(pos + neg))) / peak
        if mismatch > limits.antisymmetry:
            flags.append(
                (
                    "not-antisymmetric",
                    f"the responses to +/- steps on {label} differ by {100 * mismatch:.0f}% of the "
                    f"peak (limit {100 * limits.antisymmetry:.0f}%): offset or nonlinearity",
                )
            )
    if out_range > 0:
        if peak < limits.small * out_range:
            flags.append(
                (
                    "too-small",
                    f"step amplitude {peak:.3g} on {label} is implausibly small against the measured "
                    f"output range {out_range:.3g} (limit {limits.small:g} x range)",
                )
            )
        if not integrating and peak > limits.large * out_range:
            flags.append(
                (
                    "too-large",
                    f"step amplitude {peak:.3g} on {label} is implausibly large against the measured "
                    f"output range {out_range:.3g} (limit {limits.large:g} x range)",
                )
            )
    if not finite:
        end = math.inf
        sign_end = float(np.sign(pos[np.isfinite(pos)][-1])) if np.isfinite(pos).any() else 0.0
    else:
        end = abs(float(pos[-1]))
        sign_end = float(np.sign(pos[-1]))
    if integrating and len(pos) >= 4:
        flags += _growth_flags(
            pos, label, finite=finite, peak=peak, end=end, out_range=out_range, expect=expect, limits=limits
        )
    if limits.sign is not None and sign_end != 0 and sign_end != np.sign(limits.sign):
        flags.append(
            (
                "wrong-sign",
                f"a positive step on {label} ends {'negative' if sign_end < 0 else 'positive'}, "
                f"the expected sign is {'+' if limits.sign > 0 else '-'}",
            )
        )
    return peak, flags


def _growth_flags(
    pos: np.ndarray,
    label: str,
    *,
    finite: bool,
    peak: float,
    end: float,
    out_range: float,
    expect: str | None,
    limits: SanityLimits,
) -> list[tuple[str, str]]:
    """``not-growing`` and ``sign-change`` of an integrating plant's response to a positive step."""
    flags: list[tuple[str, str]] = []
    h = growth_horizon(pos, out_range) if finite else len(pos)
    g_end = abs(float(pos[h - 1])) if finite else end
    mid = abs(float(pos[h // 2]))
    need = limits.growth if expect == "integrating" else limits.growth_double
    if not (g_end >= need * mid) or g_end == 0:
        flags.append(
            (
                "not-growing",
                f"expect={expect!r} but the step response on {label} is not growing "
                f"(|s({h})| = {g_end:.3g}, |s({h // 2})| = {mid:.3g}, need x{need:g})",
            )
        )
    if finite and peak > 0:
        big = np.flatnonzero(np.abs(pos) >= limits.sign_tolerance * peak)
        if big.size:
            first_sign = np.sign(pos[big[0]])
            after = pos[big[0] :]
            if np.any(first_sign * after < -limits.sign_tolerance * peak):
                flags.append(
                    (
                        "sign-change",
                        f"the step response on {label} changes sign, which "
                        f"{'an' if expect == 'integrating' else 'a'} {expect} plant rules out",
                    )
                )
    return flags


def step_inputs(data: IOData, horizon: int) -> dict[str, np.ndarray]:
    """The extra signals a step response holds constant: each at its mean over ``data``.

    Parameters
    ----------
    data : IOData
        Measured data.
    horizon : int
        Samples of the step response.

    Returns
    -------
    dict of str to ndarray of shape (horizon,)
        One constant series per extra signal of ``data``.
    """
    return {k: np.full(int(horizon), float(np.nanmean(v))) for k, v in data.extra.items()}


def _simulate(model, u: np.ndarray, extra: dict[str, np.ndarray] | None) -> np.ndarray:
    """Free run of ``model`` from rest (an ARX model takes the extra signals its effects need)."""
    with np.errstate(all="ignore"):
        if extra is None or not isinstance(model, ArxModel):
            return np.asarray(model.simulate(u), dtype=float)
        return np.asarray(model.simulate(u, extra=extra), dtype=float)


def step_deviation(
    model, n_samples: int, amplitude: float = 1.0, input: int = 0, *, extra: dict[str, np.ndarray] | None = None
) -> np.ndarray:
    """What a step does: the response to a step of ``amplitude`` on ``input`` minus the response to
    no step, ``s(a) − s(0)``, both from rest with the same extra signals.

    A constant, a drift (``time``) or a logged signal held constant is not an input: it moves the
    output the same way whether the input steps up, down or not at all. Taking ``s(0)`` out leaves
    the input's own effect, so for a model linear in its inputs ``step_deviation(m, n, -a)`` is
    exactly ``-step_deviation(m, n, a)``, offset or not; input terms such as ``u1^2`` or
    ``abs(u1)`` keep their asymmetry. For a linear model without effects it is the step response.

    Parameters
    ----------
    model : ArxModel or PolynomialModel
        A fitted model.
    n_samples : int
        Samples of the response.
    amplitude : float
        Step height in the input's units.
    input : int
        Index of the input that steps.
    extra : mapping of str to ndarray of shape (n_samples,), optional
        Extra signals an ARX model's effects need (:func:`step_inputs` holds each at its mean);
        other model classes compute their inputs from ``u`` and ignore it.

    Returns
    -------
    ndarray of shape (n_samples,)
    """
    n, m = int(n_samples), len(model.input_names)
    if isinstance(input, bool) or not isinstance(input, numbers.Integral) or not 0 <= int(input) < m:
        raise DataError(f"input {input!r} does not exist: the model has {m} input(s), numbered 0 to {m - 1}")
    u = np.zeros((n, m))
    base = _simulate(model, u, extra)
    u[:, int(input)] = amplitude
    with np.errstate(all="ignore"):
        return _simulate(model, u, extra) - base


def step_sanity(
    model, data: IOData, expect: str | None = None, limits: SanityLimits | None = None, horizon: int | None = None
) -> StepSanity:
    """Step sanity checks of a fitted :class:`~arxid.ArxModel` against measured ``data``.

    Each input steps up and down by its typical amplitude (:func:`typical_amplitudes`), the other
    inputs at zero and the extra signals at their means; the checks judge the deviations from the
    response to no step (:func:`step_deviation`), so a constant or other term that is not an input
    never reads as an asymmetry, a size or a growth.

    Parameters
    ----------
    model : ArxModel
        A fitted model.
    data : IOData
        Measured data (normally the validation data) giving the typical input amplitude, the output
        range and the horizon.
    expect : {None, "stable", "integrating", "double-integrating"}
        What the physics says about the plant.
    limits : SanityLimits, optional
        Thresholds (defaults documented in :class:`SanityLimits`).
    horizon : int, optional
        Samples of the step responses (default: the length of ``data``).

    Returns
    -------
    StepSanity
    """
    limits = limits or SanityLimits()
    horizon = int(horizon or data.n_samples)
    amps = typical_amplitudes(data)
    extra = step_inputs(data, horizon)
    pos, neg = [], []
    m = data.n_inputs
    at = operating_inputs(model, data)
    base = _simulate(model, np.tile(at, (horizon, 1)), extra)
    for i in range(m):
        if model.nb_[i] == 0:
            continue
        u = np.tile(at, (horizon, 1))
        with np.errstate(all="ignore"):
            u[:, i] = at[i] + amps[i]
            pos.append(_simulate(model, u, extra) - base)
            u[:, i] = at[i] - amps[i]
            neg.append(_simulate(model, u, extra) - base)
    poles = model.discrete_poles()
    excess = None
    if poles.size and np.max(np.abs(poles)) > 1.0 and expect in ("integrating", "double-integrating"):
        excess = pole_excess(model.parameters_, model.covariance_, model.na_)[1]
    return check_responses(
        model.structure_name(),
        pos,
        neg,
        poles,
        out_range=output_range(data),
        amplitudes=amps,
        expect=expect,
        limits=limits,
        pole_excess=excess,
        record=model.n_rows_,
    )
