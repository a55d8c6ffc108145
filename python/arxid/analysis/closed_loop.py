"""What the analysis does once the data are known to be closed loop.

The feedback test of :func:`arxid.feedback` runs on the estimation data, and its verdict steers
the chain (Forssell & Ljung, "Closed-loop identification revisited", Automatica 35, 1999):

* **no feedback**: the open-loop chain (least-squares sweep, free-run validation);
* **feedback and a logged reference** (named with ``reference=``, or recognised from its name:
  ``setpoint``, ``_sp``, ``ref``, ``des`` ...): every structure is fitted by instrumental variables
  whose instruments come from the reference (consistent for any noise colour), and judged by the
  free run of the plant on the reference-driven part of the input (the two-stage input ``û``, see
  :mod:`arxid.models.two_stage`), which the noise did not pass through. The chosen structure is
  refitted by IV4 (:func:`arxid.iv`); the diagnosis judges its candidates on the two-stage
  validation data;
* **feedback, no reference**: the direct method, a Box–Jenkins model fitted by prediction error on
  the measured signals, consistent when its noise model can describe the noise. The validation can
  only use the measured input, which carries the noise fed back: the plant may still be biased.

In closed loop the default grid starts the delay at one sample (a controller that reads the output
and writes the input within one sample makes a direct feedthrough indistinguishable from the
loop), and the operating point (the estimation record's means of the output and inputs) is part of
every structure, so that the offsets of a raw log are not left to be found later.

Loop signals, the reference and any logged signal the controller computes from the output (PID
terms, motor and actuator commands), are never proposed as extra inputs: such a signal explains the
error because the loop closes through it, not because the plant misses an effect.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from dataclasses import field, replace
from typing import Any

import numpy as np

from .._base.records import record
from ..checks.feedback import FeedbackTest, feedback
from ..data.iodata import IOData
from ..exceptions import ArxidError, DataError
from ..models.iv import instrument_names, iv

__all__ = [
    "ClosedLoopMethod",
    "feedback_check",
    "beyond_the_sample",
    "feedback_notes",
    "reference_candidates",
    "reference_names",
    "still_references",
    "loop_signal_names",
    "closed_loop_grid",
    "operating_point",
    "remove_operating_point",
    "iv_refit",
    "direct_refit",
    "NOISE_ORDERS",
]

# Words of a reference or setpoint in the names firmware and users give them.
_REFERENCE = re.compile(r"(setpoint|_sp(_|$)|(^|_)sp_|ref|command|target|(^|_)des|des($|_)|rdes|pdes|ydes)", re.I)
# Signals a controller computes from the output: PID terms, its outputs to motors and actuators.
_CONTROLLER = re.compile(
    r"(axis[pidf](_|$)|pid|(^|_)[pidf]term|rout$|pout$|yout$|(^|_)out(_|$)|actuator|motor|servo|rcou|control)", re.I
)

#: Level of the test beyond the sample that switches to the direct method without a reference. An
#: open-loop plant with a static nonlinearity driven by a coloured input leaves a nonlinear residual
#: that the later inputs partly predict (the Silverbox circuit: p = 5e-4), while rate loops give
#: p-values below 1e-12: the switch asks for evidence far beyond the test's 0.1 %.
DIRECT_SWITCH_LEVEL = 1e-6

#: Orders (nc, nd) of the Box–Jenkins noise model of the direct method: a noise spectrum with two
#: resonances or slopes, enough for vibration and gusts seen by a gyro.
NOISE_ORDERS = (2, 2)


def reference_candidates(data: IOData) -> list[str]:
    """Extra signals whose names look like a reference or setpoint (instrument candidates).

    Parameters
    ----------
    data : IOData

    Returns
    -------
    list of str
    """
    return [n for n in data.extra if _REFERENCE.search(n) and not _CONTROLLER.search(n)]


def reference_names(
    data: IOData, reference: str | Sequence[str] | None, validation: IOData | None = None
) -> tuple[str, ...]:
    """The references of the analysis: those named (checked), else those recognised by name.

    References that do not move (in the estimation or the validation data) are left out (see
    :func:`still_references`). Of the rest of those recognised, the analysis keeps as many as
    there are inputs, those the output follows most closely (largest correlation: a loop makes its
    output track its reference), so that a roll analysis takes the roll setpoint, not the
    throttle's.

    Parameters
    ----------
    data : IOData
        The estimation data.
    reference : None, str or sequence of str
    validation : IOData, optional

    Returns
    -------
    tuple of str

    Raises
    ------
    DataError
        When a named reference is not an extra signal of the data, or is the output or an input.
    """
    named = reference is not None
    candidates = instrument_names(data, reference) if named else tuple(reference_candidates(data))
    moving = [n for n in candidates if n not in still_references(data, validation, candidates)]
    if named or len(moving) <= data.n_inputs:
        return tuple(moving)
    tracked = sorted(moving, key=lambda n: -_correlation(data.extra[n], data.y))
    return tuple(tracked[: data.n_inputs])


def still_references(data: IOData, validation: IOData | None, references: Sequence[str]) -> tuple[str, ...]:
    """The references that do not move in the estimation or the validation record (they excite
    nothing, so they cannot be instruments).

    Parameters
    ----------
    data, validation : IOData
    references : sequence of str

    Returns
    -------
    tuple of str
    """
    records = [data] if validation is None else [data, validation]
    return tuple(n for n in references if not all(_moves(r.extra.get(n)) for r in records))


def _moves(x: np.ndarray | None) -> bool:
    if x is None:
        return False
    finite = x[np.isfinite(x)]
    return finite.size > 1 and float(np.ptp(finite)) > 0


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 3 or np.ptp(a[ok]) == 0 or np.ptp(b[ok]) == 0:
        return 0.0
    return abs(float(np.corrcoef(a[ok], b[ok])[0, 1]))


def loop_signal_names(data: IOData, references: Sequence[str]) -> tuple[str, ...]:
    """The extra signals that belong to the loop: the references and the controller's signals.

    Parameters
    ----------
    data : IOData
    references : sequence of str

    Returns
    -------
    tuple of str
    """
    named = set(references) | set(reference_candidates(data))
    return tuple(n for n in data.extra if n in named or _CONTROLLER.search(n))


def feedback_check(data: IOData) -> FeedbackTest | None:
    """:func:`arxid.feedback` on ``data``, or None when the data are too short for it.

    Parameters
    ----------
    data : IOData

    Returns
    -------
    FeedbackTest or None
    """
    try:
        return feedback(data)
    except DataError:
        return None


def beyond_the_sample(data: IOData, test: FeedbackTest | None) -> bool:
    """Whether feedback shows in the later inputs, not only within the sample.

    The default test counts a dependence of ``u(t)`` on ``y(t)`` as feedback (MATLAB's ``fbck0``).
    A plant with a direct feedthrough (an accelerometer answering a torque in the same sample)
    shows the same dependence, so without a logged setpoint the chain changes its method only when
    the later inputs ``u(t+1), u(t+2), ...`` predict the output too (``direct=True``, MATLAB's
    ``fbck``), at the level :data:`DIRECT_SWITCH_LEVEL`. With a setpoint the loop is known and the
    default verdict is enough.

    Parameters
    ----------
    data : IOData
        The estimation data.
    test : FeedbackTest or None
        The default test of ``data``.

    Returns
    -------
    bool
    """
    if test is None or not test.feedback:
        return False
    try:
        return feedback(data, direct=True, alpha=DIRECT_SWITCH_LEVEL).feedback
    except DataError:
        return False


def closed_loop_grid(grid: Mapping[str, Any]) -> dict[str, tuple[int, ...]]:
    """The default grid of a closed-loop analysis: the delays from one sample on.

    Parameters
    ----------
    grid : mapping with keys na, nb, nk (each a tuple of int)

    Returns
    -------
    dict
    """
    nk = tuple(k for k in grid["nk"] if k >= 1) or (1,)
    return {"na": tuple(grid["na"]), "nb": tuple(grid["nb"]), "nk": nk}


def operating_point(data: IOData) -> dict[str, float]:
    """The means of the output and of each input over the samples present (the operating point).

    Parameters
    ----------
    data : IOData

    Returns
    -------
    dict of str to float
    """
    point = {data.output_name: float(np.nanmean(data.y))}
    point.update({n: float(np.nanmean(data.u[:, i])) for i, n in enumerate(data.input_names)})
    return point


def remove_operating_point(data: IOData, point: Mapping[str, float]) -> IOData:
    """``data`` with the operating point subtracted from its output and inputs.

    Parameters
    ----------
    data : IOData
    point : mapping of str to float
        As :func:`operating_point` returns it.

    Returns
    -------
    IOData
    """
    offsets = np.array([point[n] for n in data.input_names])
    return replace(data, y=data.y - point[data.output_name], u=data.u - offsets)


def iv_refit(model: Any, data: IOData, references: Sequence[str], validation: IOData, horizon: int | None) -> Any:
    """The chosen structure refitted by IV4 with the references as instruments, unless the refit
    validates worse than the basic IV fit (the sweep's) on the closed-loop criterion, or cannot
    determine every parameter (then the basic IV fit).

    Parameters
    ----------
    model : ArxModel
        The structure the sweep chose, as the sweep fitted it.
    data : IOData
        Estimation data.
    references : sequence of str
    validation : IOData
        The two-stage validation data.
    horizon : int or None
        The validation measure.

    Returns
    -------
    ArxModel
    """
    from ..checks.comparison import error_rms

    orders = (model.na, list(model.nb_), list(model.nk_))
    basic = iv(data, *orders, instruments=list(references), iterations=0)
    try:
        refit = iv(data, *orders, instruments=list(references))
    except ArxidError:
        return basic
    new, old = error_rms(refit, validation, horizon), error_rms(basic, validation, horizon)
    return refit if np.isfinite(new) and not new > old else basic


def direct_refit(model: Any, data: IOData) -> Any:
    """The chosen structure refitted as a Box–Jenkins model by prediction error (the direct
    method), its plant poles those of the ARX structure, its noise model of :data:`NOISE_ORDERS`.

    Parameters
    ----------
    model : ArxModel
    data : IOData

    Returns
    -------
    PolynomialModel
    """
    from ..models.pem import bj

    nc, nd = NOISE_ORDERS
    nf = [model.na] * data.n_inputs
    return bj(data, list(model.nb_), nc, nd, nf, list(model.nk_))


@record
class ClosedLoopMethod:
    """How the plant was identified, given the feedback verdict, and why.

    Attributes
    ----------
    key : {"open-loop", "iv-reference", "direct"}
    method : str
        The method in words.
    reason : str
        Why this method.
    criterion : str
        The validation criterion every validation error of the analysis uses.
    references : tuple of str
        The logged references used (empty without).
    loop_signals : tuple of str
        Logged signals never proposed as extra inputs (the references and the controller's).
    operating_point : dict of str to float
        The means removed from the output and the inputs (empty in open loop).
    loop_closing : tuple of str
        Loop signals that would "explain" the error if taken as inputs, with what they would
        remove: the loop closing, not a missing effect.
    """

    key: str
    method: str
    reason: str
    criterion: str
    references: tuple[str, ...] = ()
    loop_signals: tuple[str, ...] = ()
    operating_point: dict[str, float] = field(default_factory=dict)
    loop_closing: tuple[str, ...] = ()

    @property
    def closed(self) -> bool:
        """Whether the chain ran a closed-loop method."""
        return self.key != "open-loop"

    def sentences(self) -> tuple[str, ...]:
        """What the reader should know, in plain sentences.

        Returns
        -------
        tuple of str
        """
        if not self.closed:
            return ()
        out = [f"Closed-loop method: {self.method}. {self.reason}", f"Validation criterion: {self.criterion}."]
        if self.operating_point:
            point = ", ".join(f"{k} {v:.4g}" for k, v in self.operating_point.items())
            out.append(
                f"The operating point is part of the model: the estimation record's means ({point}) were "
                "removed from the output and inputs of both records before fitting."
            )
        out += list(self.loop_closing)
        return tuple(out)

    def to_dict(self) -> dict:
        """JSON-ready: key, method, reason, criterion, references, loop_signals, operating_point,
        loop_closing.

        Returns
        -------
        dict
        """
        return {
            "key": self.key,
            "method": self.method,
            "reason": self.reason,
            "criterion": self.criterion,
            "references": list(self.references),
            "loop_signals": list(self.loop_signals),
            "operating_point": dict(self.operating_point),
            "loop_closing": list(self.loop_closing),
        }


OPEN_LOOP = ClosedLoopMethod(
    "open-loop",
    "least squares (open loop)",
    "No feedback was found.",
    "free-run simulation on the measured validation input",
)


#: The open-loop chain on data the feedback test flags, without a setpoint: the evidence alone does
#: not change the method.
WEAK_EVIDENCE = ClosedLoopMethod(
    "open-loop",
    "least squares (open loop)",
    "Without a logged setpoint this is not enough to change the method: a plant with a direct feedthrough "
    "shows the same dependence within the sample, and a nonlinear plant driven by a coloured input can mimic "
    "it in the later inputs. The open-loop chain was kept; if a controller closes the loop here, give its "
    "setpoint with reference=<signal>.",
    OPEN_LOOP.criterion,
)

#: Given ARX orders on data the feedback test flags, without a setpoint: the structure is kept.
GIVEN_ORDERS = ClosedLoopMethod(
    "open-loop",
    "least squares (the given ARX orders)",
    "The ARX orders were given, so they were fitted by least squares. In closed loop the least-squares (ARX) and "
    "output-error models may be biased (the controller feeds the output noise back into the input); give the "
    "setpoint with reference=<signal> to fit the same orders by instrumental variables, which stay consistent.",
    OPEN_LOOP.criterion,
)


def iv_method(references: Sequence[str], loop: Sequence[str], point: Mapping[str, float]) -> ClosedLoopMethod:
    """The method of closed-loop data with a logged reference.

    Parameters
    ----------
    references, loop : sequence of str
    point : mapping of str to float

    Returns
    -------
    ClosedLoopMethod
    """
    refs = ", ".join(references)
    return ClosedLoopMethod(
        "iv-reference",
        f"instrumental variables with the reference {refs} as instrument, structures judged on the two-stage input",
        f"The data were logged in closed loop and the reference {refs} is logged: it is the one signal the "
        "output noise does not reach, so instruments built from it keep the plant estimate consistent, where "
        "least squares and output error learn part of the controller.",
        "free-run simulation of the plant on the reference-driven part of the validation input (the two-stage "
        "input û, the input projected on the reference), against the measured output; the noise the controller "
        "feeds back into the input does not pass through û",
        tuple(references),
        tuple(loop),
        dict(point),
    )


def direct_method(loop: Sequence[str], point: Mapping[str, float], still: Sequence[str] = ()) -> ClosedLoopMethod:
    """The method of closed-loop data without a usable reference.

    Parameters
    ----------
    loop : sequence of str
    point : mapping of str to float
    still : sequence of str
        Logged references that do not move (they excite nothing, so they cannot be instruments).

    Returns
    -------
    ClosedLoopMethod
    """
    nc, nd = NOISE_ORDERS
    return ClosedLoopMethod(
        "direct",
        f"direct prediction-error method, Box-Jenkins with a noise model of orders nc={nc}, nd={nd}",
        (
            f"The data were logged in closed loop and the setpoint {', '.join(still)} does not move in the "
            "estimation or validation record, so it excites nothing and cannot be an instrument. "
            if still
            else "The data were logged in closed loop and no reference is logged (name the setpoint with "
            "reference=<signal> to identify the plant by instrumental variables built from it). "
        )
        + "The direct method is "
        "consistent only when its noise model can describe the real noise; otherwise the controller's feedback of "
        "the noise biases it, so the plant estimate may be biased: treat its gain and poles with care.",
        "free-run simulation on the measured validation input, which carries the noise fed back by the "
        "controller: it can favour a biased model",
        (),
        tuple(loop),
        dict(point),
    )


def feedback_notes(test: FeedbackTest | None, data: IOData, method: ClosedLoopMethod | None = None) -> tuple[str, ...]:
    """The feedback test's sentence, and what it meant for the analysis.

    Parameters
    ----------
    test : FeedbackTest or None
    data : IOData
        The estimation data (for the names of candidate references).
    method : ClosedLoopMethod, optional
        The method the analysis used (None: the model was given, so no method was chosen).

    Returns
    -------
    tuple of str
    """
    if test is None:
        return ()
    if not test.feedback:
        return (test.sentence,)
    if method is not None and method.closed:
        return (test.sentence, *method.sentences())
    if method is not None:  # the open-loop chain ran on data the test flags: the method says why
        return (test.sentence, method.reason)
    refs = reference_candidates(data)
    if refs:
        todo = (
            f"Refit with the measured reference as instrument: arxid.iv(data, na, nb, nk, instruments={refs[0]!r}) "
            f"(or sweep(..., method='iv', instruments={refs[0]!r}))."
        )
    else:
        todo = (
            "Log the reference or setpoint the controller tracks and refit with it as instrument "
            "(arxid.iv(..., instruments='<setpoint>')), or fit BJ/ARMAX with a noise model that fits."
        )
    return (
        test.sentence,
        "In closed loop the least-squares (ARX) and output-error models above may be biased (the controller feeds "
        "the output noise back into the input); instrumental variables with a reference stay consistent. " + todo,
    )
