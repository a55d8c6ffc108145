"""Is something nonlinear still missing that no candidate explains? :func:`nonlinear_dependence`.

The missing-effect diagnosis only finds effects in its catalogue. When none explains the error, the
residual may still depend on a signal in a way no candidate removes (backlash, hysteresis, a
nonlinearity of an unusual shape). This test says so, and where.

For each signal (the output and each input) and each lag near the model's own, a block of nonlinear
functions of the standardised signal s = (x − mean) / std at that lag — s², s³, |s| and sign(s) for
a signal that changes sign, and the sign of its first difference — is tested against the model's
regressors **plus** the signal's plain lags, from the first tested lag to ``LINEAR_CONTEXT`` beyond
the deepest (so a missing linear lag is not mistaken for a nonlinearity: a linear misfit at deeper
lags of a held input shows in the sign of its difference at the last tested lag) by the
added-variable F-test (:mod:`arxid.added_variable`). The p-values of all
blocks are Holm-corrected together; a signal is named when one of its lags passes ``alpha``.

The F-test assumes a white remainder. An unlogged slow disturbance (gusts, a drifting load) leaves a
coloured one, and then every function of the output that follows the disturbance's level looks
significant. So the regression is first prewhitened (Cochrane–Orcutt): an AR model of the base
fit's remainder (order by AIC, at most ``MAX_NOISE_ORDER``) filters the output, the regressors and
the tested blocks alike, and the tests run on the filtered rows (rows whose previous samples are
missing are left out). A white remainder gives order 0 and the plain test.
"""

from __future__ import annotations

import math

import numpy as np

from .._base import _core
from .._base.background import in_row_halves
from .._base.nested import nested_from_factor
from .._base.records import record
from ..data.iodata import IOData
from ..models.arx_model import ArxModel
from ..models.effects import compile_effects
from ..models.lagged import ar_factor
from ..models.regressors import max_lag, regression_rows, regressor_names, write_regressors
from .added_variable import AddedVariableTest, holm
from .candidates import changes_sign

__all__ = ["NonlinearDependence", "nonlinear_dependence", "dependence_sentence"]

#: Largest number of lags tested per signal.
MAX_LAGS = 3
#: Plain lags beyond the deepest tested one that stay in the regression.
LINEAR_CONTEXT = 3
#: Largest order of the AR model that prewhitens the regression.
MAX_NOISE_ORDER = 10


@record
class NonlinearDependence:
    """The residuals depend nonlinearly on ``signal`` at ``lags``.

    Attributes
    ----------
    signal : str
        Name of the signal (the output's or an input's).
    lags : tuple of int
        Lags (samples) where the dependence is significant, ascending.
    p_value : float
        Smallest Holm-corrected p-value over those lags.
    share : float
        Largest share of the residual energy the nonlinear functions at one lag remove (0..1).
    """

    signal: str
    lags: tuple[int, ...]
    p_value: float
    share: float

    def to_dict(self) -> dict:
        """``signal``, ``lags``, ``p_value``, ``share`` as plain JSON values.

        Returns
        -------
        dict
        """
        return {"signal": self.signal, "lags": list(self.lags), "p_value": self.p_value, "share": self.share}


def _plan(model: ArxModel, data: IOData) -> list[tuple[str, np.ndarray, tuple[int, ...]]]:
    """(signal name, samples, lags) to test: the output at lags 1.., each used input from its delay on."""
    plan = [(data.output_name, data.y, tuple(range(1, min(max(model.na_, 1), MAX_LAGS - 1) + 1)))]
    for i, name in enumerate(data.input_names):
        if model.nb_[i] > 0:
            k = model.nk_[i]
            plan.append((name, data.u[:, i], tuple(k + j for j in range(min(model.nb_[i] + 1, MAX_LAGS)))))
    return plan


def _model_lags(model: ArxModel, data: IOData) -> set[tuple[str, int]]:
    """(signal name, lag) of the model's plain regressors: the output at 1..na, each input from its
    delay on."""
    own = {(data.output_name, lag) for lag in range(1, model.na_ + 1)}
    for i, name in enumerate(data.input_names):
        own |= {(name, model.nk_[i] + j) for j in range(model.nb_[i])}
    return own


def _standardised(x: np.ndarray) -> np.ndarray:
    finite = x[np.isfinite(x)]
    return (x - finite.mean()) / (finite.std() or 1.0)


