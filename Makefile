# Two commands on a fresh machine: `make demo` and `make test`.
# Both share .venv and (re)install into it when it is missing or older than pyproject.toml: the
# demo only the package (`.`), the tests the package and the `test` extra (pytest and the
# third-party ground stations of the interop tests, MAVProxy and MAVSDK, which the demo does not
# need). One stamp each; installing the test extra also satisfies the demo.
PYTHON ?= python3
VENV   := .venv
BIN    := $(VENV)/bin
DEMO_STAMP := $(VENV)/.installed-demo
TEST_STAMP := $(VENV)/.installed-test
# Parallel test workers; SITL-in-the-loop tests run in lockstep so they do not depend on load.
# One more worker than the 2 cores: some tests mostly wait (30 lossy uploads: 39 s of wall time
# for 1.6 s of CPU; the firmware's first leg in real time: 33 s for 3 s; the firmware over a
# serial line, paced by the line: half of 35 s), and a third worker fills the idle core. The
# suite's worker time was 662 s for 502 s of CPU; 340 s on 2 workers, 287 s on 3 (2026-11-27).
TEST_WORKERS ?= 3
# Idle workers take queued tests from the busy one: the slowest tests (firmware runs of 20-40 s)
# no longer leave one core idle at the end (318 s against 335 s for the suite on 2 cores).
TEST_DIST ?= worksteal

.PHONY: demo test bench venv clean

$(BIN)/python:
	@$(PYTHON) -c 'import sys; sys.exit(sys.version_info < (3, 11))' || \
	  { echo "error: Python 3.11+ is required (found $$($(PYTHON) --version 2>&1))"; exit 1; }
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip

$(DEMO_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e .
	@touch $@

$(TEST_STAMP): pyproject.toml | $(BIN)/python
	$(BIN)/python -m pip install --quiet -e '.[test]'
	@touch $@ $(DEMO_STAMP)

venv: $(TEST_STAMP)

# The main job: the emulator and the daemon drive a bundled mission among obstacles, with a report.
# Each run is a new numbered folder under runs/demo/ (runs/demo/latest points to the newest).
DEMO_CMD ?= $(BIN)/rover-ctl sim missions/cmac_loop.waypoints --world missions/worlds/cmac_loop.geojson --lockstep --out runs/demo

# `rover-ctl sim` exits 1 when the mission ran but did not succeed (e.g. a collision): the run and
# its report are the demo, so that counts as done; any other failure (2 bad input, crash) fails.
demo: $(DEMO_STAMP)
	@echo "$(DEMO_CMD)"; $(DEMO_CMD); status=$$?; [ $$status -le 1 ] || exit $$status

test: $(TEST_STAMP)
	$(BIN)/python -m pytest -n $(TEST_WORKERS) --dist $(TEST_DIST) $(PYTEST_ARGS)

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
