# Two entry points (see README): `make run` and `make test`. Both set up .venv first.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# The compiled mission rules (iout_mj/_native*.so) and the added-mass MuJoCo plugin
# (iout_mj/backends/mujoco/_added_mass*.so): rebuilt when a C source changes.
NATIVE := $(VENV)/.native
NATIVE_SOURCES := iout_mj/native.h iout_mj/native.c $(wildcard iout_mj/*/*.c iout_mj/*/*/*.c) setup.py
# The CPU build of torch that lies on these machines' disk; an unpinned torch pulls CUDA (GBs).
TORCH := torch==2.13.0

.PHONY: setup run test lint bench clean

setup: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet $(TORCH)
	$(BIN)/python -m pip install --quiet -e ".[dev]"
	touch $(STAMP) $(NATIVE)

$(NATIVE): $(STAMP) $(NATIVE_SOURCES)
	$(BIN)/python -m pip install --quiet --no-deps -e .
	touch $(NATIVE)

run: $(NATIVE)
	$(BIN)/iout-mj render --policy ppo-general --width 960 --height 540 --out renders

test: $(NATIVE)
	$(BIN)/python -m pytest -q

lint: $(STAMP)
	$(BIN)/ruff check iout_mj tests training benchmarks
	$(BIN)/mypy

bench: $(NATIVE)
	$(BIN)/iout-mj bench

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