def _features(s: np.ndarray, rows: np.ndarray, lag: int, signed: bool, buffer: np.ndarray | None = None) -> np.ndarray:
    """The nonlinear functions of the standardised signal ``s`` at ``lag`` on ``rows``, one column
    each, written a block of rows at a time (in cache), into the start of ``buffer`` when given (one
    array for every lag: its pages are not mapped again for each)."""
    shape = (len(rows), 5 if signed else 3)
    out = np.empty(shape) if buffer is None else buffer[: shape[0] * shape[1]].reshape(shape)
    for lo in range(0, len(rows), DESIGN_ROWS):
        at, block = rows[lo : lo + DESIGN_ROWS], out[lo : lo + DESIGN_ROWS]
        first, last = int(at[0]), int(at[-1])
        if last - first == len(at) - 1:  # consecutive samples: slices, not gathers
            v, before = s[first - lag : last + 1 - lag], s[first - lag - 1 : last - lag]
        else:
            v, before = s[at - lag], s[at - lag - 1]
        np.multiply(v, v, out=block[:, 0])
        np.multiply(block[:, 0], v, out=block[:, 1])  # s³ as s² s (pow is 4x slower; 1 ulp apart)
        np.sign(v - before, out=block[:, 2])
        if signed:
            np.abs(v, out=block[:, 3])
            np.sign(v, out=block[:, 4])
    return out


def nonlinear_dependence(model: ArxModel, data: IOData, alpha: float = 0.01) -> tuple[NonlinearDependence, ...]:
    """Signals and lags where the model's residual still depends nonlinearly on the data.

    Parameters
    ----------
    model : ArxModel
        A fitted model.
    data : IOData
        Data to test on (the estimation data: the F-test assumes the residual of a fit on them).
    alpha : float
        Level of the Holm-corrected F-tests.

    Returns
    -------
    tuple of NonlinearDependence
        One per signal with a significant lag, strongest first (empty: no nonlinear dependence found).

    Examples
    --------
    >>> import numpy as np, arxid
    >>> rng = np.random.default_rng(0)
    >>> u = rng.uniform(-1, 1, 3000)
    >>> y = np.zeros(3000)
    >>> for t in range(1, 3000):
    ...     y[t] = 0.8 * y[t - 1] + np.tanh(3 * u[t - 1]) + 0.01 * rng.standard_normal()
    >>> data = arxid.IOData(y, u, ts=0.01)
    >>> [(d.signal, d.lags) for d in nonlinear_dependence(arxid.arx(data, 1, 1, 1), data)]
    [('u1', (1,))]
    """
    layout = compile_effects(model.effects, data, model.nb_, model.nk_)
    plan = _plan(model, data)
    deepest = max((max(lags) for _, _, lags in plan if lags), default=0) + LINEAR_CONTEXT
    first = max(model.first_lag_, max_lag(model.na_, layout), deepest)
    # The plain lags that are already model regressors stay out of the design (the same span; a
    # design without repeated columns is solved by Cholesky, not by a QR of every row), but they
    # still count in the F-tests' degrees of freedom, as they did when they were repeated.
    own = _model_lags(model, data)
    lin_all = [
        (name, x, lag) for name, x, lags in plan if lags for lag in range(min(lags), max(lags) + LINEAR_CONTEXT + 1)
    ]
    lin_specs = [(x, lag) for name, x, lag in lin_all if (name, lag) not in own]
    repeated = len(lin_all) - len(lin_specs)
    standard = {name: _standardised(x) for name, x, lags in plan if lags}
    specs = [(name, standard[name], lag, changes_sign(x)) for name, x, lags in plan for lag in lags]
    if not specs:
        return ()
    built = _design(data, model.na_, layout, first, lin_specs, specs, repeated)
    if built is None:
        return ()
    design, y_kept, kept = built
    # The fit on the rows as they are gives the remainder the noise model is fitted to; with a white
    # remainder (no filter) it is the fit the tests need too.
    base = AddedVariableTest(design, y_kept)
    a = _noise_model(base.e, kept)
    use = _previous_rows(kept, a.size)
    if a.size:
        del base  # its regressors are about to be filtered in place
        base = AddedVariableTest(_filtered(design, a, use, design), _filtered(y_kept, a, use, np.empty(len(use))))
    base.p += repeated
    del design  # the regressors of the tests (filtered in place)
    by_signal = kept[-1] - kept[0] == len(kept) - 1  # consecutive rows
    tested = (_tests_by_signal if by_signal else _tests_by_lag)(base, specs, a, kept, use)
    if not tested:
        return ()
    adj = holm(np.array([res.p_value for _, _, res in tested]))
    found: dict[str, list[tuple[int, float, float]]] = {}
    for (name, lag, res), p in zip(tested, adj, strict=True):
        if p < alpha:
            found.setdefault(name, []).append((lag, float(p), res.score**2))
    out = [
        NonlinearDependence(
            name, tuple(sorted(lag for lag, _, _ in hits)), min(p for _, p, _ in hits), max(s for _, _, s in hits)
        )
        for name, hits in found.items()
    ]
    return tuple(sorted(out, key=lambda d: d.p_value))


