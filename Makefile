# The commands of the README. Each sets up .venv/ (idempotently) before it runs.
.PHONY: bench benchmarks test test-system test-all test-under-load setup clean
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp

setup:
	@scripts/setup_env.sh

bench: setup
	.venv/bin/rubber-rig bench $(ARGS)

# every benchmark in benchmarks/, its figures written to docs/benchmarks/ (hours; ARGS="--only models,rig")
benchmarks: setup
	.venv/bin/python benchmarks/run_all.py $(ARGS)

# the everyday tier (<= 5 min on 2 cores): lint, unit and core scenario tests on simulated time, and a few
# end-to-end tests with the nodes as processes that prove the wiring (pytest marker `system` left out), on
# TEST_WORKERS pytest-xdist workers (the end-to-end tests all on one of them, one at a time: test/conftest.py)
TEST_WORKERS ?= 2
test: setup
	.venv/bin/ruff check .
	.venv/bin/python -m pytest -m "not system" -n $(TEST_WORKERS) --dist loadgroup $(PYTEST_ARGS)

# the long runs on the wall clock (real-time fault matrix, detector trip delays, the conformance matrix in a
# network namespace): logic the simulated-time tests cover, run once more in real time (~10 min)
test-system: setup
	.venv/bin/python -m pytest -m system $(PYTEST_ARGS)

test-all: test test-system

# make test three times while one busy loop per core runs (benchmarks/busy_load.py): a busy computer must not
# make a test fail
test-under-load: setup
	.venv/bin/python benchmarks/busy_load.py --runs $(or $(RUNS),3) -- $(MAKE) --no-print-directory test

clean:
	rm -rf build .venv *.egg-info
