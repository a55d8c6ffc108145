"""A base install (numpy, scipy) works; each optional extra degrades the way the README promises.

A package is made "not installed" by a ``None`` entry in ``sys.modules``, which makes its import
raise ``ImportError`` exactly as on a machine without it.
"""

from __future__ import annotations

import io
import sys
import warnings

import numpy as np
import pytest

import arxid
import arxid._base.optional
from arxid import ArxidWarning, MissingDependencyError
from conftest import simulate_arx


@pytest.fixture
def data():
    rng = np.random.default_rng(3)
    u = rng.standard_normal(600)
    y = simulate_arx([-1.2, 0.5], [[0.8, 0.3]], [2], u, noise=0.01 * rng.standard_normal(600))
    return arxid.IOData(y, u, ts=0.01)


def _uninstall(monkeypatch, *modules):
    for name in list(sys.modules):
        if name.split(".")[0] in modules:
            monkeypatch.delitem(sys.modules, name)
    for name in modules:
        monkeypatch.setitem(sys.modules, name, None)


class _Terminal(io.StringIO):
    """stderr that says it is a terminal, so that sweep would draw its progress bar."""

    def isatty(self) -> bool:
        return True


def _sweep(data, **kwargs):
    return arxid.sweep(data, na=range(1, 4), nb=range(1, 3), nk=range(0, 4), validation=0.3, **kwargs)


def test_sweep_without_tqdm_has_no_bar_and_warns_once(data, monkeypatch):
    _uninstall(monkeypatch, "tqdm")
    monkeypatch.setattr(arxid._base.optional, "_warned", set())
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    quiet = _sweep(data, progress=False)
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        first = _sweep(data, progress=True)
        second = _sweep(data, progress=True)
    messages = [str(w.message) for w in seen if issubclass(w.category, ArxidWarning)]
    assert len(messages) == 1 and "pip install 'arxid[progress]'" in messages[0]
    assert terminal.getvalue() == ""  # no bar drawn
    np.testing.assert_array_equal(first.rms_val, quiet.rms_val)
    np.testing.assert_array_equal(second.rms_val, quiet.rms_val)


def test_sweep_with_tqdm_draws_a_bar_on_a_terminal(data, monkeypatch):
    pytest.importorskip("tqdm")
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    result = _sweep(data, progress=True)
    assert "arxid.sweep" in terminal.getvalue() and len(result) == 24


def test_plots_without_matplotlib_name_the_plot_extra(data, monkeypatch):
    model = arxid.arx(data, 2, 2, 2)
    result = _sweep(data, progress=False)
    _uninstall(monkeypatch, "matplotlib")
    with pytest.raises(MissingDependencyError, match=r"pip install 'arxid\[plot\]'"):
        result.plot()
    with pytest.raises(ImportError, match="matplotlib"):  # also an ImportError, as before
        arxid.compare(model, data).plot()


def test_to_control_without_python_control_names_the_control_extra(data, monkeypatch):
    model = arxid.arx(data, 2, 2, 2)
    _uninstall(monkeypatch, "control")
    with pytest.raises(MissingDependencyError, match=r"python-control.*pip install 'arxid\[control\]'"):
        model.to_control()
    num, den = model.to_scipy().num, model.to_scipy().den  # scipy is a base dependency: still works
    assert np.isfinite(num).all() and den[0] == 1.0


def test_every_extra_named_in_a_message_exists_in_pyproject():
    tomllib = pytest.importorskip("tomllib")
    from conftest import REPO

    extras = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    for module, extra in arxid._base.optional.EXTRAS.items():
        assert any(req.startswith((module, "python-" + module)) for req in extras[extra]), (module, extra)
        assert extra in extras and all(e in extras["all"] for e in extras[extra])
