"""What the analysis says about feedback: the test of :func:`arxid.feedback` on the estimation data,
and the notes the CLI, the report and the JSON carry (which estimators stay consistent, what to do)."""

from __future__ import annotations

from ..checks.feedback import FeedbackTest, feedback
from ..data.iodata import IOData
from ..exceptions import DataError

__all__ = ["feedback_check", "feedback_notes", "reference_candidates"]

_REFERENCE_HINTS = ("setpoint", "_sp", "sp_", "ref", "command", "target")


def reference_candidates(data: IOData) -> list[str]:
    """Extra signals whose names look like a reference or setpoint (instrument candidates).

    Parameters
    ----------
    data : IOData

    Returns
    -------
    list of str
    """
    return [n for n in data.extra if any(h in n.lower() for h in _REFERENCE_HINTS)]


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


def feedback_notes(test: FeedbackTest | None, data: IOData) -> tuple[str, ...]:
    """One or two sentences for the reader: was there feedback, and what it means for the model.

    Parameters
    ----------
    test : FeedbackTest or None
    data : IOData
        The estimation data (for the names of candidate references).

    Returns
    -------
    tuple of str
    """
    if test is None:
        return ()
    if not test.feedback:
        return (test.sentence,)
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
