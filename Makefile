# RIVET — the user's entry points. `make help` lists them.
SHELL := /bin/bash
.DEFAULT_GOAL := help

DOMAIN ?= cubes
MODEL ?= claude-opus-5
PY := .venv/bin/python
UV ?= $(shell command -v uv 2>/dev/null || echo .venv-uv/bin/uv)
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl
export MENAGERIE_ROOT ?= $(abspath ../shared/menagerie)

.PHONY: help venv system test lint author eval bench bench-checks sandbox-base sandbox-image format refreeze refreeze-check results results-runs

help: ## list the targets
	@grep -hE '^[a-zA-Z_-]+:.*## ' $(MAKEFILE_LIST) | awk 'BEGIN{FS=":.*## "}{printf "  make %-14s %s\n", $$1, $$2}'

$(UV):
	python3 -m venv .venv-uv && .venv-uv/bin/pip install -q uv

.venv/.synced: pyproject.toml uv.lock | $(UV)
	$(UV) sync --frozen --all-extras
	@touch $@

venv: .venv/.synced ## create .venv from the lock file (uv)

system: ## install and start the system pieces (Docker engine, EGL/Mesa) when missing
	@bash scripts/bootstrap-system.sh

TEST_WORKERS ?= auto
test: venv system sandbox-image ## run the whole test suite (unit, property, sandbox, simulator, end to end) on every core (TEST_WORKERS=auto)
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile --durations=10 tests

lint: venv ## ruff (lint + format check), mypy and the import layering (import-linter)
	.venv/bin/ruff check .
	.venv/bin/ruff format --check .
	.venv/bin/mypy contracts geometry sandbox agent toolbox domains sim checks artifacts experiments rivet
	.venv/bin/lint-imports  # the layering, pyproject.toml [tool.importlinter]

format: venv ## apply ruff's formatting and safe fixes
	.venv/bin/ruff format .
	.venv/bin/ruff check --fix .

author: venv system sandbox-image ## author DOMAIN's programs: replays its reference transcript, or uses MODEL when ANTHROPIC_API_KEY is set
	.venv/bin/rivet author $(DOMAIN) $(if $(ANTHROPIC_API_KEY),--model $(MODEL))

refreeze: venv system sandbox-image ## rebuild the transcripts and frozen sets from domains/*/programs (or DOMAIN=…)
	.venv/bin/rivet refreeze $(if $(filter command line environment,$(origin DOMAIN)),$(DOMAIN))

refreeze-check: venv ## exit 1 where a committed transcript or frozen set is not what its programs make
	.venv/bin/rivet refreeze --check

results: venv ## write docs/results.md from the run files in docs/results/
	$(PY) -m experiments.results render

results-runs: venv system sandbox-image ## run the commands whose docs/results/ files are missing (hours), then render
	$(PY) -m experiments.results run
	$(PY) -m experiments.results render

POLICY ?= artifacts
WORKERS ?= 2
eval: venv system ## evaluate DOMAIN on its 60 benchmark trials (POLICY=artifacts|oracle, WORKERS=2)
	.venv/bin/rivet eval $(DOMAIN) --policy $(POLICY) --workers $(WORKERS)

bench: venv system sandbox-image ## benchmarks: sandbox overhead, rendering, check mutants
	$(PY) -m benchmarks.run

bench-checks: venv system sandbox-image ## the mutation benchmark of the check suites, every domain (or DOMAIN=…)
	$(PY) -m benchmarks.checks_bench $(if $(filter command line environment,$(origin DOMAIN)),--domain $(DOMAIN))

sandbox-base: ## build the offline sandbox base image (debootstrap + docker import)
	@bash sandbox/build_base.sh

sandbox-image: venv system ## build the sandbox image (tag = hash of its inputs) if missing
	$(PY) -m sandbox.image build
