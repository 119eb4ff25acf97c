# Two entry points: `make demo` plans the demo site, `make test` runs the whole suite.
# Each creates .venv and installs what it needs on first use.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test demo-site clean

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@ $(VENV)/.installed

demo: $(VENV)/.installed
	$(BIN)/urpt-gcs plan --dem missions/demo/site.tif --targets missions/demo/targets.kml \
		--out missions/demo/out

test: $(VENV)/.installed-test
	$(BIN)/ruff check urpt_gcs tests
	$(BIN)/ruff format --check urpt_gcs tests
	$(BIN)/mypy
	$(BIN)/lint-imports
	$(BIN)/python -m pytest

# Regenerate the demo site (it is committed; this is how it was made).
demo-site: $(VENV)/.installed
	$(BIN)/urpt-gcs demo-site --out missions/demo

clean:
	rm -rf $(VENV) out .pytest_cache .mypy_cache .ruff_cache .import_linter_cache
