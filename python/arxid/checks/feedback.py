"""Is there feedback from the output to the input? (MATLAB ``feedback`` / ``checkFeedback``.)

:func:`feedback` fits a high-order ARX model of the output on its own past and on the past *and
present* of every input, then adds the *later* samples of one input, ``u(t+1) ... u(t+lead)``
(and ``u(t)`` itself when the plant has no direct feedthrough, the default). In
open loop the output at ``t`` cannot be predicted better from inputs that come after it: those
extra coefficients are zero, and an F-test of them gives a uniform p-value. When a controller
computes the input from the measured output (closed loop), later inputs carry the output's noise
and the test rejects. This is Sims' (1972) causality test, the correlation of the residuals of a
high-order model with later inputs that Ljung (*System Identification*, 2nd ed., ch. 13) and
MATLAB's ``feedback`` use. By default a dependence at lag 0 (``u(t)`` on ``y(t)``) counts as
feedback (MATLAB's ``fbck0``): a controller that reads the gyro and writes the motors within one
sample acts at lag 0.
"""

from __future__ import annotations

import math
from dataclasses import field

import numpy as np

from .._base.formatting import json_safe
from .._base.nested import nested_from_factor
from .._base.probabilities import f_sf
from .._base.records import record
from ..data.iodata import IOData
from ..exceptions import DataError
from ..models.arguments import check_data
from ..models.lagged import lagged_factor

__all__ = ["FeedbackTest", "feedback"]

_CONSEQUENCES = (
    "On closed-loop data the input is correlated with the output noise: ARX and OE fitted to them are "
    "biased (ARX unless the noise really is 1/A(q) white noise). Consistent estimators are instrumental "
    "variables with a measured reference as instrument (arxid.iv(data, na, nb, nk, instruments=<setpoint "
    "signal>)) and prediction-error models with a correct noise model (BJ, ARMAX)."
)


@record
class FeedbackTest:
    """Result of :func:`feedback`.

    Attributes
    ----------
    p_value : float
        Probability of coefficients of later inputs this large (or larger) if there is no
        feedback; the smallest over the inputs tested, times their number (Bonferroni).
    feedback : bool
        ``p_value < alpha``.
    probability : float
        ``100 (1 - p_value)``: MATLAB's ``fbck``, the level in percent at which "no feedback" is
        rejected (values above 90 are usually read as feedback).
    p_values : dict of str to float
        The p-value of each input tested.
    statistic : dict of str to float
        The F statistic of each input.
    alpha : float
        Significance level.
    order : int
        Lags of the output and of each input in the high-order model.
    lead : int
        Later input samples tested.
    n_rows : int
        Regression rows used.
    sentence : str
        What the test found, in one plain sentence.
    consequences : str
        What feedback means for the estimators, and what to do (empty without feedback).
    """

    p_value: float
    feedback: bool
    probability: float
    p_values: dict[str, float] = field(default_factory=dict)
    statistic: dict[str, float] = field(default_factory=dict)
    alpha: float = 0.001
    order: int = 10
    lead: int = 10
    n_rows: int = 0
    sentence: str = ""
    consequences: str = ""

    def __str__(self) -> str:
        return self.sentence + (" " + self.consequences if self.consequences else "")

    def to_json(self) -> str:
        """The result as a JSON object.

        Returns
        -------
        str
        """
        import json

        fields = {k: getattr(self, k) for k in self.__dataclass_fields__}
        return json.dumps(json_safe(fields), allow_nan=False)  # NaN (no conclusion) becomes null


def _f_test(r: np.ndarray, n_rows: int, p_small: int) -> tuple[float, float, int, int]:
    """F statistic and p-value of the columns of R beyond the first ``p_small`` (output last)."""
    p = r.shape[1] - 1
    rss = nested_from_factor(r)[0]  # every prefix of the columns from the one factor
    rss_small, rss_big = float(rss[p_small]), float(rss[p])
    q = p - p_small
    dof = n_rows - p
    if rss_big <= 0 or dof <= 0:
        return math.nan, math.nan, q, dof
    f = max(rss_small - rss_big, 0.0) / q / (rss_big / dof)
    return f, float(f_sf(f, q, dof)), q, dof


