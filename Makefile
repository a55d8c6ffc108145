# One task runner: the README's two commands are `make demo` and `make test`.
VENV   ?= .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
export VIRTUAL_ENV := $(abspath $(VENV))
export PATH := $(abspath $(VENV))/bin:$(PATH)

.PHONY: setup develop demo test test-rust test-python bench lint clean

$(VENV)/.installed: pyproject.toml
	python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q "maturin>=1.9.4,<2" "numpy>=1.23" "scipy>=1.10" "pandas>=1.5" "matplotlib>=3.6" "control>=0.10" "tqdm>=4.60" "pytest>=7"
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

bench: develop
	$(PY) benches/sweep_vs_numpy.py

lint:
	cargo fmt --check
	cargo clippy --release --all-targets --features python -- -D warnings

clean:
	rm -rf $(VENV) target python/arxid/_core*.so
