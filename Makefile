# One task runner: the README's two commands are `make demo` and `make test`.
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
export VIRTUAL_ENV := $(abspath $(VENV))
export PATH := $(abspath $(VENV))/bin:$(PATH)

.PHONY: setup develop demo test test-rust test-python fuzz bench lint typecheck clean wheel smoke docs

# Everything the venv needs, read from pyproject.toml (the one list): the build backend, the
# runtime dependencies and the `test` and `dev` extras (pinned ruff and mypy). Python < 3.11 has no
# tomllib; pip's vendored copy reads the file there.
REQUIREMENTS = $(PY) -c 'import sys; \
	exec("try:\n import tomllib\nexcept ImportError:\n from pip._vendor import tomli as tomllib"); \
	t = tomllib.load(open("pyproject.toml", "rb")); p = t["project"]; x = p["optional-dependencies"]; \
	print(" ".join(t["build-system"]["requires"] + p["dependencies"] + x["test"] + x["dev"]))'

# The extras that only some targets need (docs, release), installed on demand, each with its stamp.
EXTRA_REQUIREMENTS = $(PY) -c 'import sys; \
	exec("try:\n import tomllib\nexcept ImportError:\n from pip._vendor import tomli as tomllib"); \
	x = tomllib.load(open("pyproject.toml", "rb"))["project"]["optional-dependencies"]; \
	print(" ".join(r for e in sys.argv[1:] for r in x[e]))'

$(VENV)/.extra-%: $(VENV)/.installed pyproject.toml
	@echo "installing the $* tools into $(VENV)"
	@$(PIP) install -q $$($(EXTRA_REQUIREMENTS) $*)
	@touch $@

# The stamp depends on pyproject.toml: a changed dependency list reinstalls.
$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	@echo "setting up $(VENV) (pip: the build backend, numpy, scipy and the test and lint tools)"
	$(PIP) install -q --upgrade pip
	$(PIP) install -q $$($(REQUIREMENTS))
	touch $@

setup: $(VENV)/.installed

# Release build of the Rust core into python/arxid, only when a Rust source, the manifests or the
# venv changed (the .so is the stamp, so an unchanged tree builds nothing). cargo test (below)
# builds in its own profile (target/unit) and never touches the cdylib maturin owns in target/release.
CORE := python/arxid/_base/_core.abi3.so
# Every .rs file at any depth of the crate's concept folders (rust/<concept>/...).
RUST_SOURCES := Cargo.toml Cargo.lock $(shell find rust -name '*.rs')

develop: $(CORE)

$(CORE): $(VENV)/.installed $(RUST_SOURCES) pyproject.toml
	@echo "building the Rust core for Python (maturin, release: a few minutes from scratch on 2 cores, seconds to a minute after an edit) -> $(VENV)/develop.log"
	@rm -f python/arxid/_core*.so python/arxid/_base/_core*.so
	@$(VENV)/bin/maturin develop --release > $(VENV)/develop.log 2>&1 || { cat $(VENV)/develop.log; exit 1; }
	@touch $@

demo: develop
	$(VENV)/bin/arxid demo

# --lib: the unit tests only (there are no doctests or tests/*.rs); building the lib target as a
# dependency would rebuild the cdylib with other features than maturin's, and each would undo the other.
# --profile unit (Cargo.toml): release without LTO, more codegen units. The harness is compiled on
# every change and never shipped; its dependencies compile once for this profile (target/unit).
test-rust:
	@echo "building and running the Rust unit tests (cargo test, profile unit: a few minutes from scratch on 2 cores, seconds after)"
	@cargo test --profile unit --lib --quiet

# One BLAS thread: the tests' tall-skinny products run up to 10x slower when OpenBLAS threads
# compete for 2 shared cores (benchmarks keep the default, so numpy baselines are not handicapped).
# pytest-xdist runs the tests in one worker per core, a test file to a worker (its module fixtures
# made once); the tests marked `timed` (a latency or a duration bound) run after them, alone, so no
# other test competes for the cores while they measure. Both runs always run; either failing fails.
# Bytecode is written even where the environment says PYTHONDONTWRITEBYTECODE (pytest's rewritten
# test modules and arxid's own), into .venv/pycache so the tree stays clean: without it every pytest
# process compiles every module again (about 10 s of CPU each).
PYTEST_WORKERS ?= auto
test-python: develop
	@echo "running the Python tests (pytest, $(PYTEST_WORKERS) workers, then the timed tests alone)"
	@export OPENBLAS_NUM_THREADS=1 PYTHONPYCACHEPREFIX=$(CURDIR)/$(VENV)/pycache; unset PYTHONDONTWRITEBYTECODE; status=0; \
		$(PY) -m pytest -q -n $(PYTEST_WORKERS) --dist loadfile -m "not timed" || status=$$?; \
		$(PY) -m pytest -q -p no:xdist -m timed || status=$$?; \
		exit $$status

