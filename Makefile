# The two commands of the README. Each sets up .venv/ (idempotently) before it runs.
.PHONY: bench test setup clean
export RMW_IMPLEMENTATION ?= rmw_fastrtps_cpp

setup:
	@scripts/setup_env.sh

bench: setup
	.venv/bin/rubber-rig bench $(ARGS)

test: setup
	.venv/bin/ruff check .
	.venv/bin/python -m pytest $(PYTEST_ARGS)

clean:
	rm -rf build .venv *.egg-info
