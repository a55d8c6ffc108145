"""Step sanity checks on models with known step responses."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.selection.sanity import SanityLimits, check_responses, step_sanity


def _data(a, b, nk, n=4000, seed=0, offset=0.0):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    y = lfilter(np.concatenate([np.zeros(nk), b]), a, u) + offset + 0.001 * rng.standard_normal(n)
    return arxid.IOData(y, u, ts=0.01)


def test_stable_first_order_passes_and_reports_numbers():
    d = _data([1, -0.9], [0.1], 1)
    m = arxid.arx(d, 1, 1, 1)
    v = step_sanity(m, d, expect="stable")
    assert v.ok and v.flags == ()
    # step amplitude = std(u) x DC gain 1
    assert v.amplitude == pytest.approx(np.std(d.u) * 1.0, rel=0.02)
    assert v.horizon == d.n_samples
    assert "ok" in str(v) and json.loads(v.to_json())["ok"] is True


def test_implausibly_small_and_large_amplitude_are_flagged():
    d = _data([1, -0.9], [0.1], 1)
    m = arxid.arx(d, 1, 1, 1)
    small = step_sanity(m, d, limits=SanityLimits(small=10.0))
    assert "too-small" in small.flags and "implausibly small" in small.reasons[0]
    large = step_sanity(m, d, limits=SanityLimits(large=0.01))
    assert large.flags == ("too-large",)


def test_unstable_model_flagged_when_stable_is_expected():
    d = _data([1, -1.02], [0.01], 1, n=300)
    m = arxid.arx(d, 1, 1, 1)
    assert m.poles()[0] > 1
    v = step_sanity(m, d, expect="stable")
    assert "unstable" in v.flags


def test_integrator_grows_and_stable_plant_does_not():
    integ = _data([1, -1.0], [0.05], 2)
    m = arxid.arx(integ, 1, 1, 2)
    assert step_sanity(m, integ, expect="integrating").ok
    stable = _data([1, -0.5], [0.5], 2)
    ms = arxid.arx(stable, 1, 1, 2)
    v = step_sanity(ms, stable, expect="integrating")
    assert "not-growing" in v.flags
    assert "not-growing" in step_sanity(m, integ, expect="double-integrating").flags  # t, not t^2


def test_sign_change_and_wrong_sign():
    # A response that rises, then turns and grows with the opposite sign.
    t = np.arange(1000.0)
    s = 0.5 * t - 1e-3 * t**2
    v = check_responses(
        "X",
        [s],
        [-s],
        np.array([1.0, 1.0]),
        out_range=1.0,
        amplitudes=[1.0],
        expect="double-integrating",
        limits=SanityLimits(),
    )
    assert "sign-change" in v.flags
    small_dip = 1e-3 * t**2 - 0.01 * np.minimum(t, 5)
    v = check_responses(
        "X",
        [small_dip],
        [-small_dip],
        np.array([1.0, 1.0]),
        out_range=1.0,
        amplitudes=[1.0],
        expect="double-integrating",
        limits=SanityLimits(),
    )
    assert v.ok  # a dip below sign_tolerance of the peak is not a sign change
    d2 = _data([1, -1.0], [0.05], 1)
    m2 = arxid.arx(d2, 1, 1, 1)
    assert "wrong-sign" in step_sanity(m2, d2, expect="integrating", limits=SanityLimits(sign=-1)).flags
    assert step_sanity(m2, d2, expect="integrating", limits=SanityLimits(sign=1)).ok


def test_offset_does_not_break_antisymmetry():
    """Issue 27: the constant's own response is the same for both steps and is taken out (it used
    to be read as an asymmetry; tests/test_robust_offsets.py has the cases that must stay flagged)."""
    d = _data([1, -0.8], [0.2], 1, offset=0.5)
    m = arxid.arx(d, 1, 1, 1, effects=["const"])
    v = step_sanity(m, d)
    assert "not-antisymmetric" not in v.flags


def test_unknown_expectation_is_refused():
    d = _data([1, -0.9], [0.1], 1, n=200)
    m = arxid.arx(d, 1, 1, 1)
    with pytest.raises(arxid.ArxidError, match="expect must be one of"):
        step_sanity(m, d, expect="unstable")
