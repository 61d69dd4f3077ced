# Two commands from a fresh machine: `make demo` and `make test`. Both create .venv first.
PYTHON ?= python3
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

.PHONY: demo test bench sample clean

$(STAMP): pyproject.toml
	@$(PYTHON) -c 'import sys; sys.exit(0 if sys.version_info >= (3, 11) else "wallmap needs Python 3.11 or newer (set PYTHON=...)")'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check -e '.[dev]'
	@# The detector's compiled loops: compiled once here (about 10 s), cached by numba.
	$(BIN)/python -c 'from wallmap.common.compiled import compile_all; compile_all()'
	@# wallmap's bytecode, compiled once here: an editable install has none, and where
	@# PYTHONDONTWRITEBYTECODE is set no process writes it, so each one compiled every module
	@# it imports again (0.15 s of every service's start). common/ and services/ by name:
	@# compileall does not follow wallmap/'s links to them.
	$(BIN)/python -m compileall -q wallmap common services
	@touch $(STAMP)

demo: $(STAMP)
	$(BIN)/wallmap demo

# Two workers, a test file each: most end-to-end time is spent waiting on real time and
# processes, so two files at once take half the time (9 min, not 20, on the 2-core machine).
test: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	$(BIN)/python -m pytest -q -n 2 --dist loadfile

# The sample bag that ships in the package: a generated scene, 128x96 depth at 5 Hz, LZ4.
sample: $(STAMP)
	rm -f wallmap/data/sample.bag wallmap/data/sample.bag.truth.json
	$(BIN)/wallmap scene wallmap/data/sample.bag --seed 11 --frames 1000 --sensor depth16 \
		--width 128 --height 96 --rate 5 --compress

# scikit-learn (the RANSAC the detector is measured against) goes in a folder of its own, which
# only benchmarks/detector_speed.py reads: in the venv, numba imports the scipy it brings at
# every service's start (0.2 s each), and the services would not start as a user's install does.
BENCH_ONLY := $(VENV)/bench-only
bench: $(STAMP)
	$(BIN)/python -m pip install --quiet --disable-pip-version-check --target $(BENCH_ONLY) \
		--upgrade 'scikit-learn>=1.3'
	$(BIN)/python benchmarks/run.py

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
