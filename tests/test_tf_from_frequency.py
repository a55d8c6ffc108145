"""arxid.tf_from_frequency: a continuous transfer function fitted to a measured frequency response.

Known answers: plants sampled exactly with scipy.signal.cont2discrete (zero-order hold), simulated
with lfilter under output noise, their FRF by arxid.frf, and the fit's poles within 2 % of the
plant's; exact data give the plant to 1e-6.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.signal import cont2discrete, freqz, lfilter

import arxid
from arxid.exceptions import ArxidError, DataError, OrderError

TS = 0.01
#: 2 poles at 10 rad/s (damping 0.2) and one real pole at 30 rad/s, one zero at 50 rad/s.
NUM = np.array([600.0, 30000.0]) / 50.0
DEN = np.polymul([1.0, 4.0, 100.0], [1.0, 30.0])


def _simulate(seed: int, num=NUM, den=DEN, noise: float = 0.002, n: int = 2**16, delay_samples: int = 0):
    rng = np.random.default_rng(seed)
    b, a, _ = cont2discrete((num, den), TS, method="zoh")
    b = np.concatenate([np.zeros(delay_samples), np.ravel(b)])
    u = rng.standard_normal(n)
    y = lfilter(b, a, u) + noise * rng.standard_normal(n)
    return arxid.IOData(y, u, ts=TS)


def _pole_error(model, den=DEN) -> float:
    """Largest relative distance from a true pole to the nearest estimated one."""
    est = model.poles()
    return max(np.min(np.abs(est - p)) / abs(p) for p in np.roots(den))


@pytest.mark.parametrize("seed", range(5))
def test_poles_within_2_percent_from_a_noisy_frf(seed):
    fr = arxid.frf(_simulate(seed), segment_length=1024)
    model = arxid.tf_from_frequency(fr, 3, 1)
    assert isinstance(model, arxid.models.continuous_tf.ContinuousTransferFunction)
    assert _pole_error(model) < 0.02
    assert model.structure_name().startswith("tf(3,1)")


@pytest.mark.parametrize("weighting", ["coherence", "none"])
def test_other_weightings_fit_absolute_errors(weighting):
    """Weights on the absolute error favour the high-gain frequencies: the resonant pair within 2 %,
    the fast pole (where the gain is low) worse than with the default inverse-variance weights."""
    fr = arxid.frf(_simulate(7), segment_length=1024)
    model = arxid.tf_from_frequency(fr, 3, 1, weighting=weighting)
    assert _pole_error(model, np.array([1.0, 4.0, 100.0])) < 0.02
    assert _pole_error(arxid.tf_from_frequency(fr, 3, 1)) < _pole_error(model)


def test_exact_data_give_the_plant():
    fr = arxid.frf(_simulate(0, noise=0.0), segment_length=4096)
    # the Welch window's leakage is the only error left: tiny for 4096 samples at 100 Hz
    model = arxid.tf_from_frequency(fr, 3, 1)
    np.testing.assert_allclose(model.den_, DEN, rtol=2e-3)
    np.testing.assert_allclose(model.num_, NUM, rtol=2e-3)


def test_the_zero_order_hold_matters_near_nyquist():
    """Fitted as if continuous, the hold's phase lag biases the poles; the exact ZOH response does not."""
    fr = arxid.frf(_simulate(1), segment_length=1024)
    zoh = _pole_error(arxid.tf_from_frequency(fr, 3, 1))
    continuous = _pole_error(arxid.tf_from_frequency(fr, 3, 1, intersample="continuous"))
    assert zoh < 0.02 < continuous


def test_dead_time_estimated():
    fr = arxid.frf(_simulate(2, delay_samples=3), segment_length=1024)
    model = arxid.tf_from_frequency(fr, 3, 1, delay="estimate")
    assert model.dead_time_ == pytest.approx(0.03, abs=0.002)
    assert _pole_error(model) < 0.02


def test_closed_loop_frf_fits_the_plant():
    """The reference-based FRF of a P-controlled loop, fitted: the plant's poles, not the loop's."""
    rng = np.random.default_rng(3)
    n = 2**16
    b, a, _ = cont2discrete((NUM, DEN), TS, method="zoh")
    b, a = np.ravel(b), np.ravel(a)
    r = 10.0 * rng.standard_normal(n)
    v = lfilter([1.0], [1.0, -0.95], rng.standard_normal(n)) * 0.01
    y, u = np.zeros(n), np.zeros(n)
    x = np.zeros(n)
    for t in range(n):
        x[t] = sum(b[k] * u[t - k] for k in range(1, len(b)) if t >= k) - sum(
            a[k] * x[t - k] for k in range(1, len(a)) if t >= k
        )
        y[t] = x[t] + v[t]
        u[t] = 0.5 * (r[t] - y[t])
    fr = arxid.frf(arxid.IOData(y, u, ts=TS, extra={"r": r}), reference="r", segment_length=1024)
    assert _pole_error(arxid.tf_from_frequency(fr, 3, 1)) < 0.02


def test_model_is_usable_like_tfests():
    data = _simulate(4)
    model = arxid.tf_from_frequency(arxid.frf(data, segment_length=1024), 3, 1)
    assert model.fit_percent_ > 90
    sd = model.parameter_dict()
    assert set(sd) == {"a1", "a2", "a3", "b0", "b1"} and all(s > 0 for _, s in sd.values())
    assert "Sanathanan" in model.method_


def test_bad_input_gives_typed_errors():
    fr = arxid.frf(_simulate(0, n=4096), segment_length=256)
    with pytest.raises(DataError, match="FrequencyResponse"):
        arxid.tf_from_frequency(_simulate(0, n=512), 2)
    with pytest.raises(OrderError, match="strictly proper"):
        arxid.tf_from_frequency(fr, 2, 2)
    with pytest.raises(OrderError):
        arxid.tf_from_frequency(fr, -1)
    with pytest.raises(ArxidError, match="weighting"):
        arxid.tf_from_frequency(fr, 2, weighting="bode")
    with pytest.raises(ArxidError, match="intersample"):
        arxid.tf_from_frequency(fr, 2, intersample="foh")
    with pytest.raises(ArxidError, match="dead time"):
        arxid.tf_from_frequency(fr, 2, delay=-1.0)
    with pytest.raises(DataError, match="too few"):
        arxid.tf_from_frequency(fr, 3, 1, frequency_range=(1.0, 1.5))
    with pytest.raises(DataError, match="no input named"):
        arxid.tf_from_frequency(fr, 2, input="u9")


def test_bode_figure_shades_where_the_model_misses():
    pytest.importorskip("matplotlib")
    from arxid.frequency_domain._model_response import model_response
    from arxid.plots.bode import misses

    fr = arxid.frf(_simulate(5), segment_length=1024)
    right = arxid.tf_from_frequency(fr, 3, 1)
    wrong = arxid.tf_from_frequency(fr, 1, 0)
    b, a, _ = cont2discrete((right.num_, right.den_), TS, method="zoh")
    g = model_response(right, fr.frequency)
    np.testing.assert_allclose(g, freqz(np.ravel(b), a, worN=fr.frequency, fs=1 / TS)[1], rtol=1e-8)
    good = fr.coherence > 0.9
    assert misses(fr, g)[good].mean() < 0.05
    assert misses(fr, model_response(wrong, fr.frequency))[good].mean() > 0.5
    fig = fr.plot(wrong)
    assert len(fig.axes) == 3 and "model outside the band" in [t.get_text() for t in fig.axes[0].get_legend().texts]
    assert len(fr.plot().axes) == 3
