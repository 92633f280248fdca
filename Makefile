# napari-physeg: the two commands a newcomer needs are `make demo` and `make test`.
# Both set up everything first (Debian packages for a virtual display when run as
# root, a virtual environment in .venv, the package and its test dependencies).
VENV ?= .venv
PY := $(VENV)/bin/python
export QT_API ?= pyqt6

.PHONY: setup demo figures test bench docs clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(PY) scripts/demo.py

# Refresh the README's pictures from a demo run.
figures: demo
	cp demo_output/segmentation.png demo_output/matching_simulation.png demo_output/simulation.gif \
	   demo_output/tracking_nuclei.png docs/images/

# One pytest worker per core (pytest-xdist), each test file on one worker, so that a file's
# module fixtures (a dask cluster, the real images) are made once.
test: setup
	$(PY) -m pytest -p no:cacheprovider -n auto --dist loadfile tests

bench: setup
	$(PY) benchmarks/segmentation.py
	$(PY) benchmarks/matching.py
	$(PY) benchmarks/real.py
	$(PY) benchmarks/label_levels.py
	$(PY) benchmarks/crowd_contacts.py
	$(PY) benchmarks/drawings.py
	$(PY) benchmarks/scale.py --scale 0.5 2 3 --invert --slope --vignette --dim
	$(PY) benchmarks/noise.py
	$(PY) benchmarks/membranes.py
	$(PY) benchmarks/fields.py
	$(PY) benchmarks/tracking.py
	$(PY) benchmarks/tracking_warped.py
	$(PY) benchmarks/batch.py
	if [ -n "$$DISPLAY" ]; then $(PY) benchmarks/gui.py; else xvfb-run -a $(PY) benchmarks/gui.py; fi

# Build the documentation (docs/ and the API reference from the docstrings) into site/;
# --strict makes every warning (a broken link, a bad docstring) an error.
docs: setup
	@$(PY) -c "import mkdocs, mkdocstrings, mkdocstrings_handlers.python" 2>/dev/null || $(VENV)/bin/pip install -q -e ".[docs]"
	$(VENV)/bin/mkdocs build --strict

clean:
	rm -rf $(VENV) demo_output .pytest_cache