def feedback(
    data: IOData, *, order: int = 10, lead: int = 10, alpha: float = 0.001, direct: bool = False
) -> FeedbackTest:
    """Test the data for feedback from the output to each input.

    Parameters
    ----------
    data : IOData
        Measured output and inputs (NaN gaps and several experiments allowed).
    order : int
        Lags of the output and of each input (from lag 0) in the high-order model, >= 1.
    lead : int
        Later samples of the tested input added to the model, >= 1.
    alpha : float
        Significance level of the decision (0.1 %: a false alarm sends the user to instrumental
        variables, which cost variance, so the test asks for strong evidence; closed loops give
        p-values far below it).
    direct : bool
        False (default): the plant has no direct feedthrough (``nk >= 1``, as a sampled physical
        plant), so a dependence of ``u(t)`` on ``y(t)`` is feedback too and ``u(t)`` is tested with
        the later inputs (MATLAB's ``fbck0``). True: ``u(t)`` may act on ``y(t)`` and only later
        inputs are tested (MATLAB's ``fbck``); a controller that reacts within the sample then goes
        unseen.

    Returns
    -------
    FeedbackTest

    Raises
    ------
    DataError
        On too few usable rows for the model, or an order/lead below 1.

    Notes
    -----
    For each input ``u_i`` the test compares, by an F-test, the least-squares fits of

    .. math:: y(t) = -\\sum_{k=1}^{n} a_k y(t-k) + \\sum_j \\sum_{k=1}^{n} b_{jk} u_j(t-k)
       \\;[+ \\sum_{k=0}^{m} c_k u_i(t+k)] + e(t)

    with ``n = order`` and ``m = lead`` (with ``direct=True`` the sum over ``b`` starts at
    ``k = 0`` and the one over ``c`` at ``k = 1``). Without feedback ``c = 0``. The high order lets the model
    absorb coloured noise, so that what remains in the later inputs is feedback.

    Examples
    --------
    >>> import arxid
    >>> from arxid.datasets import pi_loop
    >>> arxid.feedback(pi_loop(seed=0)).feedback
    True
    >>> arxid.feedback(pi_loop(seed=0, closed=False)).feedback
    False
    """
    data = check_data(data)
    if order < 1 or lead < 1:
        raise DataError(f"order and lead must be >= 1, got order={order}, lead={lead}")
    y = data.y
    past = [(y, k) for k in range(1, order + 1)]
    first = 0 if direct else 1
    past += [(data.u[:, j], k) for j in range(data.n_inputs) for k in range(first, order + 1)]
    p_values, stats_ = {}, {}
    n_rows = 0
    for i, name in enumerate(data.input_names):
        later = [(data.u[:, i], -k) for k in range(1 - first, lead + 1)]
        r, n_rows = lagged_factor([*past, *later, (y, 0)], data.segments, order, lead)
        n_columns = len(past) + len(later) + 1
        if n_rows < 3 * n_columns:
            raise DataError(
                f"the feedback test needs at least {3 * n_columns} usable samples (order {order}, "
                f"lead {lead}), the data have {n_rows}; give longer data or a lower order"
            )
        f, p, _q, _dof = _f_test(r, n_rows, len(past))
        p_values[name], stats_[name] = p, f
    finite = [p for p in p_values.values() if math.isfinite(p)]
    p_value = min(1.0, min(finite) * len(finite)) if finite else math.nan
    flagged = bool(math.isfinite(p_value) and p_value < alpha)
    return FeedbackTest(
        p_value=p_value,
        feedback=flagged,
        probability=100.0 * (1.0 - p_value) if math.isfinite(p_value) else math.nan,
        p_values=p_values,
        statistic=stats_,
        alpha=alpha,
        order=order,
        lead=lead,
        n_rows=n_rows,
        sentence=_sentence(data, p_values, p_value, flagged),
        consequences=_CONSEQUENCES if flagged else "",
    )


def _sentence(data: IOData, p_values: dict[str, float], p_value: float, flagged: bool) -> str:
    if not math.isfinite(p_value):
        return "The feedback test could not run (the output is predicted exactly); no conclusion."
    if flagged:
        worst = min(p_values, key=lambda k: p_values[k] if math.isfinite(p_values[k]) else 2.0)
        return (
            f"Feedback: the input {worst} follows the output {data.output_name} (later inputs predict it, "
            f"p = {p_value:.2g}): the data were logged in closed loop."
        )
    return (
        f"No sign of feedback from {data.output_name} to the input(s) (p = {p_value:.2g}): the data look "
        "like an open-loop experiment."
    )
