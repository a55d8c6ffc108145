"""``import arxid`` and ``arxid --help`` stay light: the public names load on first use, the command
line imports what a command runs when it runs, and the analysis of a short record does not import
scipy.signal or scipy.stats. The lazy names are the ones type checkers see."""

from __future__ import annotations

import ast
import importlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import arxid

INIT = Path(arxid.__file__)


def modules_after(code: str) -> set[str]:
    """The modules a fresh interpreter holds after running ``code``."""
    probe = code + "\nimport sys\nloaded = sorted(sys.modules)\nimport json\nprint(json.dumps(loaded))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def type_checked_names(init: Path) -> dict[str, str]:
    """Each name the ``if TYPE_CHECKING:`` block of a package's ``__init__.py`` imports, and its module."""
    tree = ast.parse(init.read_text())
    guarded = next(n for n in tree.body if isinstance(n, ast.If) and getattr(n.test, "id", "") == "TYPE_CHECKING")
    return {
        alias.name: node.module
        for node in guarded.body
        if isinstance(node, ast.ImportFrom) and node.module
        for alias in node.names
    }


def test_the_lazy_names_are_the_names_type_checkers_see():
    assert {name: "arxid." + module for name, module in type_checked_names(INIT).items()} == arxid._PUBLIC
    for name in arxid.__all__:
        assert getattr(arxid, name) is not None


@pytest.mark.parametrize("package", ["models", "data", "selection", "frequency_domain"])
def test_a_subpackage_loads_its_names_on_first_use(package):
    module = importlib.import_module(f"arxid.{package}")
    assert type_checked_names(Path(module.__file__)) == module._PUBLIC
    assert sorted(module._PUBLIC) == sorted(module.__all__)
    for name in module.__all__:
        value = getattr(module, name)
        assert value is getattr(importlib.import_module(f"arxid.{package}.{module._PUBLIC[name]}"), name)
    assert set(module.__all__) <= set(dir(module))
    with pytest.raises(AttributeError, match="has no attribute 'nothing'"):
        module.nothing  # noqa: B018


def test_import_arxid_and_help_import_neither_numpy_nor_the_pipeline():
    light = modules_after("import arxid")
    assert "numpy" not in light and "arxid.selection.search" not in light
    assert "signal" not in light  # a library leaves Ctrl-C alone (arxid._base.launch)
    cli = "import sys\nfrom arxid.analysis.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n    pass"
    helped = modules_after(cli)
    assert not {"numpy", "scipy", "arxid._base._core", "arxid.analysis.pipeline"} & helped
    assert "importlib.metadata" not in light | helped  # the version is read when asked


def test_the_version_is_read_when_asked():
    from importlib.metadata import version

    out = subprocess.run(
        [sys.executable, "-m", "arxid.analysis.cli", "--version"], capture_output=True, text=True, check=True
    )
    assert out.stdout == f"arxid {version('arxid')}\n" and out.stderr == ""
    assert arxid.__version__ == version("arxid")


def test_a_name_loads_its_module_and_the_fleet_fits_load_on_demand():
    loaded = modules_after("import arxid\narxid.IOData")
    assert "arxid.data.iodata" in loaded and "arxid.selection.search" not in loaded
    fits = modules_after("from arxid.models.many_logs import logs_fitting\nlogs_fitting('client=')")
    assert "arxid.fleet" in fits


def test_a_short_analysis_imports_neither_scipy_signal_nor_scipy_stats():
    code = (
        "import warnings, arxid\n"
        "warnings.simplefilter('ignore')\n"
        "d = arxid.datasets.thrust_stand(seed=0, duration=20.0, ts=0.01)\n"
        "arxid.analyse(d, progress=False)"
    )
    loaded = modules_after(code)
    assert "arxid.diagnosis.ladder" in loaded  # the analysis ran
    assert "scipy.signal" not in loaded and "scipy.stats" not in loaded
    assert "arxid.fleet" not in loaded  # the many logs' modules load for many logs


