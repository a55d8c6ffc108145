"""Static nonlinearities as physics writes them: the input acts *through* f(u) (Hammerstein), or the
output is read through g(x) (Wiener).

Every plant is seeded and simulated here with its exact shape and parameter; separate records
(other seeds) are the validation data. The many-seed rates are in the closing note of the issue
(`/work/notes/hsim.py` ran 10 seeds per plant); here two seeds per case keep the suite short.
"""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from scipy.signal import lfilter

import arxid
from arxid.analysis.cli import main
from arxid.exceptions import DataError, OrderError
from arxid.models.effects import parse_effect
from arxid.selection.sanity import step_sanity

B, A = [0, 0.3, 0.15], [1, -1.2, 0.45]  # the linear part: a second-order lag, DC gain 1.8

HAMMERSTEIN = {  # f, input range, the shape's kind, its parameter (exponent, upper level, half-width)
    "square law": (lambda u: u**2, (0.5, 2.0), "power", 2.0),
    "square root": (np.sqrt, (0.1, 4.0), "power", 0.5),
    "signed power": (lambda u: np.sign(u) * np.abs(u) ** 1.5, (-2.0, 2.0), "signed power", 1.5),
    "reversible thrust": (lambda u: u * np.abs(u), (-2.0, 2.0), "signed power", 2.0),
    "saturation": (lambda u: np.clip(u, -0.6, 0.8), (-1.5, 1.5), "saturation", 0.8),
    "dead zone": (lambda u: np.sign(u) * np.maximum(np.abs(u) - 0.4, 0), (-1.5, 1.5), "dead zone", 0.4),
}
WIENER = {
    "quadratic sensor": (lambda x: np.maximum(x, 0) ** 2, (0.5, 2.0), "power", 2.0),
    "saturating sensor": (lambda x: np.clip(x, -0.6, 0.8), (-0.8, 0.8), "saturation", 0.8),
    "dead band": (lambda x: np.sign(x) * np.maximum(np.abs(x) - 0.4, 0), (-1.5, 1.5), "dead zone", 0.4),
}


def held(rng, n, lo, hi, levels=None):
    """Steps held 5 to 40 samples: uniform amplitudes (rich), or a few levels (a staircase)."""
    u, t = np.empty(n), 0
    while t < n:
        d = int(rng.integers(5, 40))
        u[t : t + d] = rng.choice(levels) if levels is not None else rng.uniform(lo, hi)
        t += d
    return u


def plant(f, span, seed, n, staircase, wiener=False, snr_db=30):
    rng = np.random.default_rng(seed)
    levels = np.linspace(*span, 7 if wiener else 5) if staircase else None
    u = held(rng, n, *span, levels)
    y0 = f(lfilter(B, A, u)) if wiener else lfilter(B, A, f(u))
    y = y0 + rng.standard_normal(n) * np.std(y0) * 10 ** (-snr_db / 20)
    return arxid.IOData(y, u, 0.01, input_names=["u"])


def records(f, span, seed, staircase, wiener=False):
    """Estimation and validation from separate experiments (other seeds)."""
    return plant(f, span, 1000 + seed, 3000, staircase, wiener), plant(f, span, 5000 + seed, 2000, staircase, wiener)


def first_named(d):
    sig = [s for s in d.suspects if s.significant]
    return sig[0] if sig else None


# --------------------------------------------------------------------------------- the grammar
def test_a_shape_replaces_its_input_and_a_noise_free_plant_is_recovered_exactly():
    rng = np.random.default_rng(0)
    u = held(rng, 2000, 0.5, 2.0)
    y = lfilter([0, 0.3, 0.15], [1, -1.2, 0.45], 0.7 * u**2) + 0.25
    data = arxid.IOData(y, u, 0.01, input_names=["volt"])
    m = arxid.arx(data, 2, 2, 1, effects=["through(volt^2)", "const"])
    np.testing.assert_allclose(m.parameters_, [-1.2, 0.45, 0.21, 0.105, 0.25 * 0.25], atol=1e-9)
    assert m.n_params == 5  # the square replaces the voltage: no column of the voltage itself
    assert m.predict(data, None)[10:] == pytest.approx(y[10:], abs=1e-8)
    # the model keeps its shape through JSON
    again = arxid.ArxModel.from_json_text(m.to_json())
    assert again.effects == ("through(volt^2)", "const")
    np.testing.assert_allclose(again.predict(data, None), m.predict(data, None))


