# Two commands set everything up on a new machine:
#   make demo   - run the main job on the embedded default data
#   make test   - run the test suite
# (make lint runs ruff check and ruff format --check on the code and the tests; CI runs it
# before the tests.)
# Both create or reuse .venv, install the CPU build of torch 2.13.0 first, then the project.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.habitsim-installed
DEMO_OUT ?= demo_out

.PHONY: demo test lint install clean fuzz

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

# ruff is a dev tool, not a dependency of the package: installed on first use.
$(BIN)/ruff: $(BIN)/python
	$(BIN)/python -m pip install --quiet "ruff>=0.5"

LINTED := habitsim controllers evaluation mjcf_models tests

lint: $(BIN)/ruff
	$(BIN)/ruff check $(LINTED)
	$(BIN)/ruff format --check $(LINTED)

# A long fuzzing campaign over the readers and the command line (counts by outcome; the
# same campaign as `habitsim fuzz --n N`).
fuzz: $(STAMP)
	$(BIN)/python -m habitsim.fuzz --n $(or $(FUZZ_N),10000)

clean:
	rm -rf $(VENV) $(DEMO_OUT)
