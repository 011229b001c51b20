# higbench: the two commands that set everything up are `make run` and `make test`.
PYTHON ?= python3
VENV ?= .venv
TORCH_VERSION ?= 2.13.0
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
PRESET ?= quick
PYTEST_ARGS ?=

.PHONY: install run test test-slow test-all lint bench bench-time-to-loss figures clean

# A virtual environment with torch pinned first (CPU build), then higbench (editable) and
# its dev and launcher extras. Re-runs when pyproject.toml changes.
$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip "setuptools>=68" wheel
	$(BIN)/python -m pip install --quiet "torch==$(TORCH_VERSION)"
	$(BIN)/python -m pip install --quiet -e ".[dev,cluster,optuna]"
	touch $(STAMP)

install: $(STAMP)

# The main job on a default budget of about a minute; prints where its run file went.
run: install
	$(BIN)/higbench problem=oscillator optimizer=hig budget.seconds=60

# Default test suite (no test marked slow); CI runs this through .ci/run.
test: install
	$(BIN)/python -m pytest -q -m "not slow" $(PYTEST_ARGS)

test-slow: install
	$(BIN)/python -m pytest -q -m slow $(PYTEST_ARGS)

test-all: install
	$(BIN)/python -m pytest -q $(PYTEST_ARGS)

lint: install
	$(BIN)/ruff check higbench tests scripts
	$(BIN)/ruff format --check higbench tests scripts

bench: install
	$(BIN)/python scripts/bench_step.py

# Training-clock seconds to test loss 1e-3..1e-7: oscillator HIG/GN/Adam, dipole HIG/Adam,
# paper settings, TTL_BUDGET seconds of training clock per run (the issue's 15 minutes).
TTL_BUDGET ?= 900
bench-time-to-loss: install
	$(BIN)/python scripts/time_to_loss.py --budget $(TTL_BUDGET)

figures: install
	$(BIN)/python -m higbench.figures all --preset $(PRESET)

clean:
	rm -rf $(VENV) build dist *.egg-info
