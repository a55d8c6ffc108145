# One task runner: the README's two commands are `make demo` and `make test`.
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
export VIRTUAL_ENV := $(abspath $(VENV))
export PATH := $(abspath $(VENV))/bin:$(PATH)

.PHONY: setup develop demo test test-rust test-python fuzz bench lint typecheck clean

# Everything the venv needs, read from pyproject.toml (the one list): the build backend, the
# runtime dependencies and the `test` and `dev` extras (pinned ruff and mypy). Python < 3.11 has no
# tomllib; pip's vendored copy reads the file there.
REQUIREMENTS = $(PY) -c 'import sys; \
	exec("try:\n import tomllib\nexcept ImportError:\n from pip._vendor import tomli as tomllib"); \
	t = tomllib.load(open("pyproject.toml", "rb")); p = t["project"]; x = p["optional-dependencies"]; \
	print(" ".join(t["build-system"]["requires"] + p["dependencies"] + x["test"] + x["dev"]))'

# The stamp depends on pyproject.toml: a changed dependency list reinstalls.
$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q $$($(REQUIREMENTS))
	touch $@

setup: $(VENV)/.installed

# Release build of the Rust core into python/arxid (incremental: target/ is the cache).
develop: setup
	@echo "building the Rust core (release; the first build takes a few minutes) -> $(VENV)/develop.log"
	@$(VENV)/bin/maturin develop --release > $(VENV)/develop.log 2>&1 || { cat $(VENV)/develop.log; exit 1; }

demo: develop
	$(VENV)/bin/arxid demo

test-rust:
	cargo test --release --quiet

test-python: develop
	$(PY) -m pytest -q

test: setup test-rust test-python

# The property-based suite at length (make test runs it derandomized with a few examples each).
fuzz: develop
	HYPOTHESIS_PROFILE=long $(PY) -m pytest -q tests/test_fuzz.py

bench: develop
	$(PY) benches/sweep_vs_numpy.py
	$(PY) benches/sweep_miso.py
	$(PY) benches/fleet.py

# OE and ARMAX against scipy least_squares, and SIPPY when it is installed (it is not a dependency:
# the row says "not installed" otherwise).
.PHONY: bench-pem
bench-pem: develop
	$(PY) benches/pem_vs_sippy.py

# Python: lint, format, and the stub of the compiled core against the built module (hence
# `develop`). Rust: format and clippy (--release: it shares target/release with `make test`'s
# builds, but only their build scripts; its metadata-only check artifacts are its own, about a
# minute from clean, seconds when warm). Every step runs, in this order; lint fails at the end if
# any step failed, naming them.
LINT_STEPS = \
	"$(PY) -m ruff check python tests benches" \
	"$(PY) -m ruff format --check python tests benches" \
	"$(PY) -m mypy" \
	"$(PY) -m mypy.stubtest arxid._core" \
	"cargo fmt --check" \
	"cargo clippy --release --all-targets --features python -- -D warnings"

lint: develop
	@failed=""; for step in $(LINT_STEPS); do \
		echo "+ $$step"; sh -c "$$step" || failed="$$failed$$step; "; \
	done; \
	if [ -n "$$failed" ]; then echo "make lint: failed: $$failed"; exit 1; fi

# mypy alone (it is also a step of `make lint`).
typecheck: develop
	$(PY) -m mypy

clean:
	rm -rf $(VENV) target python/arxid/_core*.so
