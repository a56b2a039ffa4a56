# Two entry points (see README): `make run` and `make test`. Each creates .venv on first use,
# installs the pinned CPU build of torch, then the package with its test extra.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test test-slow lint typecheck-tree bench install clean mutate

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q torch==2.13.0
	$(BIN)/python -m pip install -q -e ".[test]"
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(BIN)/rmm-bench --agent all --episodes 32 --batch-size 16

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2

# ruff (lint and format) and mypy over the three packages, as .pre-commit-config.yaml runs them
LINT_STAMP := $(VENV)/.installed-lint

$(LINT_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -e ".[test,lint]"
	touch $(LINT_STAMP)

# mypy does not read pyproject's package-dir mapping: build/typecheck/ links the mapped folders
# under their import names (pyproject's [tool.mypy] mypy_path)
typecheck-tree:
	@mkdir -p build/typecheck
	@ln -sfn ../../guardians build/typecheck/rmm_guardians
	@ln -sfn ../../benchmarks/bench build/typecheck/rmm_bench

lint: $(LINT_STAMP) typecheck-tree
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/mypy

# The checks marked `slow` (README, Development): end-to-end drills and the paper-scale dataset.
test-slow: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 -m slow

# Mutation score of the decision-making modules (docs/mutation.md): targets and the tests that judge
# each are in mutation/targets.toml; `make mutate TARGETS="cbf hj"` runs only those.
MUTATE_STAMP := $(VENV)/.installed-mutate
TARGETS ?=

$(MUTATE_STAMP): $(STAMP)
	$(BIN)/python -m pip install -q -e ".[test,mutate]"
	touch $(MUTATE_STAMP)

mutate: $(MUTATE_STAMP)
	$(BIN)/python mutation/run.py $(TARGETS)

bench: $(STAMP)
	$(BIN)/python -m benchmarks.perf_env
	$(BIN)/python -m benchmarks.perf_risk
	$(BIN)/python -m benchmarks.perf_guardians
	$(BIN)/python -m benchmarks.perf_hj --quick
	$(BIN)/python -m benchmarks.perf_quadrotor
	$(BIN)/python -m benchmarks.perf_quadrotor_parallel
	$(BIN)/python -m benchmarks.perf_vector

clean:
	rm -rf $(VENV) build *.egg-info
