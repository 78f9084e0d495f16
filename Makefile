# The two commands of the README. Each sets up .venv/ (idempotently) before it runs.
.PHONY: bench benchmarks test setup clean
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp

setup:
	@scripts/setup_env.sh

bench: setup
	.venv/bin/rubber-rig bench $(ARGS)

# every benchmark in benchmarks/, its figures written to docs/benchmarks/ (hours; ARGS="--only models,rig")
benchmarks: setup
	.venv/bin/python benchmarks/run_all.py $(ARGS)

test: setup
	.venv/bin/ruff check .
	.venv/bin/python -m pytest $(PYTEST_ARGS)

clean:
	rm -rf build .venv *.egg-info
