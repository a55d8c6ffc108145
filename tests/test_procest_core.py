"""procest's refinement in the Rust core: its exact ZOH simulation (fractional dead times) against
the Python one, its optimum against scipy's ``least_squares`` on the same residual, its bounds, and
process models of several inputs fitted jointly. Data simulated with an exact zero-order hold and
10 % output noise unless said otherwise; tolerances are stated per test."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from scipy.optimize import least_squares

import arxid
from arxid._base import _core
from arxid.exceptions import ArxidWarning, OrderError
from arxid.models.process_models import parse_process
from arxid.models.srivc import output_error
from test_tfest import record, simulate

STRUCTURES = {
    "P1D": {"K": 2.0, "Tp1": 0.7, "Td": 0.137},
    "P2DU": {"K": 1.5, "Tw": 0.5, "Zeta": 0.3, "Td": 0.23},
    "P3Z": {"K": -0.8, "Tp1": 1.0, "Tp2": 0.5, "Tp3": 0.2, "Tz": 0.3},
    "P1DI": {"K": 0.8, "Tp1": 0.4, "Td": 0.12},
    "P3DUZ": {"K": 1.2, "Tw": 0.3, "Zeta": 0.7, "Tp3": 0.9, "Tz": -0.2, "Td": 0.071},
    "P2D": {"K": 1.0, "Tp1": 0.5, "Tp2": 0.5, "Td": 0.3},  # a double pole
}


def core_simulate(u, segments, ts, names, params):
    sts = [parse_process(n) for n in names]
    x = np.concatenate([[p[k] for k in st.parameter_names] for st, p in zip(sts, params)])
    return _core.procest_simulate(np.ascontiguousarray(u), segments, ts, [st.core_spec for st in sts], x)


@pytest.mark.parametrize("name", list(STRUCTURES))
def test_core_simulation_agrees_with_the_python_exact_zoh(name):
    """The core's sample of each structure (fractional dead time, integrator, zero, underdamped,
    double pole) simulates as the Python exact ZOH (zoh_matrices) to 1e-12 of the output's size,
    in two segments around a gap."""
    rng = np.random.default_rng(3)
    ts, n = 0.05, 800
    u = np.sign(rng.standard_normal(n // 4)).repeat(4).reshape(-1, 1)
    seg = [(0, 350), (360, n)]
    st = parse_process(name)
    num, den, tau = st.transfer(STRUCTURES[name])
    err, _ = output_error(np.zeros(n), u, ts, [den / den[0]], [num / den[0]], [tau], seg)
    ours = core_simulate(u, seg, ts, [name], [STRUCTURES[name]])
    ok = np.isfinite(err)
    assert np.array_equal(ok, np.isfinite(ours))
    assert np.max(np.abs(ours[ok] + err[ok])) <= 1e-12 * np.max(np.abs(err[ok]))


def test_core_simulation_sums_the_inputs():
    """Two inputs with their own structures: the sum of their single-input simulations (exactly)."""
    rng = np.random.default_rng(4)
    u = np.sign(rng.standard_normal((300, 2))).repeat(3, axis=0)
    seg = [(0, 900)]
    both = core_simulate(u, seg, 0.1, ["P1D", "P2DU"], [STRUCTURES["P1D"], STRUCTURES["P2DU"]])
    one = core_simulate(u[:, [0]], seg, 0.1, ["P1D"], [STRUCTURES["P1D"]])
    two = core_simulate(u[:, [1]], seg, 0.1, ["P2DU"], [STRUCTURES["P2DU"]])
    np.testing.assert_allclose(both, one + two, rtol=0, atol=1e-13)


def refine_both(data, name, x0, lower, upper):
    """The core's refinement and scipy's least_squares (trust-region reflective) from the same start."""
    st = parse_process(name)
    seg = [(0, data.n_samples)]
    u = np.ascontiguousarray(data.u)
    x, _, resid, it, _, converged, on_bound = _core.procest_refine(
        data.y, u, seg, data.ts, [st.core_spec], np.asarray(x0, float), np.asarray(lower), np.asarray(upper)
    )
    lo = np.maximum(
        lower,
        [1e-6 * data.ts if n.startswith("T") and n != "Tz" and n != "Td" else -np.inf for n in st.parameter_names],
    )

    def res(p):
        return data.y - _core.procest_simulate(u, seg, data.ts, [st.core_spec], p)

    ref = least_squares(res, x0, bounds=(lo, upper), x_scale="jac", xtol=1e-12, ftol=1e-12, gtol=1e-12)
    return x, resid, it, converged, on_bound, ref


@pytest.mark.parametrize("seed", [0, 1])
def test_core_refinement_reaches_scipys_optimum(seed):
    """P2DU with a fractional dead time, 10 % noise, started 20 % off: the core's projected
    Levenberg-Marquardt and scipy's trust-region reflective least squares reach the same optimum,
    parameters within 1e-5 relative and sums of squares within 1e-9 relative."""
    data, _ = record([1.5], [0.25, 0.3, 1.0], 0.05, 2000, 10, tau=0.23, seed=seed)
    x0 = np.array([1.5, 0.5, 0.3, 0.23]) * [1.2, 0.8, 1.2, 0.8]
    inf = np.inf
    x, resid, it, converged, on_bound, ref = refine_both(data, "P2DU", x0, [-inf, 0, 0, 0], [inf, inf, inf, 1.0])
    assert converged and not any(on_bound) and it < 30
    np.testing.assert_allclose(x, ref.x, rtol=1e-5)
    assert resid @ resid == pytest.approx(2 * ref.cost, rel=1e-9)


def test_core_refinement_stops_on_its_bounds():
    """The unconstrained optimum outside the box: Td = 0.47 s capped at 0.3 s, and Zeta = 0.3 held
    at >= 0.45: each ends exactly on its bound, at scipy's bounded optimum (parameters within 1e-5
    relative)."""
    data, _ = record([2.0], [3.0, 1.0], 0.1, 1500, 10, tau=0.47, seed=0)
    inf = np.inf
    x, _, _, converged, on_bound, ref = refine_both(data, "P1D", [1.5, 2.0, 0.1], [-inf, 0, 0], [inf, inf, 0.3])
    assert x[2] == 0.3 and on_bound == [False, False, True] and converged
    np.testing.assert_allclose(x, ref.x, rtol=1e-5)
    data, _ = record([1.5], [0.25, 0.3, 1.0], 0.05, 2000, 10, tau=0.23, seed=1)
    x, _, _, _, on_bound, ref = refine_both(
        data, "P2DU", [1.4, 0.55, 0.6, 0.2], [-inf, 0, 0.45, 0], [inf, inf, inf, 1.0]
    )
    assert x[2] == 0.45 and on_bound == [False, False, True, False]
    np.testing.assert_allclose(x, ref.x, rtol=1e-5)


def test_procest_bounds_and_max_delay_are_kept_and_said():
    """procest itself: max_delay = 0.3 s under a 0.47 s dead time ends on 0.3 s with a warning that
    names Td; bounds={"Zeta": (0.45, 2)} under Zeta = 0.3 ends on 0.45."""
    data, _ = record([2.0], [3.0, 1.0], 0.1, 1500, 10, tau=0.47, seed=0)
    with pytest.warns(ArxidWarning, match="Td ended on a bound"):
        m = arxid.procest(data, "P1D", max_delay=0.3)
    assert m.parameter_dict()["Td"][0] == 0.3 and m.parameters_on_bound_ == ["Td"]
    data, _ = record([1.5], [0.25, 0.3, 1.0], 0.05, 2000, 10, tau=0.23, seed=1)
    with pytest.warns(ArxidWarning, match="Zeta"):
        m = arxid.procest(data, "P2DU", bounds={"Zeta": (0.45, 2.0)})
    assert m.parameter_dict()["Zeta"][0] == 0.45


def two_input_record(seed, n=3000, noise=0.1):
    """u1 → 2 e^{-0.12 s}/(1 + 1.0 s); u2 → 1.5 e^{-0.335 s}/(1 + 2·0.3·0.5 s + (0.5 s)²); ts = 0.05 s."""
    rng = np.random.default_rng(seed)
    ts = 0.05
    u1 = np.sign(rng.standard_normal(n // 10)).repeat(10)
    u2 = np.sign(rng.standard_normal(n // 7 + 1)).repeat(7)[:n]
    y0 = simulate([2.0], [1.0, 1.0], ts, 0.12, u1) + simulate([1.5], [0.25, 0.3, 1.0], ts, 0.335, u2)
    return arxid.IOData(y0 + noise * np.std(y0) * rng.standard_normal(n), np.column_stack([u1, u2]), ts=ts)


@pytest.mark.parametrize("seed", [0, 1])
def test_two_inputs_each_with_its_own_process_model(seed):
    """P1D on u1 (K = 2, Tp1 = 1 s, Td = 0.12 s) and P2DU on u2 (K = 1.5, Tw = 0.5 s, Zeta = 0.3,
    Td = 0.335 s = 6.7 samples), 10 % noise: gains and time constants within 3 %, dead times
    within 0.1 sample (0.005 s), fitted jointly."""
    m = arxid.procest(two_input_record(seed), ["P1D", "P2DU"])
    assert list(m.parameter_dict()) == ["K(u1)", "Tp1(u1)", "Td(u1)", "K(u2)", "Tw(u2)", "Zeta(u2)", "Td(u2)"]
    p1, p2 = m.parameter_dict(input="u1"), m.parameter_dict(input=1)
    assert list(p1) == ["K", "Tp1", "Td"] and list(p2) == ["K", "Tw", "Zeta", "Td"]
    for p, truth in ((p1, {"K": 2.0, "Tp1": 1.0}), (p2, {"K": 1.5, "Tw": 0.5, "Zeta": 0.3})):
        for k, v in truth.items():
            assert p[k][0] == pytest.approx(v, rel=0.03), k
    assert p1["Td"][0] == pytest.approx(0.12, abs=0.005)
    assert p2["Td"][0] == pytest.approx(0.335, abs=0.005)
    assert m.structure_name() == "P1D,P2DU" and m.delays_ == pytest.approx((p1["Td"][0], p2["Td"][0]))


def test_one_structure_string_for_every_input():
    """ "P1D" for both inputs of 2 e^{-0.12 s}/(1 + s) and 3 e^{-0.335 s}/(1 + 0.5 s), noise-free:
    every parameter within 1e-4 relative; a count of structures other than the inputs' is refused."""
    rng = np.random.default_rng(5)
    ts, n = 0.05, 2000
    u = np.sign(rng.standard_normal((n // 8, 2))).repeat(8, axis=0)
    y = simulate([2.0], [1.0, 1.0], ts, 0.12, u[:, 0]) + simulate([3.0], [0.5, 1.0], ts, 0.335, u[:, 1])
    data = arxid.IOData(y, u, ts=ts)
    m = arxid.procest(data, "P1D")
    np.testing.assert_allclose(m.continuous_parameters_, [2.0, 1.0, 0.12, 3.0, 0.5, 0.335], rtol=1e-4)
    with pytest.raises(OrderError, match="one per input"):
        arxid.procest(data, ["P1D"] * 3)


def test_gaps_and_experiments_and_bad_bounds():
    """P1D (K = 2, Tp1 = 3 s, Td = 0.47 s), 10 % noise, with a NaN gap in the output: the core
    simulates each run from rest, K and Tp1 within 3 %, Td within 0.1 sample; empty bounds are
    refused with the parameter named."""
    data, _ = record([2.0], [3.0, 1.0], 0.1, 2000, 10, tau=0.47, seed=3)
    y = data.y.copy()
    y[900:940] = np.nan
    gapped = arxid.IOData(y, data.u, ts=0.1)
    p = arxid.procest(gapped, "P1D").parameter_dict()
    assert p["K"][0] == pytest.approx(2.0, rel=0.03) and p["Tp1"][0] == pytest.approx(3.0, rel=0.03)
    assert p["Td"][0] == pytest.approx(0.47, abs=0.01)
    with pytest.raises(arxid.ArxidError, match="Tp1 has no admissible value"):
        arxid.procest(data, "P1D", bounds={"Tp1": (5.0, 1.0)})
    with pytest.raises(arxid.ArxidError, match="no parameter 'Tw'"):
        arxid.procest(data, "P1D", bounds={"Tw": (0.0, 1.0)})


def test_core_errors_are_typed():
    """Wrong parameter counts, impossible structures and mismatched lengths come back as arxid
    errors, not panics."""
    u = np.ones((50, 1))
    with pytest.raises(arxid.DataError, match="parameters"):
        _core.procest_simulate(u, [(0, 50)], 0.1, [(1, False, False, False, True)], np.ones(2))
    with pytest.raises(OrderError, match="1, 2 or 3 poles"):
        _core.procest_simulate(u, [(0, 50)], 0.1, [(4, False, False, False, False)], np.ones(5))
    with pytest.raises(OrderError, match="underdamped"):
        _core.procest_simulate(u, [(0, 50)], 0.1, [(1, False, True, False, False)], np.ones(3))
    with pytest.raises(arxid.DataError, match="rows"):
        _core.procest_refine(
            np.zeros(40), u, [(0, 40)], 0.1, [(1, False, False, False, False)], np.ones(2), np.zeros(2), np.ones(2)
        )


_LONG_REFINEMENT = textwrap.dedent(
    """
    import os, signal, threading, time
    import numpy as np
    from arxid._base import _core
    n = 3_000_000
    rng = np.random.default_rng(0)
    u = np.sign(rng.standard_normal((n // 10, 1))).repeat(10, axis=0)
    y = rng.standard_normal(n)
    spec = [(3, True, True, False, True)]  # P3DUZ: 6 parameters
    x0 = np.array([1.0, 0.5, 0.5, 1.0, 0.1, 0.05])
    lo, hi = np.array([-np.inf, 0, 0, 0, -np.inf, 0]), np.array([np.inf] * 5 + [1.0])
    sent = []
    def interrupt():
        sent.append(time.monotonic())
        os.kill(os.getpid(), signal.SIGINT)
    threading.Timer(1.0, interrupt).start()
    try:
        _core.procest_refine(y, u, [(0, n)], 0.01, spec, x0, lo, hi, max_iterations=10_000)
        print("finished", flush=True)
    except KeyboardInterrupt:
        print("interrupted", time.monotonic() - sent[0], flush=True)
    """
)


@pytest.mark.timed  # a latency bound: run alone (make test runs these after the parallel run)
def test_ctrl_c_stops_the_core_refinement_promptly():
    """A refinement on 3 million samples (each simulation tens of milliseconds) interrupted after
    1 s: KeyboardInterrupt within 0.5 s (the core looks at the flag before every simulation)."""
    proc = subprocess.run(
        [sys.executable, "-W", "ignore", "-c", _LONG_REFINEMENT],
        capture_output=True,
        text=True,
        timeout=300,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    word, *latency = proc.stdout.split()
    assert word == "interrupted" and proc.returncode == 0, proc.stdout + proc.stderr
    assert float(latency[0]) < 0.5, latency


def test_an_iteration_cap_is_said():
    """max_iterations=1 stops the refinement before it settles: the model says so and warns."""
    data, _ = record([1.5], [0.25, 0.3, 1.0], 0.05, 1500, 10, tau=0.23, seed=2)
    with pytest.warns(ArxidWarning, match="max_iterations"):
        m = arxid.procest(data, "P2DU", max_iterations=1)
    assert not m.converged_ and m.iterations_ == 1
