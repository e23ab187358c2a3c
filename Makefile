# gearspec: two set-up commands on a fresh machine (see README.md)
#   make demo   creates .venv if absent, installs gearspec, runs the main analysis on built-in data
#   make test   creates .venv if absent, installs gearspec with test tools, runs the test suite

PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# the real data sets live outside the project; tests read them through GEARSPEC_DATA
GEARSPEC_DATA ?= $(abspath ../shared/datasets)
export GEARSPEC_DATA

.PHONY: demo test test-fast mutation bench clean

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/gearspec demo --out demo-out
	@echo "open demo-out/report.html"

test: $(STAMP)
	$(BIN)/python -m pytest -q -n 2

# the quick tier: everything not marked slow (under 4 minutes on 2 cores); not a set-up command
test-fast: $(STAMP)
	$(BIN)/python -m pytest -q -n 2 -m "not slow"

# mutation score of the core modules against the quick tier, on a seeded sample of SAMPLE mutants
# per module (hours on 2 cores; not run in CI): tests/MUTATION.md
SAMPLE ?= 40
mutation: $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,mutation]"
	MPLBACKEND=Agg $(BIN)/python benchmarks/mutation.py run --sample $(SAMPLE)
	$(BIN)/python benchmarks/mutation.py report --sample $(SAMPLE) --diffs

bench: $(STAMP)
	$(BIN)/python benchmarks/bench_spectrum.py

clean:
	rm -rf $(VENV) demo-out .pytest_cache mutants