# The venv (pip: mostly the network and one core), the Rust unit tests and the Rust core side by
# side (cargo's lock on target/ runs the two compiles one after the other), each target's output
# shown when it ends; then the Python tests, alone on the cores.
test:
	@$(MAKE) --no-print-directory -j2 --output-sync=target setup test-rust develop
	@$(MAKE) --no-print-directory test-python

# The property-based suite at length (make test runs it derandomized with a few examples each).
fuzz: develop
	HYPOTHESIS_PROFILE=long $(PY) -m pytest -q tests/test_fuzz.py

bench: develop $(VENV)/.extra-bench
	$(PY) benches/sweep_vs_numpy.py
	$(PY) benches/sweep_miso.py
	$(PY) benches/fleet.py
	$(PY) benches/csv_read.py
	$(PY) benches/iv_sweep.py
	$(PY) benches/tfest.py
	$(PY) benches/analyse_scale.py
	$(PY) benches/checks_kernels.py
	$(PY) benches/analyse_fleet.py
	$(PY) benches/cli_start.py
	$(PY) benches/subspace.py

# The wheel (abi3: one file for CPython >= 3.10) for manylinux2014 (glibc 2.17; maturin links with
# zig) and the sdist, in dist/; the wheel's tag is checked and it is installed in a fresh venv
# without Rust, imported and used for a fit. The tools (the `release` extra) live in a temporary
# venv: this target touches no other venv.
wheel:
	@bash tests/smoke/wheel.sh

# The wheel installed in fresh venvs without cargo on PATH: base (numpy, scipy, threadpoolctl) and
# full (arxid[all]), side by side, each output shown when it ends. The wheel's own install check
# (make wheel) is left to the base run, which checks the same and more.
smoke:
	@ARXID_WHEEL_CHECK=0 bash tests/smoke/wheel.sh
	@$(MAKE) --no-print-directory -j2 --output-sync=target smoke-base smoke-full

.PHONY: smoke-base smoke-full
smoke-base smoke-full:
	@bash tests/smoke/run.sh dist/*.whl $(@:smoke-%=%)

# The documentation site in site/: the gallery scripts run first (their figures and pages go to
# docs/gallery/, git-ignored), then mkdocs builds with --strict (a warning fails the build).
docs: develop $(VENV)/.extra-docs
	@echo "running the gallery examples and building the site (mkdocs --strict) -> site/"
	@$(PY) docs/gallery/build.py
	@$(VENV)/bin/mkdocs build --strict --quiet

# OE and ARMAX against scipy least_squares, and SIPPY when it is installed (it is not a dependency:
# the row says "not installed" otherwise).
.PHONY: bench-pem
bench-pem: develop
	$(PY) benches/pem_vs_sippy.py

# Python: lint, format, the stub of the compiled core against the built module (hence `develop`),
# and the layers (import-linter's contracts in pyproject.toml, docs/architecture.md). Rust: the
# crate's layers and file sizes (tools/check_crate_layers.py, the same map), format and clippy
# (--release: it shares target/release with maturin's builds, but only their build scripts; its
# metadata-only check artifacts are its own, about a minute from clean, seconds when warm). Every
# step runs, in this order; lint fails at the end if any step failed, naming them.
LINT_STEPS = \
	"$(PY) -m ruff check python tests benches examples docs/gallery tools" \
	"$(PY) -m ruff format --check python tests benches examples docs/gallery tools" \
	"$(PY) -m mypy" \
	"$(PY) -m mypy.stubtest arxid._base._core" \
	"$(VENV)/bin/lint-imports --no-cache" \
	"$(PY) tools/check_crate_layers.py" \
	"cargo fmt --check" \
	"env $(MATURIN_PYO3_ENV) cargo clippy --release --all-targets --features python -- -D warnings"

# clippy sees pyo3 configured as maturin configured it (the interpreter file maturin writes and the
# extension-module flag). Otherwise pyo3's build scripts rerun, and clippy and the next maturin build
# (make wheel, make develop after an edit) each recompile pyo3, numpy and arxid: 90 s on 2 cores.
MATURIN_PYO3_ENV = $$(f=$$(ls $(CURDIR)/target/maturin/pyo3-config-*-abi3.txt 2>/dev/null | head -n 1); \
	[ -n "$$f" ] && echo PYO3_BUILD_EXTENSION_MODULE=1 PYO3_CONFIG_FILE=$$f)

lint: develop
	@failed=""; for step in $(LINT_STEPS); do \
		echo "+ $$step"; sh -c "$$step" || failed="$$failed$$step; "; \
	done; \
	if [ -n "$$failed" ]; then echo "make lint: failed: $$failed"; exit 1; fi

# mypy alone (it is also a step of `make lint`).
typecheck: develop
	$(PY) -m mypy

clean:
	rm -rf $(VENV) target python/arxid/_core*.so python/arxid/_base/_core*.so dist site docs/gallery/generated
