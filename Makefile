# napari-physeg: the two commands a newcomer needs are `make demo` and `make test`.
# Both set up everything first (Debian packages for a virtual display when run as
# root, a virtual environment in .venv, the package and its test dependencies).
VENV ?= .venv
PY := $(VENV)/bin/python
export QT_API ?= pyqt5

.PHONY: setup demo test bench clean

setup:
	@bash scripts/setup.sh

demo: setup
	$(PY) scripts/demo.py

test: setup
	$(PY) -m pytest -p no:cacheprovider tests

bench: setup
	$(PY) benchmarks/segmentation.py

clean:
	rm -rf $(VENV) demo_output .pytest_cache
