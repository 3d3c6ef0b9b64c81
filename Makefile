# Two commands set everything up on a new machine:
#   make demo   - run the main job on the embedded default data
#   make test   - run the test suite
# Both create or reuse .venv, install the CPU build of torch 2.13.0 first, then the project.
# Also:
#   make test-fast  - the tests not marked slow (no IPOPT solves, long rollouts, training,
#                     subprocess command-line runs or rendering), about a minute
#   make typecheck  - mypy on the package (.ci/typecheck.py)
#   make lint       - ruff check, ruff format --check (code and tests), then typecheck;
#                     CI (.ci/run) runs it before the tests
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.habitsim-installed
DEMO_OUT ?= demo_out

.PHONY: demo test test-fast lint typecheck install clean fuzz

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(STAMP): $(BIN)/python pyproject.toml setup.py
	$(BIN)/python -m pip install --quiet torch==2.13.0
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $(STAMP)

install: $(STAMP)

demo: $(STAMP)
	$(BIN)/habitsim demo --out $(DEMO_OUT)

test: $(STAMP)
	$(BIN)/python -m pytest -q

# The quick subset: every test not marked `slow` (see the marker in pyproject.toml).
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -m "not slow"

# ruff and mypy are dev tools, not dependencies of the package: installed on first use.
$(BIN)/ruff: $(BIN)/python
	$(BIN)/python -m pip install --quiet "ruff>=0.5"

$(BIN)/mypy: $(BIN)/python
	$(BIN)/python -m pip install --quiet "mypy>=2.4"

LINTED := habitsim controllers evaluation mjcf_models tests .ci

# mypy reads the installed dependencies' types (numpy, torch, casadi): the project first.
typecheck: $(STAMP) $(BIN)/mypy
	$(BIN)/python .ci/typecheck.py

lint: $(BIN)/ruff $(BIN)/mypy $(STAMP)
	$(BIN)/ruff check $(LINTED)
	$(BIN)/ruff format --check $(LINTED)
	$(BIN)/python .ci/typecheck.py

# A long fuzzing campaign over the readers and the command line, counts by outcome
# (tests/fuzzing, a developer tool: `python -m fuzzing` from tests/). FUZZ_N inputs.
fuzz: $(STAMP)
	cd tests && ../$(BIN)/python -m fuzzing --n $(or $(FUZZ_N),10000) --check

clean:
	rm -rf $(VENV) $(DEMO_OUT)
