"""analyse(model=...): a structure written as text (``oe:2,2,3``) or a fitted model, instead of a sweep."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

import arxid
from arxid.analysis.cli import main
from arxid.models.spec import MODEL_FORMS, parse_model_spec


def _data(seed: int = 3, n: int = 3000, coloured: bool = False) -> arxid.IOData:
    """The issue's plant (0.5 z^-3 + 0.3 z^-4)/(1 - 1.5 z^-1 + 0.7 z^-2), binary input, 20 % output
    noise (white, or through C/D = (1 + 0.5 z^-1)/(1 - 0.8 z^-1))."""
    rng = np.random.default_rng(seed)
    u = np.sign(rng.standard_normal(n))
    x = signal.lfilter([0, 0, 0, 0.5, 0.3], [1, -1.5, 0.7], u)
    e = rng.standard_normal(n)
    v = signal.lfilter([1, 0.5], [1, -0.8], e) if coloured else e
    return arxid.IOData(x + 0.2 * np.std(x) * v / np.std(v), u, ts=0.01)


@pytest.mark.parametrize(
    ("text", "kind", "orders", "name"),
    [
        ("oe:2,2,3", "oe", (2, 2, 3), "OE(2,2,3)"),
        ("OE: 2, 2, 3", "oe", (2, 2, 3), "OE(2,2,3)"),
        ("armax:2,2,1,3", "armax", (2, 2, 1, 3), "ARMAX(2,2,1,3)"),
        ("bj:2,1,1,2,3", "bj", (2, 1, 1, 2, 3), "BJ(2,1,1,2,3)"),
        ("arx:2,2,3", "arx", (2, 2, 3), "ARX(2,2,3)"),
    ],
)
def test_model_specs_read_matlab_argument_order(text, kind, orders, name):
    spec = parse_model_spec(text)
    assert (spec.kind, spec.orders, spec.name) == (kind, orders, name)
    assert len(MODEL_FORMS[kind][1]) == len(orders)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("bj:2,1", r"bj takes 5 non-negative integers NB,NC,ND,NF,NK \(nb, nc, nd, nf, nk\), e.g. bj:2,1,1,2,3"),
        ("oe:2,-2,3", r"oe takes 3 non-negative integers NB,NF,NK"),
        ("oe:2;2;3", r"oe takes 3 non-negative integers NB,NF,NK"),
        ("ss:2,2", r"write one of arx:NA,NB,NK, oe:NB,NF,NK, armax:NA,NB,NC,NK, bj:NB,NC,ND,NF,NK"),
        ("tf:2,2", r"tf takes NP >= 1 poles and NZ < NP zeros"),
        ("proc:P4D", r"cannot read the model 'proc:P4D': cannot read the process model 'P4D'"),
        ("oe223", r"write one of"),
    ],
)
def test_a_model_written_wrongly_is_refused_with_the_correct_form(text, message, capsys):
    with pytest.raises(arxid.OrderError, match=message):
        parse_model_spec(text)
    with pytest.raises(arxid.OrderError, match=message):
        arxid.analyse(_data(n=400), model=text)
    # the command line says the same before it reads any data
    assert main(["diagnose", "missing.csv", "--output", "y", "--inputs", "u", "--model", text]) == 2
    assert "cannot read the model" in capsys.readouterr().err


def test_a_model_and_orders_are_refused_together(capsys):
    with pytest.raises(arxid.OrderError, match="not both"):
        arxid.analyse(_data(n=400), model="oe:1,1,1", orders=(1, 1, 1))
    assert main(["diagnose", "missing.csv", "--output", "y", "--inputs", "u", "--model", "oe:1,1,1", "--na", "2"]) == 2
    assert "not both" in capsys.readouterr().err


def test_a_fitted_model_is_analysed_as_given():
    data = _data()
    est, val = data.split(0.7)
    fitted = arxid.oe(est, 2, 2, 3)
    a = arxid.analyse(data, model=fitted, max_steps=1)
    b = arxid.analyse(data, model="oe:2,2,3", max_steps=1)
    assert a.model is fitted and a.choice.reason.startswith("the model was given")
    np.testing.assert_array_equal(b.model.parameters_, fitted.parameters_)
    assert a.diagnosis.rms_sim_val == b.diagnosis.rms_sim_val == fitted.rms(val, None)
    # the comparison, where-it-fails and the frequency check are the given model's
    assert a.comparison.names[0] == "OE(2,2,3)" and a.comparison.rms[0] == fitted.rms(val, None)
    assert a.failures[0].rms == pytest.approx(fitted.rms(val, None), rel=1e-12)
    assert a.frequency[0].model_name == "OE(2,2,3)"
    # nothing is missing from the right structure: the ladder stays at the start
    assert a.missing_effect is None and len(a.ladder) == 1


def test_residual_tests_say_what_they_test_for_each_model_class():
    data = _data(coloured=True)
    oe = arxid.analyse(data, model="oe:2,2,3", max_steps=0)
    bj = arxid.analyse(data, model="bj:2,1,1,2,3", max_steps=0)
    armax = arxid.analyse(data, model="armax:2,2,2,3", max_steps=0)
    # OE leaves the coloured noise in its residual: not white, and that is allowed
    rt = oe.residual_tests
    assert not rt.is_white and not rt.whiteness_expected and rt.ljung_box_dof == 25
    assert "an output-error model allows" in rt.whiteness_text
    assert rt.independent["u1"]  # the test that judges an OE model passes for the right structure
    # BJ models the noise: its residual is white, and the Ljung-Box dof count its noise parameters
    assert bj.residual_tests.whiteness_expected and bj.residual_tests.is_white
    assert bj.residual_tests.ljung_box_dof == 25 - 2
    assert armax.residual_tests.ljung_box_dof == 25 - 4