def _tests_by_lag(base: AddedVariableTest, specs: list, a: np.ndarray, kept: np.ndarray, use: np.ndarray) -> list:
    """(signal, lag, result) of each tested block: its functions on the kept rows, filtered as the
    regressors were (rows with gaps between them)."""
    buffer = np.empty(len(kept) * 5)  # the functions of one lag at a time (the tests keep none)
    tested = []
    for name, x, lag, signed in specs:
        z = _features(x, kept, lag, signed, buffer)
        res = base.test(_filtered(z, a, use, z))[0]
        if res is not None:
            tested.append((name, lag, res))
    return tested


def _tests_by_signal(base: AddedVariableTest, specs: list, a: np.ndarray, kept: np.ndarray, use: np.ndarray) -> list:
    """:func:`_tests_by_lag` for consecutive rows: filtering commutes with the lag, so each signal's
    functions are filtered once as series and each lag's block is a slice of them (no copy); a
    signal's lags are tested in one pass over the rows. The same numbers as filtering each block,
    operation for operation."""
    start = int(kept[use[0]]) if len(use) else int(kept[-1]) + 1  # the sample of the first filtered row
    tested = []
    buffer = np.empty(len(specs[0][1]) * 5)  # one signal's functions at a time (its pages mapped once)
    for name in dict.fromkeys(name for name, *_ in specs):
        mine = [(lag, x, signed) for n, x, lag, signed in specs if n == name]
        series = _filtered_functions(mine[0][1], a, mine[0][2], start - max(lag for lag, *_ in mine), buffer)
        got = base.tests([series[start - lag : start - lag + base.n] for lag, *_ in mine])
        tested += [(name, lag, res) for (lag, *_), (res, _) in zip(mine, got, strict=True) if res is not None]
    return tested


def _filtered_functions(s: np.ndarray, a: np.ndarray, signed: bool, first: int, buffer: np.ndarray) -> np.ndarray:
    """The nonlinear functions of ``s`` (as :func:`_features`) filtered by the noise model,
    ``g(t) = h(t) − Σ_j a_j h(t − 1 − j)``, for samples ``first`` on (rows before: NaN), written
    into the start of ``buffer``."""
    order, n = a.size, len(s)
    shape = (n, 5 if signed else 3)
    out = buffer[: shape[0] * shape[1]].reshape(shape)
    out[:first] = np.nan
    for lo in range(first, n, DESIGN_ROWS):
        hi = min(lo + DESIGN_ROWS, n)
        h = _features(s, np.arange(lo - order, hi), 0, signed)
        _filtered(h, a, np.arange(order, len(h)), out[lo:hi])
    return out


#: Rows of the design written at a time: a block stays in cache while its columns are written.
DESIGN_ROWS = 8192


def _design(data: IOData, na: int, layout, first: int, lin_specs: list, specs: list, repeated: int) -> tuple | None:
    """The model's regressors, the plain lags of the tested signals and a constant, written into one
    array (a block of rows at a time, column by column: stacked lists would hold several copies of
    a long record), on the rows where every tested feature exists too; None when too few rows are
    left (counting the ``repeated`` plain lags that are model regressors, left out of the array)."""
    rows = regression_rows(data, first)
    p = len(regressor_names(data.output_name, na, layout))
    design = np.empty((len(rows), p + len(lin_specs) + 1))
    ok = np.ones(len(rows), dtype=bool)
    # Finite samples give finite regressors (an output term that overflows is refused when compiled):
    # then no row is checked.
    check = not (np.isfinite(data.y).all() and np.isfinite(layout.u).all())

    def write(span: tuple[int, int]) -> None:
        for lo in range(span[0], span[1], DESIGN_ROWS):
            hi = min(lo + DESIGN_ROWS, span[1])
            at, block = rows[lo:hi], design[lo:hi]
            write_regressors(block, data, na, layout, at)
            a0, a1 = int(at[0]), int(at[-1])
            for j, (x, lag) in enumerate(lin_specs):
                if a1 - a0 == len(at) - 1:  # consecutive samples: a slice, not a gather
                    block[:, p + j] = x[a0 - lag : a1 + 1 - lag]
                else:
                    block[:, p + j] = x[at - lag]
            block[:, -1] = 1.0
            if not check:
                continue
            good = np.isfinite(block).all(axis=1) & np.isfinite(data.y[at])
            for _, x, lag, _signed in specs:  # the features are finite where the signal is, at lag and lag + 1
                good &= np.isfinite(x[at - lag]) & np.isfinite(x[at - lag - 1])
            ok[lo:hi] = good

    in_row_halves(write, len(rows), DESIGN_ROWS)  # the halves of the rows on two threads
    if ok.sum() <= design.shape[1] + repeated + 9:
        return None
    if not ok.all():
        design = design[ok]
    return design, data.y[rows][ok], rows[ok]


