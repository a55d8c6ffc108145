"""The integrator verdict on records nobody tuned it on: separate validation flights, many seeds.

Each case is estimated on one record and validated on another (a different seed: its own battery
level, drift and noise), never on a split of the same record. The verdict must be right and never
leave the choice empty: the demo's collective thrust -> vertical acceleration settles (its unit-root
t sits just below the critical value, so the fitted models decide), a slow stable plant whose input
gain sags settles, and a position servo integrates.
"""

from __future__ import annotations

import warnings

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.selection.integrator import IntegratorTest, SettlingEvidence, integrator_test
from plants import position_servo

SEEDS = range(20)


def sagging_plant(seed: int, n: int = 8000, pole: float = 0.998) -> arxid.IOData:
    """A stable second-order plant (poles 0.998 and 0.6, time constant 500 samples) whose input gain
    sags by 30 % over the record, as with an unlogged battery, with coloured output noise."""
    rng = np.random.default_rng(seed)
    u = np.repeat(rng.standard_normal(n // 40 + 1), 40)[:n] + 1.0
    gain = 1.0 - 0.3 * np.linspace(0.0, 1.0, n) ** 1.5
    y = lfilter([0, 0, 0, 0.4 * (1 - pole)], np.convolve([1, -pole], [1, -0.6]), u * gain)
    y = y + lfilter([1], [1, -0.9], 0.02 * np.std(y) * rng.standard_normal(n))
    return arxid.IOData(y, u, 0.01, output_name="speed", input_names=["command"])


def sweep_quietly(est: arxid.IOData, val: arxid.IOData) -> arxid.SweepResult:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", arxid.ArxidWarning)  # grid-edge notes
        return arxid.sweep(est, validation=val, progress=False)


def best_sane(res: arxid.SweepResult) -> arxid.ArxModel:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", arxid.ArxidWarning)
        return res.best(sane=True)


# ------------------------------------------------------------------------------------------ the demo
@pytest.mark.parametrize("seed", SEEDS)
def test_demo_on_a_separate_flight_settles_and_has_a_sane_choice(demo_flight, seed):
    """Measured before the fix: every seed called integrating (t 2.39-2.52 < 2.58), and some raised
    'no structure of the sweep passes the step sanity checks'."""
    res = sweep_quietly(demo_flight(seed), demo_flight(seed + 1000))
    assert not res.integrating and res.horizon is None, res.integrating_reason
    verdict = res.integrator
    assert verdict.decided_by in ("fitted models", "unit-root test"), verdict.reason
    if verdict.decided_by == "fitted models":  # the unit root alone was not rejected
        assert min(verdict.t_values) <= verdict.critical and verdict.settling.settles
        assert "the fitted models decide" in res.integrating_reason
    model = best_sane(res)
    assert model.is_stable and res.sanity(model.selection_.rank).ok


@pytest.mark.parametrize("seed", [0, 7, 13])
def test_demo_analysis_names_the_battery_first_and_the_error_falls(demo_flight, seed):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", arxid.ArxidWarning)
        a = arxid.analyse(demo_flight(seed), demo_flight(seed + 1000))
    assert not a.sweep.integrating and a.horizon is None
    first = a.ladder.steps[1]
    assert any("vbat" in e for e in first.effects), [s.effects for s in a.ladder.steps]
    assert first.rms_sim_val < 0.95 * a.ladder.steps[0].rms_sim_val


# ------------------------------------------------------------------------ a stable and an integrating plant
@pytest.mark.parametrize("seed", SEEDS)
def test_a_slow_stable_plant_with_a_sagging_gain_is_not_integrating(seed):
    res = sweep_quietly(sagging_plant(seed), sagging_plant(seed + 1000))
    assert not res.integrating and res.horizon is None, res.integrating_reason
    assert 0.99 < res.max_pole[0] < 1.0
    assert best_sane(res).is_stable


# 2,000 samples (20 s) prove what 4,000 did: the verdict and the sane choice held on seeds 0-59 at
# that length, at 45 % of the time.
@pytest.mark.parametrize("seed", SEEDS)
def test_a_position_servo_is_integrating_on_every_seed(seed):
    res = sweep_quietly(position_servo(seed), position_servo(seed + 1000))
    assert res.integrating and res.horizon is not None, res.integrating_reason
    assert not res.integrator.settling.settles  # its stable approximations drift away in free run
    model = best_sane(res)
    assert res.sanity(model.selection_.rank).ok


# ------------------------------------------------------------------------------------------ the rules
def test_settling_evidence_overrides_only_a_unit_root_that_is_not_rejected():
    settles = SettlingEvidence(("ARX(2,1,1)",) * 3, (100.0, 120.0, 90.0), (40.0, 38.0, 41.0), 5000)
    drifts = SettlingEvidence(("ARX(2,1,1)",) * 3, (100.0, 120.0, 90.0), (-80.0, -90.0, 5.0), 5000)
    slow = SettlingEvidence(("ARX(2,1,1)",) * 3, (1500.0, 1200.0, 90.0), (40.0, 38.0, 41.0), 5000)
    names, t_low, tau = ("a", "b", "c"), (2.4, 2.5, 2.3), (100.0, 100.0, 100.0)
    assert not integrator_test(names, t_low, tau, 5000, settles).integrating
    assert integrator_test(names, t_low, tau, 5000, settles).decided_by == "fitted models"
    assert integrator_test(names, t_low, tau, 5000, drifts).integrating  # free runs do not follow
    assert integrator_test(names, t_low, tau, 5000, slow).integrating  # too slow for the record
    assert integrator_test(names, t_low, tau, 5000).integrating  # no free-run evidence
    rejected = integrator_test(names, (9.0, 8.0, 7.0), tau, 5000, drifts)
    assert not rejected.integrating and rejected.decided_by == "unit-root test"


def test_a_revised_verdict_says_what_it_was_and_why():
    first = IntegratorTest(True, "integrating: 5 of the 5 best structures by FPE say so (...)")
    revised = first.revised(False, "as an integrating plant no structure's step response passes the sanity checks")
    assert not revised.integrating and revised.decided_by == "step sanity of the sweep"
    assert revised.reason.startswith("not integrating (revised: as an integrating plant")
    assert "the first verdict was: integrating: 5 of the 5" in revised.reason
    assert revised.to_dict()["decided_by"] == "step sanity of the sweep"


def test_analyse_answers_even_when_no_structure_is_sane():
    """Valid data always get a model: the choice says which check it fails (no exception)."""
    est, val = sagging_plant(1), sagging_plant(1001)
    strict = arxid.selection.sanity.SanityLimits(large=1e-6)  # every step is 'implausibly large'
    res = arxid.sweep(est, validation=val, na=[1, 2], nb=[1], nk=[2, 3], limits=strict, progress=False)
    with pytest.raises(arxid.ArxidError, match="no structure of the sweep passes"):
        res.select(sane=True)
    from arxid.analysis import choose

    model, choice = choose(res)
    assert choice.structure == res.structure_name(res.select(sane=False).rank) == model.structure_name()
    assert "no structure's step response passes the sanity check" in choice.reason
