# Two commands on a fresh machine: `make demo` and `make test`.
# Both (re)build .venv from pyproject.toml when it is missing or older than pyproject.toml.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed
# Parallel test workers; SITL-in-the-loop tests run in lockstep so they do not depend on load.
TEST_WORKERS ?= 2

.PHONY: demo test bench venv clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "error: Python 3.11+ is required (found $$($(PYTHON) --version 2>&1))"; exit 1; }
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $(STAMP)

venv: $(STAMP)

# The main job: the emulator and the daemon drive a bundled mission among obstacles, with a report.
DEMO_CMD ?= $(BIN)/rover-ctl sim missions/cmac_loop.waypoints --world missions/worlds/cmac_loop.geojson --lockstep --out runs/demo

# `rover-ctl sim` exits 1 when the mission ran but did not succeed (e.g. a collision): the run and
# its report are the demo, so that counts as done; any other failure (2 bad input, crash) fails.
demo: $(STAMP)
	@echo "$(DEMO_CMD)"; $(DEMO_CMD); status=$$?; [ $$status -le 1 ] || exit $$status

test: $(STAMP)
	$(BIN)/python -m pytest -n $(TEST_WORKERS) $(PYTEST_ARGS)

# Benchmarks get their own venv: the competitors (pyfuzzylite, scikit-fuzzy) pin numpy < 2, which
# must not change what `make test` runs against. `make bench BENCH_ARGS="fuzzy --quick"` runs one.
BENCH_VENV  := .venv-bench
BENCH_STAMP := $(BENCH_VENV)/.installed

$(BENCH_STAMP): pyproject.toml
	@test -x $(BENCH_VENV)/bin/python || $(PYTHON) -m venv $(BENCH_VENV)
	$(BENCH_VENV)/bin/python -m pip install --quiet --upgrade pip
	$(BENCH_VENV)/bin/python -m pip install --quiet -e '.[bench]'
	@touch $(BENCH_STAMP)

bench: $(BENCH_STAMP)
	$(BENCH_VENV)/bin/python -m bench $(BENCH_ARGS)

clean:
	rm -rf $(VENV) $(BENCH_VENV) build *.egg-info .pytest_cache