@pytest.mark.parametrize(
    "text, written, values",
    [
        ("through(u1^0.5)", "through(u1^0.5)", [0.0, 1.0, 2.0]),
        ("through( spow(u1, 2) )", "through(spow(u1,2))", [-4.0, 1.0, 16.0]),
        ("through(clip(u1,-1,2.5))", "through(clip(u1,-1,2.5))", [-1.0, 1.0, 2.5]),
        ("through(dz(u1,0.5))", "through(dz(u1,0.5))", [-1.5, 0.5, 3.5]),
        ("through(u1*vbat)", "through(u1*vbat)", [-4.0, 2.0, 8.0]),
    ],
)
def test_each_shape_reads_and_evaluates(text, written, values):
    u = np.array([-2.0, 1.0, 4.0])
    data = arxid.IOData(np.zeros(3), np.abs(u) if "^0.5" in text else u, 1.0, extra={"vbat": np.full(3, 2.0)})
    e = parse_effect(text, data)
    assert e.text == written and e.shape is not None
    from arxid.models.effects import effect_series

    np.testing.assert_allclose(
        effect_series(text, data)[[0, 1, 2]], values if "^0.5" not in text else np.sqrt([2, 1, 4])
    )


@pytest.mark.parametrize(
    "effects, error, match",
    [
        (["through(u1^2)"], DataError, "goes negative"),
        (["through(dz(u1,0.1))", "through(clip(u1,-1,1))"], OrderError, "both replace the input"),
        (["through(clip(u1,1,0))"], OrderError, "lower level must be below"),
        (["through(tanh(u1))"], OrderError, "through\\( \\) takes one of"),
        (["through(vbat^2)"], OrderError, "shapes an input"),
    ],
)
def test_a_shape_that_cannot_be_is_refused_with_a_clear_message(effects, error, match):
    rng = np.random.default_rng(1)
    data = arxid.IOData(rng.standard_normal(300), rng.standard_normal(300), 1.0, extra={"vbat": np.ones(300)})
    with pytest.raises(error, match=match):
        arxid.arx(data, 1, 1, 1, effects=effects)


# --------------------------------------------------------------------- Hammerstein and Wiener plants
@pytest.mark.parametrize("staircase", [False, True], ids=["rich", "staircase"])
@pytest.mark.parametrize("name", list(HAMMERSTEIN))
def test_the_input_shape_is_named_first_with_its_parameter(name, staircase):
    f, span, kind, truth = HAMMERSTEIN[name]
    if staircase and name == "signed power":
        pytest.skip("on a staircase only the named laws are tried: an exponent of 1.5 is not one (see docs)")
    for seed in (0, 1):
        est, val = records(f, span, seed, staircase)
        d = arxid.diagnose(arxid.arx(est, 2, 2, 1), est, val)
        top = first_named(d)
        assert top is not None and top.kind == "shape", (name, seed, str(d))
        shape = parse_effect(top.effects[0], est).shape
        found = shape.params[1] if kind == "saturation" else shape.params[0]
        assert shape.kind == kind and abs(found / truth - 1) <= 0.10, (name, seed, top.effect)
        assert top.improvement >= 0.3 and "the input acts through" in top.physics
        # terms that only re-describe the shape (u^3, sign(du), u^2 beside u) are not named
        assert [s.effect for s in d.significant if s.kind != "dynamics"] == [top.effect], str(d)


@pytest.mark.parametrize("staircase", [False, True], ids=["rich", "staircase"])
@pytest.mark.parametrize("name", list(WIENER))
def test_the_sensor_shape_is_named_first_and_the_ladder_ends_there(name, staircase):
    g, span, kind, truth = WIENER[name]
    for seed in (0, 1):
        est, val = records(g, span, seed, staircase, wiener=True)
        lad = arxid.Ladder.run(arxid.arx(est, 2, 2, 1), est, val)
        top = first_named(lad.diagnoses[0])
        assert top is not None and top.kind == "sensor", (name, seed, str(lad.diagnoses[0]))
        sensor = top.model.sensor
        found = sensor.params[1] if kind == "saturation" else sensor.params[0]
        assert sensor.kind == kind and abs(found / truth - 1) <= 0.10, (name, seed, top.effect)
        assert lad.steps[-1].added == top.effect and "the output is read through" in lad.steps[-1].physics
        assert lad.errors[-1] < 0.5 * lad.errors[0]


@pytest.mark.parametrize("staircase", [False, True], ids=["rich", "staircase"])
def test_a_linear_plant_gets_no_shape(staircase):
    for seed in range(4):
        est, val = records(lambda u: u, (-1.0, 1.0), seed, staircase)
        d = arxid.diagnose(arxid.arx(est, 2, 2, 1), est, val)
        assert not [s.effect for s in d.significant if s.kind in ("shape", "sensor")], str(d)


