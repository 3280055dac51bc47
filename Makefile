# The two commands: `make demo` (track the sample bag and evaluate) and `make test` (the suite).
VENV := .venv
PY := $(VENV)/bin/python
AWALKER := $(VENV)/bin/awalker
# Test workers: pytest-xdist, one DDS domain per worker (see test/conftest.py).
TEST_WORKERS ?= 2

.PHONY: demo test setup bench clean

setup:
	@bash scripts/setup_env.sh

demo: setup
	@$(AWALKER) demo --force

test: setup
	@$(PY) -m pytest -n $(TEST_WORKERS) test

bench: setup
	@for b in benchmarks/bench_*.py; do echo "== $$b"; $(PY) $$b; done

clean:
	rm -rf $(VENV) build install log
