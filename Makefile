# Two commands set everything up on a fresh machine with python3 and make:
#   make demo   creates .venv, installs the toolkit, compiles its kernels, runs designs/carousel.toml
#   make test   creates or updates .venv, runs the whole test suite on both cores
#   make test-min  creates or updates .venv-min with the tested minimum versions
#                  (constraints/minimum.txt = the lower bounds in pyproject.toml), runs the suite
#   make docs      adds the docs group to .venv, builds the site into docs/_build/html
#                  (warnings are errors, every cross-reference checked)
#   make bench-page  runs every benchmark and writes benchmarks/performance.txt (the site's
#                  performance page includes it)
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
MIN_VENV  := .venv-min
MIN_BIN   := $(MIN_VENV)/bin
MIN_STAMP := $(MIN_VENV)/.installed

.PHONY: demo test test-quick test-min bench bench-page docs mutation clean venv

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

# The kernels are compiled once, here, with a progress bar (active-contacts warm); every
# design's first run then starts warm.
demo: $(STAMP)
	$(BIN)/active-contacts warm
	$(BIN)/active-contacts run designs/carousel.toml --out out/carousel

# The kernel tests run twice: compiled (as every test), and as plain Python under numba's
# own switch (the same source must give the same numbers): the kernels' own tests and the
# exactness tests of the engines they run (the exact method, advance).
KERNEL_TESTS := tests/test_compiled.py tests/test_lines.py tests/test_planar_kernels.py \
	tests/test_simulation_exact.py tests/test_simulation_stepper.py \
	tests/test_baselines.py tests/test_imm.py tests/test_linearize_kernel.py

# The suite runs in WORKERS processes (pytest-xdist): the kernels are compiled once before
# they start (tests/conftest.py); --dist loadgroup sends the tests one by one, but those that
# share a module-scoped fixture to one worker. The tests marked wall_clock (the live loop,
# Ctrl-C, the memory-bound runs, process pools and Dask clusters) then run in one process:
# no busy sibling, and no worker's threads in the processes they fork. --durations lists the
# slowest tests. docs/testing.md says more.
WORKERS ?= 2
PYTEST  := -m pytest -q -n $(WORKERS) --dist loadgroup
test: $(STAMP)
	$(BIN)/python $(PYTEST) -m "not wall_clock" --durations=20
	$(BIN)/python -m pytest -q -m wall_clock --durations=5
	NUMBA_DISABLE_JIT=1 $(BIN)/python $(PYTEST) $(KERNEL_TESTS)

# While developing: every test but those marked slow (notebooks, subprocess sweeps, the wheel).
test-quick: $(STAMP)
	$(BIN)/python $(PYTEST) -m "not slow and not wall_clock"
	$(BIN)/python -m pytest -q -m "wall_clock and not slow"

$(MIN_STAMP): pyproject.toml constraints/minimum.txt
	test -x $(MIN_BIN)/python || $(PYTHON) -m venv $(MIN_VENV)
	$(MIN_BIN)/python -m pip install --quiet --upgrade pip
	$(MIN_BIN)/python -m pip install --quiet -c constraints/minimum.txt -e ".[test]"
	touch $(MIN_STAMP)

test-min: $(MIN_STAMP)
	$(MIN_BIN)/python $(PYTEST) -m "not wall_clock" --durations=20
	$(MIN_BIN)/python -m pytest -q -m wall_clock
	NUMBA_DISABLE_JIT=1 $(MIN_BIN)/python $(PYTEST) $(KERNEL_TESTS)

# Mutation testing of the laws and the numerics, each module against its own test files
# (mutation/modules.toml); prints the kill rate per module and the surviving mutants.
# Not part of make test: about half an hour of both cores. MUTATION_ARGS="toolkit/model/*"
# runs some modules; working copies persist in build/mutation/ (a module whose source and
# test files are unchanged reports at once).
MUTATION_STAMP := $(VENV)/.installed-mutation
$(MUTATION_STAMP): $(STAMP)
	$(BIN)/python -m pip install --quiet -e ".[test,mutation]"
	touch $(MUTATION_STAMP)

mutation: $(MUTATION_STAMP)
	$(BIN)/python mutation/run.py --workers 2 $(MUTATION_ARGS)

bench: $(STAMP)
	$(BIN)/python -m toolkit.bench all

bench-page: $(STAMP)
	$(BIN)/python -m toolkit.bench all > benchmarks/performance.txt.new
	mv benchmarks/performance.txt.new benchmarks/performance.txt

DOCS_STAMP := $(VENV)/.installed-docs
$(DOCS_STAMP): $(STAMP) pyproject.toml
	$(BIN)/python -m pip install --quiet -e ".[test,docs]"
	touch $(DOCS_STAMP)

docs: $(DOCS_STAMP)
	rm -rf docs/generated docs/reference/generated
	$(BIN)/python -m sphinx -b html -W --keep-going -n -q docs docs/_build/html

clean:
	rm -rf $(VENV) $(MIN_VENV) out build/mutation .pytest_cache .hypothesis docs/_build docs/reference/generated
