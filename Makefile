# dpi: two commands on a fresh Debian machine.
#   make demo   set up, then run the workflow on the bundled synthetic demo (results/)
#   make test   set up, then run the test suite
VENV ?= .venv
CORES ?= 2
PYTEST_ARGS ?=
# the real HDR panoramas the real-light study rows use (the manifest's files; dpi.prior.panoramas)
PANORAMAS ?= ../shared/panoramas

.PHONY: setup demo test test-fast test-slurm benchmarks studies tables clean

setup:
	bash scripts/setup.sh

demo: setup
	$(VENV)/bin/snakemake --cores $(CORES)

test: setup
	$(VENV)/bin/python -m pytest -q -n $(CORES) --dist loadscope $(PYTEST_ARGS)

test-slurm: setup
	$(VENV)/bin/python -m pytest -q -m slurm $(PYTEST_ARGS)

test-fast: setup
	$(VENV)/bin/python -m pytest -q -n $(CORES) --dist loadscope -m "not slow" $(PYTEST_ARGS)

# the quick benchmarks (minutes): cost of a render step, of a dps step, of the procedural worlds
benchmarks: setup
	$(VENV)/bin/python benchmarks/timing/render_step.py
	$(VENV)/bin/python benchmarks/timing/dps_step.py
	$(VENV)/bin/python benchmarks/timing/outdoor_generator.py

# the studies behind the docs' tables (hours on 2 cores; a row already there with the same settings is kept),
# then the tables regenerated from their CSVs
studies: setup
	$(VENV)/bin/python benchmarks/posterior_study.py --panoramas $(PANORAMAS)
	$(VENV)/bin/python benchmarks/calibration_study.py
	$(VENV)/bin/python benchmarks/roughness_study.py
	$(VENV)/bin/python benchmarks/resolution_study.py
	$(VENV)/bin/python benchmarks/lens_study.py
	$(VENV)/bin/python benchmarks/tradeoff.py --presets draft
	$(VENV)/bin/python benchmarks/contraction/contraction.py
	$(VENV)/bin/python benchmarks/doc_tables.py

tables: setup
	$(VENV)/bin/python benchmarks/doc_tables.py

clean:
	rm -rf results .snakemake captures/demo
