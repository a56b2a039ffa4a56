# Two entry points (see README): `make run` and `make test`. Each creates .venv on first use,
# installs the pinned CPU build of torch, then the package with its test extra.
PYTHON ?= python3
VENV ?= .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed
# setuptools says "Editable installation ... be careful with folders in your working directory with
# the same name as your package" on every editable install of this layout: informational, and the
# folders are mapped on purpose (docs/decisions/0001-import-names.md), so the install says nothing
PIP_E := PYTHONWARNINGS="ignore:Editable installation" $(BIN)/python -m pip install -q -e

.PHONY: run test test-slow lint typecheck-tree bench install clean mutate docs

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q torch==2.13.0
	$(PIP_E) ".[test]"
	touch $(STAMP)

install: $(STAMP)

run: $(STAMP)
	$(BIN)/rmm-bench --agent all --episodes 32 --batch-size 16

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2

# ruff (lint and format) and mypy over the three packages, as .pre-commit-config.yaml runs them
LINT_STAMP := $(VENV)/.installed-lint

$(LINT_STAMP): $(STAMP)
	$(PIP_E) ".[test,lint]"
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

# The documentation site (docs/decisions/0028-docs-site.md): Sphinx with MyST markdown over docs/, the
# API reference from the docstrings, warnings (broken cross-references among them) as errors
DOCS_STAMP := $(VENV)/.installed-docs

$(DOCS_STAMP): $(STAMP)
	$(PIP_E) ".[test,docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	rm -rf docs/api  # autosummary writes the API pages afresh: none left from a removed module
	$(BIN)/python -m sphinx -b html -E -W --keep-going -q -j 2 docs build/docs

# Mutation score of the decision-making modules (docs/mutation.md): targets and the tests that judge
# each are in mutation/targets.toml; `make mutate TARGETS="cbf hj"` runs only those.
MUTATE_STAMP := $(VENV)/.installed-mutate
TARGETS ?=

$(MUTATE_STAMP): $(STAMP)
	$(PIP_E) ".[test,mutate]"
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
