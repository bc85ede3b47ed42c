# exo_ilc_ros: `make demo` runs the paper's experiment, `make test` runs every check.
# Both create (or update) a local virtualenv in .venv with everything from PyPI.

PYTHON ?= $(shell command -v python3.11 || command -v python3)
VENV := .venv
BIN := $(VENV)/bin
STAMP := $(VENV)/.installed

# Never let DDS multicast discovery onto the network; logs stay in the checkout.
export ROS_AUTOMATIC_DISCOVERY_RANGE ?= LOCALHOST
export ROS_LOG_DIR ?= $(CURDIR)/.ros_log

.PHONY: venv demo test lint bench clean

$(STAMP): setup.py setup.cfg package.xml
	@$(PYTHON) -c 'import sys; assert sys.version_info[:2] == (3, 11), \
	  "the ros-jazzy wheels need CPython 3.11; set PYTHON=/path/to/python3.11"'
	$(PYTHON) -m venv $(VENV)
	$(BIN)/pip install -qq --upgrade pip
	$(BIN)/pip install -qq -e '.[test]'
	touch $@

venv: $(STAMP)

demo: $(STAMP)
	$(BIN)/exo-ilc simulate --mass-uncertainty 0.05 0.10 0.15

lint: $(STAMP)
	$(BIN)/ruff check .
	$(BIN)/mypy

test: lint
	$(BIN)/python -m pytest

bench: $(STAMP)
	$(BIN)/python -m bench.core_bench

clean:
	rm -rf $(VENV) build install log .ros_log
