"""Property-based tests (hypothesis): the oracle is a correct result or an ArxidError, never
anything else. ``make test`` runs the ``ci`` profile (derandomized, a modest number of examples);
``make fuzz`` runs the ``long`` profile (HYPOTHESIS_PROFILE=long). The CLI is fuzzed with hostile
files and flags in a subprocess: exit 2 with one line on stderr, within a time bound."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import arxid
from arxid.exceptions import ArxidError, ArxidWarning, DataError

settings.register_profile(
    "ci", max_examples=25, derandomize=True, deadline=None, suppress_health_check=[HealthCheck.too_slow]
)
settings.register_profile(
    "long",
    max_examples=int(os.environ.get("HYPOTHESIS_EXAMPLES", 2000)),
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow],
)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

_floats = st.floats(allow_nan=True, allow_infinity=True, width=64)
_finite = st.floats(-1e6, 1e6, allow_nan=False)


def _signal(draw, n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(n) * draw(st.sampled_from([1.0, 1e-3, 1e5]))


@st.composite
def _systems(draw):
    """Random data of a random ARX system, with the orders to fit."""
    n = draw(st.integers(40, 400))
    seed = draw(st.integers(0, 2**32 - 1))
    na, nb, nk = draw(st.integers(0, 3)), draw(st.integers(1, 3)), draw(st.integers(0, 3))
    u = _signal(draw, n, seed)
    rng = np.random.default_rng(seed + 1)
    y = np.zeros(n)
    a = rng.uniform(-0.4, 0.4, na)
    b = rng.standard_normal(nb)
    for t in range(max(na, nb + nk - 1), n):
        y[t] = -sum(a[i] * y[t - 1 - i] for i in range(na)) + sum(b[j] * u[t - nk - j] for j in range(nb))
    y += draw(st.sampled_from([0.0, 0.01, 1.0])) * rng.standard_normal(n)
    return arxid.IOData(y, u, ts=0.1), na, nb, nk


def _regressors(d: arxid.IOData, na: int, nb: int, nk: int) -> tuple[np.ndarray, np.ndarray]:
    """Φ and y built independently of arxid, rows from the largest lag on."""
    lag = max(na, nb + nk - 1)
    rows = range(lag, d.n_samples)
    phi = [[-d.y[t - i] for i in range(1, na + 1)] + [d.u[t - nk - j, 0] for j in range(nb)] for t in rows]
    return np.array(phi, dtype=float).reshape(len(rows), na + nb), d.y[lag:]


@given(
    y=hnp.arrays(np.float64, st.integers(0, 30), elements=_floats),
    u=st.one_of(hnp.arrays(np.float64, st.integers(0, 30), elements=_floats), st.none(), st.integers(), st.text()),
    ts=st.one_of(_floats, st.integers(-2, 2), st.none(), st.text(max_size=3)),
    names=st.one_of(st.none(), st.integers(), st.lists(st.text(max_size=3), max_size=3), st.text(max_size=3)),
    starts=st.one_of(st.none(), st.lists(st.integers(-3, 40), max_size=3), st.integers()),
)
def test_iodata_construction_gives_data_or_an_arxid_error(y, u, ts, names, starts):
    try:
        d = arxid.IOData(y, u, ts, input_names=names, experiment_starts=starts)
    except ArxidError as exc:
        assert str(exc)
        return
    assert d.n_samples == len(y) > 0 and d.ts > 0 and math.isfinite(d.ts)
    assert d.experiment_starts[0] == 0 and len(d.input_names) == d.n_inputs


@given(_systems())
def test_arx_agrees_with_lstsq_on_independently_built_regressors(system):
    d, na, nb, nk = system
    phi, y = _regressors(d, na, nb, nk)
    assume(phi.shape[0] > phi.shape[1] + 1)
    try:
        m = arxid.arx(d, na, nb, nk)
    except ArxidError:
        # Refused data must be (nearly) rank deficient for lstsq too.
        assert np.linalg.matrix_rank(phi) < phi.shape[1] or np.ptp(d.u) == 0
        return
    ref, *_ = np.linalg.lstsq(phi, y, rcond=None)
    scale = max(np.abs(ref).max(), 1.0)
    cond = np.linalg.cond(phi)
    assume(cond < 1e8)
    np.testing.assert_allclose(m.parameters_, ref, atol=1e-8 * scale * cond)


@given(_systems(), st.one_of(st.none(), st.integers(1, 500)))
def test_predict_agrees_with_a_reference_recursion(system, horizon):
    d, na, nb, nk = system
    try:
        m = arxid.arx(d, na, nb, nk)
    except ArxidError:
        return
    pred = m.predict(d, horizon)
    a, b = m.a, m.b[0]
    lag = max(na, nb + nk - 1)
    for t in sorted({lag, lag + 1, d.n_samples // 2, d.n_samples - 1}):
        if t < lag or t >= d.n_samples:
            continue
        c = lag - 1 if horizon is None else max(t - horizon, lag - 1)
        hist = list(d.y[: c + 1])
        for tau in range(c + 1, t + 1):
            ar = sum(a[i] * hist[tau - i] for i in range(1, len(a)))
            hist.append(-ar + sum(b[j] * d.u[tau - j, 0] for j in range(len(b))))
        if math.isfinite(hist[t]) and abs(hist[t]) < 1e12:
            assert pred[t] == pytest.approx(hist[t], rel=1e-7, abs=1e-9 * max(1.0, np.abs(d.y).max()))


@given(_systems())
def test_sweep_rows_agree_with_arx_on_the_same_rows(system):
    d, _, _, _ = system
    try:
        res = arxid.sweep(d, na=range(0, 3), nb=range(1, 3), nk=range(0, 3), progress=False)
    except ArxidError:
        return
    for i in range(len(res)):
        if res.errors[i] is not None:
            continue
        na, nb, nk = int(res.na[i]), int(res.nb[i, 0]), int(res.nk[i, 0])
        try:
            m = arxid.ArxModel(na=na, nb=nb, nk=nk).fit(d, first_lag=res.first_lag)
        except ArxidError:
            continue
        theta = res.parameters[i]
        # Both solve the same least-squares problem by different QR paths: they agree to the
        # conditioning of the regressor.
        cond = np.linalg.cond(_regressors(d, na, nb, nk)[0])
        tol = 1e-12 * cond * max(1.0, np.abs(theta).max())
        np.testing.assert_allclose(theta, m.parameters_, rtol=1e-9, atol=tol)


_JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-(2**70), 2**70) | _floats | st.text(max_size=5),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=5), children, max_size=3),
    max_leaves=8,
)


@pytest.fixture(scope="module")
def model_dict() -> dict:
    rng = np.random.default_rng(3)
    u = rng.standard_normal(300)
    y = np.convolve(u, [0, 0.5, 0.2])[:300] + 0.01 * rng.standard_normal(300)
    return arxid.arx(arxid.IOData(y, u, ts=0.1), 1, 2, 1, effects=["const"]).to_dict()


_CELL_VALUES = st.one_of(
    st.floats(allow_nan=False, allow_infinity=False, width=64),  # huge, tiny and subnormal values too
    st.sampled_from([0.0, -0.0, 1e308, -1e-308, 5e-324]),
)


@given(
    rows=st.lists(st.tuples(_CELL_VALUES, st.one_of(_CELL_VALUES, st.none())), min_size=1, max_size=40),
    eol=st.sampled_from(["\n", "\r\n", "\r"]),
    bom=st.booleans(),
    quote=st.booleans(),
    marker=st.sampled_from(["", "nan", "NaN", "NA", "null", " nan "]),
    blank=st.booleans(),
    final_eol=st.booleans(),
)
def test_csv_round_trips_every_value_with_any_line_ending(rows, eol, bom, quote, marker, blank, final_eol):
    """Values written with repr() read back bit for bit, whatever the line endings (LF, CRLF, a
    lone CR), a byte order mark, quoted cells, missing-sample markers and blank lines; one row is a
    file too."""
    import tempfile

    def cell(v):
        text = marker if v is None else repr(v)
        return f'"{text}"' if quote else text

    lines = ["y,u"] + [f"{cell(a)},{cell(b)}" for a, b in rows]
    if blank:
        lines.insert(2, "")
    text = eol.join(lines) + (eol if final_eol else "")
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "d.csv")
        with open(path, "wb") as fh:
            fh.write((b"\xef\xbb\xbf" if bom else b"") + text.encode())
        d = arxid.IOData.from_csv(path, output="y", inputs=["u"], ts=0.01)
    np.testing.assert_array_equal(d.y, [a for a, _ in rows])
    np.testing.assert_array_equal(d.u[:, 0], [np.nan if b is None else b for _, b in rows])


@settings(max_examples=10)
@given(
    seed=st.integers(0, 2**32 - 1),
    run=st.integers(2, 40),
    kind=st.sampled_from(["oe", "armax", "bj"]),
    initial=st.sampled_from(["zero", "estimate"]),
)
def test_pem_on_many_short_runs_between_nan_gaps_fits_or_says_why(seed, run, kind, initial):
    """Thousands of NaN gaps (runs of 2 to 40 samples, some shorter than the model's lags): a fit
    and its predictions, or an ArxidError; never another exception."""
    rng = np.random.default_rng(seed)
    n = 4000
    u = rng.standard_normal(n)
    y = np.convolve(u, [0.0, 0.5, 0.25])[:n] + 0.05 * rng.standard_normal(n)
    y[:: run + 1] = np.nan
    u[rng.integers(0, n, n // 50)] = np.nan
    d = arxid.IOData(y, u, ts=0.01)
    fits = {
        "oe": lambda: arxid.oe(d, 2, 1, 1, initial=initial),
        "armax": lambda: arxid.armax(d, 1, 2, 1, 1, initial=initial),
        "bj": lambda: arxid.bj(d, 2, 1, 1, 1, 1, initial=initial),
    }
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ArxidWarning)  # a stalled or unstable fit says so; allowed here
            m = fits[kind]()
    except ArxidError:
        return
    assert np.isfinite(m.parameters_).all()
    for horizon in (1, 5, None):
        p = m.predict(d, horizon, initial=initial)
        assert p.shape == (n,)


@settings(suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data(), value=_JSON_VALUES)
def test_model_json_round_trips_and_mutations_load_or_raise_data_error(model_dict, data, value):
    text = json.dumps(model_dict)
    assert arxid.ArxModel.from_json_text(text).to_dict() == model_dict
    mutated = json.loads(text)
    node = mutated
    keys = data.draw(st.lists(st.integers(0, 50), min_size=1, max_size=3))
    for depth, k in enumerate(keys):
        if isinstance(node, dict) and node:
            key = sorted(node)[k % len(node)]
        elif isinstance(node, list) and node:
            key = k % len(node)
        else:
            break
        if depth == len(keys) - 1 or not isinstance(node[key], (dict, list)):
            node[key] = value
            break
        node = node[key]
    try:
        m = arxid.ArxModel.from_json_text(json.dumps(mutated))
    except DataError:
        return
    # Whatever loads is a consistent model.
    assert len(m.parameters_) == m.n_params == len(m.regressor_names_)
    assert np.isfinite(m.parameters_).all()


# ---------------------------------------------------------------------------------------------- CLI
_CLI_DRIVER = textwrap.dedent(
    """
    import contextlib, io, json, sys, time
    from arxid.analysis.cli import main
    results = []
    for argv in json.loads(sys.argv[1]):
        err = io.StringIO()
        t = time.monotonic()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(argv)
            except SystemExit as exc:  # argparse's --help and the like
                code = exc.code
        results.append([code, err.getvalue(), time.monotonic() - t])
    print(json.dumps(results))
    """
)


@pytest.fixture(scope="module")
def hostile_files(tmp_path_factory) -> dict:
    root = tmp_path_factory.mktemp("hostile")
    rng = np.random.default_rng(0)
    u = rng.standard_normal(200)
    y = np.convolve(u, [0, 0.8])[:200]
    np.savez(root / "ok.npz", y=y, u=u, ts=0.1)
    good = "y,u\n" + "".join(f"{a},{b}\n" for a, b in zip(y, u))
    (root / "ok.csv").write_text(good)
    raw = (root / "ok.npz").read_bytes()
    files = {
        "truncated.npz": raw[: len(raw) // 2],
        "empty.npz": b"",
        "text.npz": b"y,u\n1,2\n",
        "zeros.npz": b"\0" * 4096,
        "bom_only.csv": b"\xef\xbb\xbf",
        "latin1.csv": "y,u\n1,é\n".encode("latin-1"),
        "nul.csv": b"y,u\n1,\x002\n3,4\n",
        "binary.csv": bytes(range(256)) * 4,
        "header_only.csv": b"y,u\n",
        "onerow.csv": b"y,u\n1,2\n",
        "bom.csv": b"\xef\xbb\xbf" + good.encode(),
        "cr_only.csv": good.replace("\n", "\r").encode(),
        "crlf.csv": good.replace("\n", "\r\n").encode(),
        "quoted.csv": ('"y","u"\n' + "".join(f'"{a}","{b}"\n' for a, b in zip(y, u))).encode(),
        "utf16.csv": good.encode("utf-16"),
        "decimal_comma.csv": ("y;u\n" + "".join(f"{a:.3f};{b:.3f}\n".replace(".", ",") for a, b in zip(y, u))).encode(),
        "huge.csv": ("y,u\n" + "".join(f"{a * 1e306!r},{b * 1e306!r}\n" for a, b in zip(y, u))).encode(),
        "tiny.csv": ("y,u\n" + "".join(f"{a * 1e-306!r},{b * 1e-306!r}\n" for a, b in zip(y, u))).encode(),
        "overflow.csv": b"y,u\n1e309,2\n3,4\n" * 50,
        "spaces_only.csv": b"y,u\n   \n \t \n",
        "only_newlines.csv": b"\n\n\r\n",
    }
    for name, content in files.items():
        (root / name).write_bytes(content)
    os.mkfifo(root / "fifo.csv")
    (root / "folder.csv").mkdir()
    times = "t,y,u\n" + "".join(f"{1e308 * (-1) ** (i + 1)},{a},{b}\n" for i, (a, b) in enumerate(zip(y, u)))
    (root / "time_overflow.csv").write_text(times)
    return {
        name: str(root / name) for name in [*files, "ok.npz", "ok.csv", "fifo.csv", "folder.csv", "time_overflow.csv"]
    }


# Files that must be read (and fitted): line endings, quotes, a byte order mark.
_GOOD = ("ok.npz", "ok.csv", "bom.csv", "cr_only.csv", "crlf.csv", "quoted.csv")
# Files that may be fitted or refused, but only with one line and no traceback (extreme values).
_EITHER = ("huge.csv", "tiny.csv")


def _bad_cases(f: dict) -> list[list[str]]:
    io = ["--output", "y", "--inputs", "u", "--ts", "0.1"]
    fit = ["fit", "--orders", "1,1,1"]
    cases = [[*fit, f[name], *io] for name in f if name not in (*_GOOD, *_EITHER, "time_overflow.csv")]
    cases += [
        [*fit, f["ok.csv"], "--output", "y", "--inputs", "u", "--ts", "1e308", "--effects", "time"],
        [*fit, f["ok.csv"], "--output", "y", "--inputs", "u", "--ts", "1e-12"],
        [*fit, f["ok.csv"], "--output", "y", "--inputs", "u", "--ts", "5e-324"],
        [*fit, f["ok.csv"], "--output", "y", "--inputs", "u", "--ts", "1e400"],
        [*fit, f["time_overflow.csv"], "--output", "y", "--inputs", "u", "--time", "t"],
        [*fit, "/dev/zero", *io],
        [*fit, "/nonexistent.csv", *io],
        [*fit, f["ok.csv"], *io, "--validation", f["onerow.csv"]],
        [*fit, f["ok.csv"], *io, "--validation", f["fifo.csv"]],
        ["sweep", f["ok.csv"], *io, "--nk", ""],
        ["sweep", f["ok.csv"], *io, "--na", "0:99999999999"],
        ["sweep", f["ok.csv"], *io, "--nb", "3:1"],
        ["sweep", f["ok.csv"], *io, "--nk", "-1"],
        ["sweep", f["ok.csv"], *io, "--horizon", "0"],
        ["sweep", f["ok.csv"], *io, "--horizon", "99999999999999999999999"],
        ["sweep", f["ok.csv"], "--output", "y", "--inputs", "u", "--ts", "nan"],
        ["sweep", f["ok.csv"], "--output", "y", "--inputs", "u", "--ts", "-1"],
        [*fit, f["ok.csv"], *io, "--bogus"],
        ["fit", f["ok.csv"], *io, "--orders", "1,x,1"],
        ["nonsense"],
        [],
    ]
    return cases


def _run_cli(cases: list[list[str]]) -> list:
    proc = subprocess.run(
        [sys.executable, "-c", _CLI_DRIVER, json.dumps(cases)], capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout)


def test_cli_refuses_hostile_files_and_flags_in_one_line_with_exit_2(hostile_files):
    cases = _bad_cases(hostile_files)
    for argv, (code, err, seconds) in zip(cases, _run_cli(cases)):
        assert code == 2, (argv, code, err)
        assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, (argv, err)
        assert seconds < 30, (argv, seconds)


def test_cli_reads_good_files_including_a_bom(hostile_files):
    io = ["--output", "y", "--inputs", "u", "--ts", "0.1", "--json"]
    cases = [["fit", "--orders", "1,1,1", hostile_files[name], *io] for name in _GOOD]
    for argv, (code, err, _) in zip(cases, _run_cli(cases)):
        assert code == 0, (argv, err)


def test_cli_on_huge_and_tiny_values_fits_or_says_why_in_one_line(hostile_files):
    io = ["--output", "y", "--inputs", "u", "--ts", "0.1"]
    cases = [["fit", "--orders", "1,1,1", hostile_files[name], *io] for name in _EITHER]
    cases += [["sweep", hostile_files[name], *io, "--na", "1:2", "--nb", "1:2", "--nk", "0:2"] for name in _EITHER]
    for argv, (code, err, _) in zip(cases, _run_cli(cases)):
        assert code in (0, 2), (argv, code, err)
        assert "Traceback" not in err and len(err.strip().splitlines()) <= 1, (argv, err)


def test_cli_names_absurd_sampling_times_and_decimal_commas(hostile_files):
    f = hostile_files
    cases = [
        [
            "fit",
            "--orders",
            "1,1,1",
            f["ok.csv"],
            "--output",
            "y",
            "--inputs",
            "u",
            "--ts",
            "1e308",
            "--effects",
            "time",
        ],
        ["fit", "--orders", "1,1,1", f["ok.csv"], "--output", "y", "--inputs", "u", "--ts", "1e-12"],
        ["fit", "--orders", "1,1,1", f["time_overflow.csv"], "--output", "y", "--inputs", "u", "--time", "t"],
        ["fit", "--orders", "1,1,1", f["decimal_comma.csv"], "--output", "y", "--inputs", "u", "--ts", "0.1"],
        ["fit", "--orders", "1,1,1", f["utf16.csv"], "--output", "y", "--inputs", "u", "--ts", "0.1"],
    ]
    wanted = ["longer than a day", "below 1 ns", "steps of time column 't' overflow", "decimal comma", "not a UTF-8"]
    for argv, (code, err, _), words in zip(cases, _run_cli(cases), wanted, strict=True):
        assert code == 2 and words in err, (argv, err)