def test_a_name_spelt_as_its_module_stays_the_name():
    # the submodules imported first, as another path imports them: the package still names the functions
    code = (
        "import arxid.selection.refine, arxid.models.iv, arxid.models.tfest\n"
        "import arxid.selection as s, arxid.models as m\n"
        "print(callable(s.refine) and callable(m.iv) and callable(m.tfest), s.refine.__module__, m.iv.__module__)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["True", "arxid.selection.refine", "arxid.models.iv"]


def test_diagnose_on_a_short_file_imports_only_the_models_it_fits():
    code = "from arxid.analysis import cli\nfrom arxid.analysis.pipeline import analyse\ncli.build_parser('diagnose')"
    loaded = modules_after(code)
    assert "arxid.models.arx_model" in loaded
    unused = {
        "arxid.models.process_models",  # --model proc: imported when fitted
        "arxid.models.tfest",
        "arxid.models.continuous",  # to_control(continuous=True)
        "arxid.data.logs",  # lists of logs
        "arxid.selection.refine",  # sweep(refine="oe")
        "arxid.frequency_domain._step",
        "arxid.frequency_domain._tf_fit",
    }
    assert not unused & loaded


def test_the_program_leaves_its_objects_to_the_exit_and_a_library_keeps_them_collectable():
    probe = (
        "import gc, sys\n"
        "sys.argv[0] = {argv0!r}\n"
        "from arxid._base.launch import leave_to_exit\n"
        "before = gc.get_freeze_count()\n"
        "leave_to_exit()\n"
        "print(before == 0, gc.get_freeze_count() > 0)"
    )
    for argv0, frozen in (("/usr/bin/arxid", "True"), ("my_script.py", "False")):
        out = subprocess.run([sys.executable, "-c", probe.format(argv0=argv0)], capture_output=True, text=True)
        assert out.stdout.split() == ["True", frozen], out.stderr


def test_a_diagnose_in_text_imports_what_it_runs(tmp_path):
    """The modules deferred for ``arxid diagnose`` on a small file (issue 42, part 5) stay deferred:
    json (for --json and to_json), numpy.typing (annotations only), numpy.ma (numpy's unique,
    quantile and median import it: ``arxid._base.order_statistics``), statistics (the normal
    quantile is its accelerator's), and no frozen dataclass on the way compiles its methods
    (``arxid._base.records``: half the import time when they did)."""
    d = arxid.datasets.thrust_stand(seed=0, duration=5.0, ts=0.01)
    path = tmp_path / "thrust_stand.csv"
    columns = np.column_stack([d.y, d.u[:, 0], d.extra["vbat"]])
    np.savetxt(path, columns, fmt="%.9g", delimiter=",", header="thrust,pwm,vbat", comments="")
    code = (
        "import contextlib, dataclasses, io, sys\n"
        "from arxid.analysis.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()) as out:\n"
        f"    code = main(['diagnose', {str(path)!r}, '--output', 'thrust', '--inputs', 'pwm', '--extra', 'vbat',"
        " '--ts', '0.01', '--no-progress'])\n"
        "assert code == 0 and 'thrust' in out.getvalue(), out.getvalue()\n"
        "compiled = sorted(f'{c.__module__}.{c.__qualname__}' for name, m in list(sys.modules.items())"
        " if name.startswith('arxid') for c in vars(m).values() if isinstance(c, type) and c.__module__ == name"
        " and dataclasses.is_dataclass(c) and c.__dataclass_params__.frozen)\n"
        "print(compiled)"
    )
    probe = code + "\nloaded = sorted(sys.modules)\nimport json\nprint(json.dumps(loaded))"
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    *_, compiled, loaded = out.stdout.strip().splitlines()
    assert "arxid.diagnosis.ladder" in json.loads(loaded)  # the diagnosis ran
    assert not {"json", "numpy.typing", "numpy.ma", "statistics"} & set(json.loads(loaded))
    assert compiled == "[]"


def test_the_program_imports_without_collecting_and_collects_after_its_start():
    probe = (
        "import gc, sys\n"
        "sys.argv[0] = {argv0!r}\n"
        "from arxid._base import launch\n"
        "paused = not gc.isenabled()\n"
        "launch.end_startup()\n"
        "print(paused, gc.isenabled(), gc.get_freeze_count() > 0)"
    )
    for argv0, paused in (("/usr/bin/arxid", ["True", "True", "True"]), ("my_script.py", ["False", "True", "False"])):
        out = subprocess.run([sys.executable, "-c", probe.format(argv0=argv0)], capture_output=True, text=True)
        assert out.stdout.split() == paused, out.stderr
