# Two commands set everything up on a fresh machine with python3 and make:
#   make demo   creates .venv, installs the toolkit, runs designs/carousel.toml
#   make test   creates or updates .venv, runs the whole test suite
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

.PHONY: demo test bench clean venv

venv: $(STAMP)

$(STAMP): pyproject.toml
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e ".[test]"
	touch $(STAMP)

demo: $(STAMP)
	$(BIN)/active-contacts run designs/carousel.toml --out out/carousel

test: $(STAMP)
	$(BIN)/python -m pytest -q

bench: $(STAMP)
	$(BIN)/python -m toolkit.bench all

clean:
	rm -rf $(VENV) out .pytest_cache .hypothesis
