# dpi: two commands on a fresh Debian machine.
#   make demo   set up, then run the workflow on the bundled synthetic demo (results/)
#   make test   set up, then run the test suite
VENV ?= .venv
CORES ?= 2
PYTEST_ARGS ?=

.PHONY: setup demo test test-fast test-slurm benchmarks tables clean

setup:
	bash scripts/setup.sh

demo: setup
	$(VENV)/bin/snakemake --cores $(CORES)

test: setup
	$(VENV)/bin/python -m pytest -q $(PYTEST_ARGS)

test-slurm: setup
	$(VENV)/bin/python -m pytest -q -m slurm $(PYTEST_ARGS)

test-fast: setup
	$(VENV)/bin/python -m pytest -q -m "not slow" $(PYTEST_ARGS)

benchmarks: setup
	$(VENV)/bin/python benchmarks/render_step.py

tables: setup
	$(VENV)/bin/dpi tables

clean:
	rm -rf results .snakemake captures/demo
