# Two entry points, both starting from a bare python3 + pip + make:
#   make demo   installs otjax into .venv and runs the built-in example
#   make test   installs otjax with its test extras into .venv and runs the suite
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

$(BIN)/activate:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install --quiet --upgrade pip

install: $(BIN)/activate
	$(BIN)/pip install --quiet -e ".[test]"

demo: install
	$(BIN)/python -m otjax.demo

test: install
	$(BIN)/python -m pytest -q

.PHONY: install demo test
