"""Is the plant integrating? A unit-root test on the best structures of a sweep, with a stated level.

An ARX model ``A(z^-1) y = B(z^-1) u + e`` has a pole at z = 1 exactly when ``A(1) = 1 + Σ aᵢ = 0``.
``A(1)`` is linear in the parameters, so its standard error follows from the parameter covariance,
``se = √(gᵀ P g)`` with ``g`` one on the a's and zero elsewhere, and ``t = A(1) / se`` is the
Dickey–Fuller statistic of the regression rewritten in differences (Δy on y(t−1), the lagged Δy
and the inputs; its coefficient of y(t−1) is −A(1)). A stable plant has ``A(1) > 0``: the unit
root is **rejected** when ``t > UNIT_ROOT_CRITICAL`` (2.58, the 1% one-sided critical value of
the Dickey–Fuller test without a constant; MacKinnon 1996). Poles outside the unit circle near
z = 1 make ``A(1) < 0`` and are not rejected either.

The t statistic assumes the residuals are white; an ARX of a closed-loop double integrator is
biased, and its t sits near the critical value (2.8 on 10 s of the simulated quadrotor roll axis,
where Silverbox's worst is 2.8 too). So a second, data-length criterion: a real pole whose time
constant ``−1 / ln |p|`` (in samples) exceeds ``RECORD_SHARE`` (1/5) of the estimation rows cannot be
told from an integrator, because the record holds fewer than five time constants of its decay.
This looks at the low-frequency poles, ``|ln p| < LOW_FREQUENCY`` (0.1 rad per sample: near z = 1),
and counts one on or outside the unit circle as infinitely slow (a double integrator is often
estimated as a complex pair just outside, 1.00001 ± 0.002j, whose A(1) = |1 − p|² is positive).
A structure votes "integrating" when its unit root is not rejected or its slowest low-frequency
pole is that slow; the plant is integrating when most of the five best structures by FPE
(estimation data) vote so. Measured values are in docs/selection.md.

The unit-root t is weak near its threshold (2.4–2.5 on a quadrotor's collective thrust to vertical
acceleration, which settles), so the fitted models have a say: when the unit root alone is not
rejected, the best structures by **free-run validation error** are asked whether they settle
(:class:`SettlingEvidence`). When most of them are stable, their slowest low-frequency pole decays
within the record (time constant below ``RECORD_SHARE`` of it, the same rule as above) and their free
run follows the validation data better than its mean (fit above 0 %), a stable model explains data it
was not fitted on, which an integrating plant's drift would not allow: the plant is called not
integrating, and the reason says that the fitted models decided. An integrator's stable
approximation drifts away in free run (fit −108 % on the simulated roll axis), so it keeps its verdict.

A pole outside the unit circle is judged with the same covariance: its magnitude's standard
error is ``σ = √(gᵀ P_aa g)`` with ``g_k = Re(p̄/|p| · ∂p/∂a_k)`` and ``∂p/∂a_k = −p^(n−k) / A'(p)``
(first order in the parameters), and ``(|p| − 1) / σ > UNIT_ROOT_CRITICAL`` is a pole
significantly outside.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from .._base.records import record

__all__ = [
    "UNIT_ROOT_CRITICAL",
    "RECORD_SHARE",
    "IntegratorTest",
    "unit_root_t",
    "pole_excess",
    "slowest_time_constant",
    "integrator_test",
    "structure_integrates",
    "SettlingEvidence",
]

#: One-sided 1% critical value of the Dickey–Fuller t statistic without a constant (large samples).
UNIT_ROOT_CRITICAL = 2.58

#: How many of the best structures by FPE vote.
VOTERS = 5

#: A pole near z = 1 whose time constant exceeds this share of the estimation record counts as an integrator.
RECORD_SHARE = 0.2

#: Poles with |ln p| below this (rad per sample) are the low-frequency ones the time-constant rule looks at.
LOW_FREQUENCY = 0.1


@record
class IntegratorTest:
    """The verdict of the unit-root test on the best structures of a sweep.

    Attributes
    ----------
    integrating : bool
        The plant was called integrating (or declared so with ``expect``).
    reason : str
        One sentence: why, with the numbers.
    structures : tuple of str
        The structures that voted (best by FPE first); empty when ``expect`` decided.
    t_values : tuple of float
        Their unit-root t statistics ``A(1) / se(A(1))``.
    time_constants : tuple of float
        Time constant of each one's slowest real pole, in samples (inf at or beyond z = 1).
    record : int
        Estimation rows.
    critical : float
        The critical value: t above it rejects a pole at z = 1.
    decided_by : str
        Which evidence decided: ``"unit-root test"``, ``"record length"``, ``"fitted models"``
        (the best free-run structures settle, :class:`SettlingEvidence`) or ``"step sanity of the
        sweep"`` (the first verdict left no sane structure and was revised).
    settling : SettlingEvidence or None
        What the best structures by free-run validation error say (None without a free-run sweep).
    """

    integrating: bool
    reason: str
    structures: tuple[str, ...] = ()
    t_values: tuple[float, ...] = ()
    time_constants: tuple[float, ...] = ()
    record: int = 0
    critical: float = UNIT_ROOT_CRITICAL
    decided_by: str = "unit-root test"
    settling: SettlingEvidence | None = None

    def to_dict(self) -> dict:
        """JSON-ready verdict.

        Returns
        -------
        dict
        """
        return {
            "integrating": self.integrating,
            "reason": self.reason,
            "structures": list(self.structures),
            "t_values": [float(t) for t in self.t_values],
            "time_constants": [float(t) if np.isfinite(t) else None for t in self.time_constants],
            "record": self.record,
            "critical": self.critical,
            "decided_by": self.decided_by,
            "settling": self.settling.to_dict() if self.settling is not None else None,
        }

    def revised(self, integrating: bool, why: str) -> IntegratorTest:
        """The verdict turned over because under it no structure of the sweep is sane.

        Parameters
        ----------
        integrating : bool
            The revised verdict.
        why : str
            One sentence: what left no sane structure.

        Returns
        -------
        IntegratorTest
        """
        verdict = "integrating" if integrating else "not integrating"
        reason = f"{verdict} (revised: {why}; the first verdict was: {self.reason})"
        return replace(self, integrating=integrating, reason=reason, decided_by="step sanity of the sweep")


@record
class SettlingEvidence:
    """What the best structures by free-run validation error say about settling.

    Attributes
    ----------
    structures : tuple of str
        The structures asked, best first.
    time_constants : tuple of float
        Time constant of each one's slowest low-frequency pole, in samples (inf on or beyond z = 1,
        0 without one).
    fits : tuple of float
        Each one's free-run fit on the validation data, percent.
    record : int
        Estimation rows.
    """

    structures: tuple[str, ...]
    time_constants: tuple[float, ...]
    fits: tuple[float, ...]
    record: int

    def votes(self) -> np.ndarray:
        """Per structure: stable, settling within the record, and following the data in free run.

        Returns
        -------
        ndarray of bool
        """
        tau = np.asarray(self.time_constants, dtype=float)
        fit = np.asarray(self.fits, dtype=float)
        return (tau < RECORD_SHARE * self.record) & (fit > 0.0)

    @property
    def settles(self) -> bool:
        """Most of the structures settle and follow the data (see :meth:`votes`)."""
        return bool(self.structures) and 2 * int(self.votes().sum()) > len(self.structures)

    def sentence(self) -> str:
        """One sentence with the numbers, for the verdict's reason.

        Returns
        -------
        str
        """
        ok = self.votes()
        tau = np.asarray(self.time_constants, dtype=float)[ok]
        fit = np.asarray(self.fits, dtype=float)[ok]
        return (
            f"{int(ok.sum())} of the {len(self.structures)} best structures by free-run validation error are stable, "
            f"settle within the record (slowest time constant {np.max(tau):.4g} samples, "
            f"{100 * np.max(tau) / self.record:.2g} % of the {self.record} estimation samples) and follow the "
            f"validation data in free run (fit {np.min(fit):.3g} to {np.max(fit):.3g} %)"
        )

    def to_dict(self) -> dict:
        """JSON-ready evidence.

        Returns
        -------
        dict
        """
        return {
            "structures": list(self.structures),
            "time_constants": [float(t) if np.isfinite(t) else None for t in self.time_constants],
            "fits": [float(f) if np.isfinite(f) else None for f in self.fits],
            "settles": self.settles,
        }


def unit_root_t(theta: np.ndarray, covariance: np.ndarray, na: int) -> float:
    """Unit-root t statistic ``A(1) / se(A(1))`` of one fitted ARX structure.

    Parameters
    ----------
    theta : ndarray of shape (p,)
        Parameters, the ``na`` a's first.
    covariance : ndarray of shape (p, p)
        Their covariance.
    na : int
        Number of a's.

    Returns
    -------
    float
        Large and positive for a stable plant; near zero or negative for a pole at (or beyond) 1.
        ``inf`` for ``na = 0`` (no pole at all).
    """
    if na == 0:
        return float("inf")
    a1 = 1.0 + float(np.sum(theta[:na]))
    var = float(np.sum(covariance[:na, :na]))
    if not var > 0:
        return float("inf") if a1 > 0 else float("-inf")
    return a1 / np.sqrt(var)


def pole_excess(theta: np.ndarray, covariance: np.ndarray, na: int) -> tuple[float, float]:
    """The largest pole magnitude and how many standard errors it lies outside the unit circle.

    Parameters
    ----------
    theta : ndarray of shape (p,)
        Parameters, the ``na`` a's first.
    covariance : ndarray of shape (p, p)
        Their covariance.
    na : int
        Number of a's.

    Returns
    -------
    magnitude : float
        Largest |pole|.
    excess : float
        ``(|p| − 1) / σ_|p|`` of that pole (negative inside; ``0`` for a repeated pole, whose
        first-order standard error is unbounded).
    """
    if na == 0:
        return 0.0, float("-inf")
    a = np.concatenate([[1.0], theta[:na]])
    poles = np.roots(a)
    p = poles[np.argmax(np.abs(poles))]
    mag = float(abs(p))
    deriv = np.polyval(np.polyder(a), p)
    if abs(deriv) < 1e-12 * max(1.0, np.abs(a).sum()):
        return mag, 0.0
    dp = -(p ** np.arange(na - 1, -1, -1)) / deriv  # ∂p/∂a_k, k = 1..na
    g = np.real(np.conj(p) / mag * dp)
    var = float(g @ covariance[:na, :na] @ g)
    if not var > 0:
        return mag, float(np.sign(mag - 1.0)) * float("inf") if mag != 1.0 else 0.0
    return mag, (mag - 1.0) / np.sqrt(var)


def slowest_time_constant(theta: np.ndarray, na: int) -> float:
    """Decay time constant ``−1 / ln |p|`` in samples of the slowest low-frequency pole
    (``|ln p| < LOW_FREQUENCY``); inf when one is on or outside the unit circle, 0 without one.

    Parameters
    ----------
    theta : ndarray of shape (p,)
        Parameters, the ``na`` a's first.
    na : int
        Number of a's.

    Returns
    -------
    float
    """
    if na == 0:
        return 0.0
    poles = np.roots(np.concatenate([[1.0], theta[:na]])).astype(complex)
    with np.errstate(divide="ignore"):
        low = poles[np.abs(np.log(poles)) < LOW_FREQUENCY]
    if not low.size:
        return 0.0
    mag = float(np.abs(low).max())
    return float("inf") if mag >= 1.0 else -1.0 / np.log(mag)


def integrator_test(
    names: Sequence[str],
    t_values: Sequence[float],
    time_constants: Sequence[float],
    record: int,
    settling: SettlingEvidence | None = None,
) -> IntegratorTest:
    """Verdict from the unit-root t statistics and slowest time constants of the best structures,
    and from what the best free-run structures say about settling.

    Parameters
    ----------
    names : sequence of str
        The voting structures, best by FPE first.
    t_values : sequence of float
        Their :func:`unit_root_t`.
    time_constants : sequence of float
        Their :func:`slowest_time_constant` (samples).
    record : int
        Estimation rows.
    settling : SettlingEvidence, optional
        The best structures by free-run validation error (from a free-run sweep).

    Returns
    -------
    IntegratorTest
        Integrating when more than half of the voters say so, unless the best free-run structures
        settle and follow the validation data (see the module docstring).
    """
    t = np.asarray(t_values, dtype=float)
    tau = np.asarray(time_constants, dtype=float)
    if not t.size:
        return IntegratorTest(False, "no structure with poles to test for an integrator", record=record)
    slow_votes = tau > RECORD_SHARE * record
    votes = ~(t > UNIT_ROOT_CRITICAL) | slow_votes
    kept = int(votes.sum())
    integrating = 2 * kept > t.size
    decided_by = "record length" if integrating and 2 * int(slow_votes.sum()) > t.size else "unit-root test"
    verdict = "integrating" if integrating else "not integrating"
    count = kept if integrating else t.size - kept
    reason = f"{verdict}: {count} of the {t.size} best structures by FPE say so ({_unit_root_numbers(t, tau, record)})"
    if integrating and settling is not None and settling.settles:
        integrating, decided_by = False, "fitted models"
        reason = (
            f"not integrating: the fitted models decide, because {settling.sentence()}, which an integrating "
            f"plant's drift would not allow; the unit-root test alone said integrating ({count} of the {t.size} "
            f"best structures by FPE; {_unit_root_numbers(t, tau, record)})"
        )
    return IntegratorTest(
        integrating,
        reason,
        tuple(names),
        tuple(float(x) for x in t),
        tuple(float(x) for x in tau),
        record,
        decided_by=decided_by,
        settling=settling,
    )


def _unit_root_numbers(t: np.ndarray, tau: np.ndarray, record: int) -> str:
    """The unit-root statistics and the slowest time constant, in words."""
    slow = np.max(tau)
    return (
        f"unit-root test of a pole at z = 1, A(1) = 0: t from {np.min(t):.3g} to {np.max(t):.3g}, rejected above "
        f"{UNIT_ROOT_CRITICAL} at the 1% level; slowest time constant "
        + ("infinite" if not np.isfinite(slow) else "none near z = 1" if slow == 0 else f"{slow:.4g} samples")
        + f" against {record} estimation samples (an integrator above {RECORD_SHARE:g} of them)"
    )


def structure_integrates(
    theta: np.ndarray, covariance: np.ndarray, na: int, record: int, free_run_fit: float | None = None
) -> bool:
    """One structure's vote: its unit root is not rejected, or its slowest low-frequency pole is
    too slow for the record (the rule of :func:`integrator_test`, applied to a single model), unless
    its free run settles and follows validation data (:class:`SettlingEvidence`, one structure).

    Parameters
    ----------
    theta : ndarray of shape (p,)
        Parameters, the ``na`` a's first.
    covariance : ndarray of shape (p, p)
        Their covariance.
    na : int
        Number of a's.
    record : int
        Estimation rows.
    free_run_fit : float, optional
        The structure's free-run fit on validation data, percent (unknown when None).

    Returns
    -------
    bool
    """
    if na == 0:
        return False
    tau = slowest_time_constant(theta, na)
    t = unit_root_t(theta, covariance, na)
    votes = bool(not t > UNIT_ROOT_CRITICAL or tau > RECORD_SHARE * record)
    if votes and free_run_fit is not None:
        return not SettlingEvidence(("",), (tau,), (float(free_run_fit),), record).settles
    return votes
