# exo_ilc_ros: `make demo` runs the paper's experiment, `make test` runs every check (the docs
# build included), `make docs` builds the documentation site into docs/_build/html.
# Both create (or update) a local virtualenv in .venv with everything from PyPI.

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Never let DDS multicast discovery onto the network; logs stay in the checkout.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export ROS_LOG_DIR ?= $(CURDIR)/.ros_log

.PHONY: venv bytecode demo demo-spread test lint docs bench soak clean

# The first run in a fresh environment (or after the kernels changed) compiles the numba kernels
# (~20 s, silent) and caches them (exo_ilc_ros/core/_numba_cache.py).
NUMBA_CACHE := $(or $(NUMBA_CACHE_DIR),$(or $(XDG_CACHE_HOME),$(HOME)/.cache)/exo_ilc_ros/numba)
NUMBA_NOTE := echo "make: (the first run in a fresh environment compiles the numba kernels, \
about 20 s without output, and caches them under $(NUMBA_CACHE))"

$(STAMP): setup.py setup.cfg package.xml
	@$(PYTHON) -c 'import sys; assert sys.version_info[:2] == (3, 11), \
	  "the ros-jazzy wheels need CPython 3.11; set PYTHON=/path/to/python3.11"'
	@echo "make: installing exo_ilc_ros and its dependencies from PyPI into $(VENV) (about 1.5 GB;"
	@echo "make: 1-2 min the first time, quiet until done; later only when setup.py changes)"
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -qq --upgrade pip
	$(BIN)/pip install -qq -e '.[test]'
	touch $@

venv: bytecode

# The package's bytecode, written even where PYTHONDONTWRITEBYTECODE is set (pip does the same
# for an installed package): without it every command compiles ~110 modules, ~0.25 s of start-up.
bytecode: $(STAMP)
	@$(BIN)/python -m compileall -q exo_ilc_ros

demo: bytecode
	@echo "make: the paper's experiment in-process, 150 trials at 5, 10 and 15 % (a few seconds)"
	@$(NUMBA_NOTE)
	$(BIN)/exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15

# The sign law amplifies last-bit differences: the same three runs 20 times each from initial
# states perturbed by 1e-12 rad, iterations to the bound as median [min-max] (2-3 min).
demo-spread: $(STAMP)
	@echo "make: the paper's experiment and 20 perturbed runs of each (2-3 min)"
	@$(NUMBA_NOTE)
	$(BIN)/exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15 --spread 20 --quiet

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

# The documentation site (Sphinx + MyST; API from the docstrings, CLI from the parser), warnings
# as errors: a broken link or cross-reference, or a docstring that does not render, fails it.
docs: $(STAMP)
	@echo "make: building the documentation into docs/_build/html (about 30 s)"
	$(BIN)/sphinx-build -W --keep-going -q -b html docs docs/_build/html

test: bytecode lint docs
	@$(NUMBA_NOTE)
	@echo "make: running the whole test suite (20-25 min on 2 idle cores;"
	@echo "make: most of it real ROS 2 graphs over DDS and a colcon build); pytest prints a dot per test"
	$(BIN)/python -m pytest

bench: $(STAMP)
	$(BIN)/python -m bench.core_bench

# The recording soak (nightly, not in `make test`): 20 recorded graph runs of 10 trials beside a
# CPU hog, every message each node published found in its bag (test/test_recording_loss.py;
# 6-9 min on 2 cores). EXO_ILC_LOSS_RUNS=N runs N instead of 20.
soak: $(STAMP)
	@echo "make: the recording soak, 20 graph runs of 10 trials under load (6-9 min)"
	EXO_ILC_SOAK=1 $(BIN)/python -m pytest -q -s -m slow test/test_recording_loss.py

clean:
	rm -rf $(VENV) build install log .ros_log docs/_build docs/api
