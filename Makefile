# Every target sets up what it needs itself: on a fresh machine `make demo` and `make test`
# are the only set-up. The virtual environment is rebuilt when pyproject.toml changes.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.installed-stamp
TOOLS := .tools
GLTF_VALIDATOR := $(TOOLS)/node_modules/gltf-validator/package.json
OUT ?= demo-out

.PHONY: demo test check bench lint studio tools clean

$(STAMP): pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PY) -m pip install --quiet --upgrade pip
	$(PY) -m pip install --quiet -e '.[dev,scale,studio,bench,physics]'
	touch $(STAMP)

# Khronos glTF validator (npm registry) for the glTF tests; skipped with a notice if npm is absent.
$(GLTF_VALIDATOR):
	@if command -v npm >/dev/null; then \
		mkdir -p $(TOOLS) && npm install --silent --no-audit --no-fund --prefix $(TOOLS) gltf-validator@2.0.0-dev.3.10; \
	else echo "npm not found: glTF validator tests will be skipped"; fi

tools: $(STAMP) $(GLTF_VALIDATOR)
	@bash scripts/ensure_apt.sh || echo "apt unavailable: browser / Blender tests will be skipped"

demo: $(STAMP)
	$(VENV)/bin/biomorph demo --out $(OUT)
	@echo "open $(OUT)/report.html"

check: $(STAMP)
	$(VENV)/bin/ruff check $(wildcard src tests bench)
	$(VENV)/bin/ruff format --check $(wildcard src tests bench)
	$(VENV)/bin/mypy

test: tools check
	$(VENV)/bin/pytest -n 2 --durations=15

# Peers for bench/tree.py: pytlidar pins numba==0.61.2, which would downgrade numba and numpy
# for the whole venv; it runs on ours, so it is installed without its pins.
PEERS := $(VENV)/.peers-stamp
$(PEERS): $(STAMP)
	$(PY) -m pip install --quiet --no-deps 'pytlidar>=1.1.2' 'plotly>=5'
	touch $(PEERS)

bench: $(STAMP) $(PEERS)
	@for f in bench/*.py; do echo "== $$f"; $(PY) $$f || exit 1; done

# ruff (lint + format, both fail the target) and mypy on core/ and io/ (config in pyproject.toml).
lint: check

studio: $(STAMP)
	$(VENV)/bin/biomorph studio

clean:
	rm -rf $(VENV) $(TOOLS) $(OUT) .pytest_cache .ruff_cache
