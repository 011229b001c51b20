# higbench: the two commands that set everything up are `make run` and `make test`.
PYTHON ?= python3
VENV ?= .venv
TORCH_VERSION ?= 2.13.0
# Where torch comes from: empty = pip's default index, which on Linux gives the CUDA build (what
# a GPU needs, several GB); TORCH_INDEX=https://download.pytorch.org/whl/cpu gives the CPU-only one.
TORCH_INDEX ?=
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed-stamp
PRESET ?= quick
IDS ?= all
OUT ?= figures
PYTEST_ARGS ?=

.PHONY: install install-dev install-optuna run test test-slow test-all test-optuna lint bench bench-time-to-loss figures authors-env probe-authors-oscillator clean

# A virtual environment with torch pinned first (TORCH_INDEX above), then higbench (editable) with
# only what `make run` needs. Re-runs when pyproject.toml changes.
$(STAMP): pyproject.toml
	@echo "[install] a virtual environment in $(VENV), then torch $(TORCH_VERSION) and higbench into it: this takes minutes, quietly"
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip "setuptools>=77" wheel
	@echo "[install] 1 of 2: torch $(TORCH_VERSION) from $(if $(TORCH_INDEX),$(TORCH_INDEX),pip's default index (on Linux the CUDA build: several GB))"
	$(BIN)/python -m pip install --quiet "torch==$(TORCH_VERSION)" $(if $(TORCH_INDEX),--index-url $(TORCH_INDEX))
	@echo "[install] 2 of 2: higbench (editable) and its dependencies (hydra-core, h5py, pandas, matplotlib, scipy, numba)"
	$(BIN)/python -m pip install -qq -e .
	@echo "[install] done"
	rm -f $(DEV_STAMP) $(OPTUNA_STAMP)
	touch $(STAMP)

# -qq on editable installs: setuptools notes that conf/ is mapped into the package (an
# informational "Editable installation" banner); errors still show, and
# tests/test_installed.py fails on any warning from a wheel build.
# Extras go in with the targets that need them: tests and lint (dev: pytest, ruff; cluster:
# Hydra's joblib and submitit launchers, which the sweep tests use), Optuna sweeps (optuna).
DEV_STAMP := $(VENV)/.dev-stamp
OPTUNA_STAMP := $(VENV)/.optuna-stamp
$(DEV_STAMP): $(STAMP)
	$(BIN)/python -m pip install -qq -e ".[dev,cluster]"
	touch $(DEV_STAMP)

$(OPTUNA_STAMP): $(DEV_STAMP)
	$(BIN)/python -m pip install -qq -e ".[dev,cluster,optuna]"
	touch $(OPTUNA_STAMP)

install: $(STAMP)
install-dev: $(DEV_STAMP)
install-optuna: $(OPTUNA_STAMP)

# The main job on a default budget of about a minute; prints where its run file went.
run: install
	$(BIN)/higbench problem=oscillator optimizer=hig budget.seconds=60

# Default test suite (no test marked slow); CI runs this through .ci/run. Tests marked
# `optuna` are skipped, with the reason shown, unless the optuna extra is installed. Its last
# lines say how many tests started processes (tests/process_starts.py; at most 15, each marked
# `process`); PYTEST_ARGS=--process-starts lists them. TEST_WORKERS pytest-xdist workers, one
# test file each at a time (a file's module fixtures are made once); TEST_WORKERS=0: in one process.
TEST_WORKERS ?= 2
test: install-dev
	$(BIN)/python -m pytest -q -m "not slow" -n $(TEST_WORKERS) --dist loadfile $(PYTEST_ARGS)

test-slow: install-dev
	$(BIN)/python -m pytest -q -m slow $(PYTEST_ARGS)

test-all: install-optuna
	$(BIN)/python -m pytest -q $(PYTEST_ARGS)

# The Optuna sweeper's tests, with the optuna extra installed.
test-optuna: install-optuna
	$(BIN)/python -m pytest -q -m optuna $(PYTEST_ARGS)

lint: install-dev
	$(BIN)/ruff check higbench tests scripts hydra_plugins
	$(BIN)/ruff format --check higbench tests scripts hydra_plugins
	$(BIN)/lint-imports

bench: install
	$(BIN)/python -m higbench.bench.step

# Training-clock seconds to the oscillator's test-loss targets (problem.targets) and each decade below
# them some run reached: oscillator HIG, GN (seed 7), Adam, L-BFGS, LM at
# paper settings, TTL_BUDGET seconds of training clock per run (default 15 minutes), TTL_JOBS at once.
TTL_BUDGET ?= 900
TTL_JOBS ?= 1
bench-time-to-loss: install
	$(BIN)/python scripts/time_to_loss.py --budget $(TTL_BUDGET) --jobs $(TTL_JOBS)

figures: install
	$(BIN)/python -m higbench.figures $(IDS) --preset $(PRESET) --out $(OUT)

# The authors' TensorFlow code (a checkout of tum-pbs/half-inverse-gradients at AUTHORS) beside
# ours on the oscillator, from the same data and initial weights: their 32 epochs (~20 min on a
# CPU) in their own environment, then our variants for the paper's hour of updates.
AUTHORS ?=
AUTHORS_VENV ?= .venv-authors
AUTHORS_EXPORT ?= outputs/probes/oscillator_authors.npz
# TensorFlow 2.15: the newest with Keras 2, whose API their code uses (they ran 2.5, which no
# longer installs on Python 3.11); matplotlib: their modules import pyplot.
$(AUTHORS_VENV)/.stamp:
	$(PYTHON) -m venv $(AUTHORS_VENV)
	$(AUTHORS_VENV)/bin/python -m pip install --quiet "tensorflow-cpu==2.15.1" matplotlib
	touch $@

authors-env: $(AUTHORS_VENV)/.stamp

probe-authors-oscillator: install authors-env
	@test -n "$(AUTHORS)" || { echo "AUTHORS=: give the path of a tum-pbs/half-inverse-gradients checkout"; exit 2; }
	test -f $(AUTHORS_EXPORT) || $(AUTHORS_VENV)/bin/python scripts/export_authors_oscillator.py --authors $(AUTHORS) --out $(AUTHORS_EXPORT)
	$(BIN)/python scripts/probe_oscillator_authors.py $(AUTHORS_EXPORT)

clean:
	rm -rf $(VENV) $(AUTHORS_VENV) build dist *.egg-info
