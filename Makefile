PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.installed

# Python writes its bytecode (__pycache__/, ignored by git) even where the shell says not
# to (PYTHONDONTWRITEBYTECODE, as in this project's image): otherwise each process of make
# test - every pytest worker, every service and simulator a test starts - compiles the
# sources anew and pytest rewrites every test module again (collecting the suite: 8.5 s of
# CPU in each worker instead of 3.2 s).
unexport PYTHONDONTWRITEBYTECODE

.PHONY: test test-long lint typecheck pytest protocol-coverage run bench fuzz clean status-page soak

# The runtime dependencies at the exact versions of constraints.txt (the
# image's); the test tools, which it does not list, resolve freely.
$(STAMP): pyproject.toml constraints.txt
	test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[test]'
	touch $(STAMP)

lint: $(STAMP)
	$(BIN)/ruff check src tests
	$(BIN)/ruff format --check src tests

typecheck: $(STAMP)
	$(BIN)/mypy

# Four workers (pytest-xdist) on a two-core machine: most tests wait on simulators,
# subprocesses and sockets (two workers kept the cores 35 % busy: 6 min 5 s, 3 min 51 s of
# CPU). As the suite grew, three took make test to 4 min 57 s (pytest 282-288 s); four
# take it to 4 min 12 s (pytest 237 s), and passed beside a busy loop taking a whole core
# (4 min 48-58 s). A fixed number, not "auto", which counts the host's cores where a
# container may have fewer.
PYTEST_WORKERS ?= 4
# Work stealing: each worker starts on its share of the tests and one that runs out takes
# half of what another still has queued. With the default (load), a worker is handed a
# run of tests in collection order that it alone may run while the others have nothing
# left: a minute of idle workers at the end of make test.
PYTEST_DIST ?= worksteal

pytest: $(STAMP)
	$(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist $(PYTEST_DIST) --cov=pkwbus --cov-report=term:skip-covered \
		$(PYTEST_SELECT)

# tests/protocol alone must cover src/pkwbus/protocol to PROTOCOL_COVERAGE % of its lines:
# the sans-I/O layer is proven by its own tests, not only through the service's. The figure
# is taken from tests/protocol's run with coverage of all of pkwbus; make test then runs the
# rest of the suite appending to the same data, so no test runs twice and the report at the
# end is the whole suite's, as make pytest's (the check costs a pytest start, not a rerun).
PROTOCOL_COVERAGE ?= 95

protocol-coverage: $(STAMP)
	$(BIN)/python -m pytest -q -n $(PYTEST_WORKERS) --dist $(PYTEST_DIST) --cov=pkwbus --cov-report= tests/protocol
	$(BIN)/python -m coverage report --include='*/pkwbus/protocol/*' --skip-covered --show-missing \
		--precision=1 --fail-under=$(PROTOCOL_COVERAGE)

test: lint typecheck
	$(MAKE) --no-print-directory protocol-coverage
	$(MAKE) --no-print-directory pytest PYTEST_SELECT="--ignore=tests/protocol --cov-append"

# The minute-long forms (60 s soak, a minute of three faulty pty lines on a busy machine,
# schemathesis over the API, 3 minutes of make soak); .ci/run runs them after make test,
# on two workers: the three minutes of make soak beside the others.
LONG_WORKERS ?= 2

test-long: $(STAMP)
	$(BIN)/python -m pytest -q -n $(LONG_WORKERS) --dist $(PYTEST_DIST) -m long

# An hour of pkwbus run on simulated lines with faults, lost ports and restarts, measured
# (README.md, "Measuring and fuzzing"); not in make test. SOAK_MINUTES=5 SOAK_LINES=3: a
# short one.
SOAK_MINUTES ?= 60
SOAK_LINES ?= 8

soak: $(STAMP)
	$(BIN)/python -m tests.soak.run --minutes $(SOAK_MINUTES) --lines $(SOAK_LINES)

# docs/status-page.png: the status page in headless chromium (deploy/browser-setup).
status-page: $(STAMP)
	PKWBUS_STATUS_SCREENSHOT=docs/status-page.png $(BIN)/python -m pytest -q -s \
		tests/service/http/test_status_page.py -k browser

run: $(STAMP)
	$(BIN)/pkwbus run --config config/demo.yaml

bench: $(STAMP)
	$(BIN)/python -m pip install --quiet -c constraints.txt -e '.[bench]'
	command -v socat >/dev/null || { echo "make bench needs socat (apt-get install -y socat)"; exit 2; }
	$(BIN)/python -m bench.run_all

fuzz: $(STAMP)
	$(BIN)/python -m pip install --quiet atheris
	$(BIN)/python fuzz/run.py --seconds $${SECONDS_PER_TARGET:-60}

clean:
	rm -rf $(VENV) .pytest_cache .mypy_cache .ruff_cache
