# dpi: two commands on a fresh Debian machine.
#   make demo   set up, then run the workflow on the bundled synthetic demo (results/)
#   make test   set up, then run the test suite
VENV ?= .venv
CORES ?= 2
PYTEST_ARGS ?=
# the real HDR panoramas the real-light study rows use (the manifest's files; dpi.prior.panoramas)
PANORAMAS ?= ../shared/panoramas

.PHONY: setup demo test test-fast test-slurm benchmarks studies list-studies tables clean

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

# the studies behind the README's and docs' tables (hours on 2 cores; a row already there with the same settings is
# kept), then the tables regenerated from their CSVs; each command is its folder's README's (`make list-studies`).
# The hotdog needs the authors' capture prepared (benchmarks/hotdog/README.md): HOTDOG=that folder.
HOTDOG ?=
studies: setup
	$(VENV)/bin/python benchmarks/posterior/posterior.py --panoramas $(PANORAMAS) --samplers proximal unperturbed paper --dps unperturbed:proximal.perturb=0
	$(VENV)/bin/python benchmarks/calibration/calibration.py --scenes blob_sun_metal blob_sun_rough blob_ldr_metal blob_ldr_rough torus_sun_metal torus_sun_rough --methods init none sds dip gan reni dps --samplers proximal --repeats 3 --samples 4
	$(VENV)/bin/python benchmarks/roughness/roughness.py
	$(VENV)/bin/python benchmarks/resolution/resolution.py
	$(VENV)/bin/python benchmarks/lens/lens.py
	$(VENV)/bin/python benchmarks/tradeoff/tradeoff.py --presets draft
	$(VENV)/bin/python benchmarks/contraction/contraction.py
	$(VENV)/bin/python benchmarks/readings/readings.py --forced --panoramas $(PANORAMAS) --repeats 1 --samples 2
	$(VENV)/bin/python benchmarks/readings/readings.py --panoramas $(PANORAMAS) --repeats 3 --samples 4
	$(VENV)/bin/python benchmarks/preprocess/preprocess.py --backgrounds textured --no-stereo --arc 180 --out benchmarks/preprocess/mask_witnesses.csv
	$(VENV)/bin/python benchmarks/preprocess/preprocess.py --backgrounds textured --no-stereo --arc 360 --out benchmarks/preprocess/mask_witnesses.csv
	$(VENV)/bin/python benchmarks/real_photos/real_photos.py --capture skull_photos
	$(VENV)/bin/python benchmarks/real_photos/real_photos.py --capture saharov32 --captures ../shared/captures
	$(VENV)/bin/snakemake --cores $(CORES)
	$(VENV)/bin/python benchmarks/sun_size/sun_size.py results
	$(VENV)/bin/python benchmarks/seams/seams.py demo=results skull=results/benchmarks/real_photos/results scan=results/benchmarks/posterior_study/results --scenes demo skull_photos torus_scan
	$(if $(HOTDOG),$(VENV)/bin/python benchmarks/hotdog/hotdog.py $(HOTDOG),@echo "hotdog skipped: make studies HOTDOG=the prepared capture (benchmarks/hotdog/README.md)")
	$(VENV)/bin/python benchmarks/doc_tables.py

# each table the README and docs show: its study folder and the command that makes its CSV
list-studies: setup
	$(VENV)/bin/python benchmarks/doc_tables.py --list

tables: setup
	$(VENV)/bin/python benchmarks/doc_tables.py

clean:
	rm -rf results .snakemake captures/demo