def test_a_shaped_input_is_stepped_about_its_operating_point():
    """A power law is not defined below zero: the step check moves the voltage about its mean."""
    f, span, _, _ = HAMMERSTEIN["square law"]
    est, val = records(f, span, 0, False)
    m = arxid.arx(est, 2, 2, 1, effects=["through(u^2)"])
    check = step_sanity(m, val)
    # the up and down steps differ (the square law is not odd), and nothing else is flagged
    assert set(check.flags) <= {"not-antisymmetric"}, check.reasons
    assert check.input_amplitude[0] > 0


# ------------------------------------------------------------------------------------ real records
@pytest.mark.realdata
def test_heating_lamp_power_is_the_first_rung_of_the_default_cli(shared_data, tmp_path, capsys):
    """The DaISy heating plate, as a new user runs it: the lamp heats with power ∝ V²."""
    raw = np.loadtxt(shared_data / "daisy-heating" / "heating_system.dat")
    path = tmp_path / "heating.csv"
    np.savetxt(path, raw, delimiter=",", header="time,voltage,temperature", comments="", fmt="%.3f")
    assert (
        main(["diagnose", str(path), "--time", "time", "--output", "temperature", "--inputs", "voltage", "--json"]) == 0
    )
    out = json.loads(capsys.readouterr().out)
    ladder = out["ladder"]
    first = ladder[1]["added"]
    power = re.fullmatch(r"through\(voltage\^([0-9.]+)\)(\+const)?", first)
    assert power and 1.6 <= float(power[1]) <= 2.4, first
    assert 1 - ladder[1]["rms_sim_val"] / ladder[0]["rms_sim_val"] >= 0.25
    rungs = " ".join(step["added"] for step in ladder)
    assert "sign(d" not in rungs and "^3" not in rungs, rungs


@pytest.mark.realdata
def test_heating_at_another_split_still_names_the_lamp_power(shared_data):
    raw = np.loadtxt(shared_data / "daisy-heating" / "heating_system.dat")
    data = arxid.IOData(raw[:, 2], raw[:, 1], 2.0, output_name="temp", input_names=["volt"])
    est, val = data.split(0.6)
    d = arxid.diagnose(arxid.arx(est, 1, 1, 0), est, val)
    assert d.top.effect in ("through(volt^2)+const", "through(volt^2)"), str(d)
    backlash = next(s for s in d.suspects if s.effect == "sign(dvolt)")
    assert not backlash.significant


@pytest.mark.realdata
def test_thrust_stand_names_the_square_law(shared_data):
    """Crazyflie thrust stand, rpm → thrust: a square law, as a shape or as a term beside the speed."""
    from test_selection import thrust_stand

    est, val = thrust_stand(shared_data).split(0.7)
    d = arxid.diagnose(arxid.arx(est, 1, 1, 0), est, val)
    top = d.top.effect
    power = re.fullmatch(r"through\(rpm\^([0-9.]+)\)(\+const)?", top)
    assert top in ("rpm^2", "rpm^2+const") or (power and abs(float(power[1]) - 2) <= 0.2), str(d)
    assert d.top.improvement >= 0.9


def test_no_sensor_shape_is_judged_against_a_perfect_baseline():
    """A validation record the model already matches exactly (a flight log's idle stretch gave
    validation error 0) has no error to fall: no sensor suspect, no division by zero."""
    from arxid.diagnosis.sensor_shapes import sensor_suspects

    f, span, _, _ = WIENER["quadratic sensor"]
    est, val = records(f, span, 0, False, wiener=True)
    assert sensor_suspects(arxid.arx(est, 2, 2, 1), est, val, None, "zero", 0.0) == []


@pytest.mark.parametrize("seed", [1, 2])
def test_an_inputs_level_count_is_the_distinct_values_up_to_the_scans_minimum(seed):
    """Counted from the first samples when they hold enough, else over the record: a staircase whose
    later levels come after the first samples, one of 25 levels, a rich input, with missing samples."""
    from arxid.diagnosis.shapes import MIN_SCAN_LEVELS, input_levels, level_count

    rng = np.random.default_rng(seed)
    late = np.concatenate([np.full(5000, 0.5), np.repeat(rng.uniform(0, 2, 30), 1000)])
    for x in (late, np.repeat(rng.uniform(0, 2, 25), 800), rng.standard_normal(9000), np.repeat([0.0, 1.0, 2.0], 3000)):
        x = x.copy()
        x[rng.integers(0, x.size, 40)] = np.nan
        for y in (x, x[:3000]):
            assert level_count(y) == min(input_levels(y).size, MIN_SCAN_LEVELS)
    assert level_count(late) == MIN_SCAN_LEVELS and input_levels(late[:4096]).size == 1
