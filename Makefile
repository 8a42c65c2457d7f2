# Two entry points for a new user: `make run` and `make test` (see README).
PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: run test test-all test-viewer test-arm64 lint bench clean

$(BIN)/python:
	@test -n "$(PYTHON)" && $(PYTHON) -c "import sys; sys.exit(sys.version_info < (3, 11))" || { echo "error: needs Python >= 3.11 (set PYTHON=...)"; exit 2; }
	$(PYTHON) -m venv $(VENV)

$(STAMP): $(BIN)/python pyproject.toml
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test,plot]'
	@touch $(STAMP)

run: $(STAMP)
	@mkdir -p runs
	$(BIN)/isaac run scenes/default.yaml --mcap runs/default.mcap --rrd runs/default.rrd

test: $(STAMP)
	$(BIN)/python -m pytest -q

# the Rerun web viewer in headless Chromium (installs Debian's chromium with apt-get if missing)
test-viewer: $(STAMP)
	$(BIN)/python -m pytest -q -m slow tests/test_viewer_browser.py

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .

test-all: $(STAMP)
	$(BIN)/python -m pytest -q -m ''

# slow (about 30 min the first time): replays the golden corpus on an emulated arm64 Debian
# userland under qemu-user, with the JIT and without (needs root; docs/replay.md)
test-arm64:
	scripts/arm64_replay.sh

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -e '.[bench]'
	$(BIN)/python -m bench

clean:
	rm -rf $(VENV) runs .pytest_cache
