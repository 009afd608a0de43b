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

# The main job on a built-in example: 1000 noisy points of a star -> 10 vertices.
demo: install
	$(BIN)/otjax curve --example noisy-star --points 1000 --mkdir -o out/noisy-star.png -o out/noisy-star.svg \
		-o out/noisy-star.json

# The layer rules (pyproject.toml's import-linter contracts), then the suite.
test: install
	$(BIN)/lint-imports --no-cache
	$(BIN)/python -m pytest -q -n 2 --dist loadfile --durations=20

.PHONY: install demo test
