# Two entry points: `make demo` plans the demo site, `make test` runs the whole suite.
# Each creates .venv and installs what it needs on first use.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin

.PHONY: demo test demo-site clean

# The browser the tests of map.html drive (tests/files/test_map_page.py): Debian's package.
CHROMIUM := /usr/bin/chromium

$(BIN)/python:
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(VENV)/.installed: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	touch $@

$(VENV)/.installed-test: pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	touch $@ $(VENV)/.installed

# Chromium for those tests, installed with apt-get where it is missing and apt-get can run
# (as root); where it cannot, the build goes on and the browser tests skip, saying why. The
# stamp is left only once Chromium is there, so a later run tries again.
$(VENV)/.chromium: | $(BIN)/python
	@if [ ! -x $(CHROMIUM) ] && command -v apt-get >/dev/null 2>&1 && [ "$$(id -u)" = 0 ]; then \
		echo "installing chromium with apt-get for the browser tests of map.html"; \
		{ apt-get update -qq && DEBIAN_FRONTEND=noninteractive \
			apt-get install -y -qq chromium; } >/dev/null 2>&1 \
			|| echo "apt-get could not install chromium: the browser tests will skip"; \
	fi
	@if [ -x $(CHROMIUM) ]; then touch $@; \
	else echo "no Chromium at $(CHROMIUM): the browser tests of map.html will skip"; fi

demo: $(VENV)/.installed
	$(BIN)/urpt-gcs plan --dem missions/demo/site.tif --targets missions/demo/targets.kml \
		--out missions/demo/out

test: $(VENV)/.installed-test $(VENV)/.chromium
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