def _previous_rows(rows: np.ndarray, order: int) -> np.ndarray:
    """The positions in ``rows`` (ascending sample numbers) whose ``order`` previous samples are rows
    too; those samples are then the ``order`` rows just before (the rows are distinct and ascending,
    so ``rows[p] − rows[p − order] = order`` says exactly that), at positions p − 1 … p − order."""
    if order == 0:
        return np.arange(len(rows))
    return np.flatnonzero(rows[order:] - rows[:-order] == order) + order


def _runs(use: np.ndarray, size: int):
    """(position in ``use``, first, last + 1) of stretches of at most ``size`` consecutive
    positions of ``use``: the lagged values of a stretch are slices, not gathers."""
    breaks = np.flatnonzero(np.diff(use) != 1) + 1
    for lo, hi in zip(np.r_[0, breaks], np.r_[breaks, len(use)], strict=True):
        for at in range(int(lo), int(hi), size):
            first = int(use[at])
            yield at, first, first + min(size, int(hi) - at)


def _filtered(v: np.ndarray, a: np.ndarray, use: np.ndarray, out: np.ndarray) -> np.ndarray:
    """``v(t) − Σ_j a_j v(t − j)`` at the positions ``use`` (whose ``a.size`` previous positions are
    the previous samples), written to ``out`` in order (``out`` may be ``v`` itself: the filtered
    rows overwrite the first ones), by the Rust core. No coefficient: ``v`` itself (``use`` is then
    every position)."""
    if a.size == 0:
        if out is not v:
            out[: len(use)] = v[: len(use)]
        return out[: len(use)]
    work = v if out is v and v.flags.c_contiguous else np.array(v, order="C")
    runs = [(at, lo, hi) for at, lo, hi in _runs(use, max(len(use), 1))]
    _core.ar_filter_rows(work.reshape(len(work), -1), np.ascontiguousarray(a, dtype=float), runs)
    if out is not work:
        out[: len(use)] = work[: len(use)]
    return out[: len(use)]


def _lagged_factor(r: np.ndarray, rows: np.ndarray, order: int) -> np.ndarray:
    """R of [r(t−1) … r(t−P) | r(t)] over the positions whose ``order`` previous positions are the
    previous samples (:func:`_previous_rows`): the runs of consecutive samples, each from its
    ``order``-th position on (:func:`arxid.models.lagged.ar_factor`)."""
    breaks = np.flatnonzero(np.diff(rows) != 1) + 1
    runs = [(int(a), int(b)) for a, b in zip(np.r_[0, breaks], np.r_[breaks, len(rows)], strict=True)]
    return ar_factor(r, runs, order)[0]


def _noise_model(r: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Coefficients a of the Cochrane–Orcutt filter A(q) = 1 − Σ a_j q^-j of a regression whose
    least-squares remainder on ``rows`` is ``r``: its AR model, order by AIC up to
    ``MAX_NOISE_ORDER`` (empty for a white one, and when too few rows have their previous samples)."""
    keep = _previous_rows(rows, MAX_NOISE_ORDER)
    if keep.size <= 4 * MAX_NOISE_ORDER + 10:
        return np.zeros(0)
    now = r[keep]
    best_ic, a = math.log(max(float(np.mean(now * now)), 1e-300)), np.zeros(0)
    rss_all, coefs = nested_from_factor(_lagged_factor(r, rows, MAX_NOISE_ORDER))  # every order from one factor
    for p in range(1, MAX_NOISE_ORDER + 1):
        c = coefs[p]
        ic = math.log(max(float(rss_all[p]) / len(now), 1e-300)) + 2.0 * p / len(now)
        if ic < best_ic:
            best_ic, a = ic, c
    return a


def dependence_sentence(found: tuple[NonlinearDependence, ...]) -> str:
    """The plain sentence for a diagnosis in which no candidate is significant.

    Parameters
    ----------
    found : tuple of NonlinearDependence
        What :func:`nonlinear_dependence` returned.

    Returns
    -------
    str
        e.g. ``"the residuals still depend nonlinearly on u1 (lags 1, 2) but none of the
        candidates removes it"``; ``""`` when ``found`` is empty.
    """
    if not found:
        return ""
    where = " and ".join(
        f"{d.signal} (lag{'s' if len(d.lags) > 1 else ''} {', '.join(map(str, d.lags))})" for d in found
    )
    return f"the residuals still depend nonlinearly on {where} but none of the candidates removes it"
