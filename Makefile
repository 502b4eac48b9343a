# A new user needs two commands: `make demo` and `make test`. Both install and build what they need.
SHELL := /bin/bash
ROOT := $(abspath $(dir $(lastword $(MAKEFILE_LIST))))
SETUP := source $(ROOT)/tools/env.sh && source $(ROOT)/.catkin_ws/devel/setup.bash &&
CXX_SOURCES = $(shell git -C $(ROOT) ls-files '*.cpp' '*.hpp' '*.h')
PY_SOURCES = src scripts test bench tools

.PHONY: setup build test lint format demo clean

setup:
	@bash $(ROOT)/tools/setup.sh

build: setup
	@bash $(ROOT)/tools/build.sh

test: build
	@bash $(ROOT)/tools/run_tests.sh

lint: setup
	clang-format --dry-run -Werror $(CXX_SOURCES)
	$(ROOT)/.venv/bin/ruff check $(PY_SOURCES)
	$(ROOT)/.venv/bin/ruff format --check $(PY_SOURCES)

format: setup
	clang-format -i $(CXX_SOURCES)
	$(ROOT)/.venv/bin/ruff check --fix $(PY_SOURCES)
	$(ROOT)/.venv/bin/ruff format $(PY_SOURCES)

demo: build
	@$(SETUP) bash $(ROOT)/tools/demo.sh

clean:
	rm -rf $(ROOT)/.catkin_ws $(ROOT)/test_results

# ---------------------------------------------------------------- monitor and experiment (issue 6)
.PHONY: bench-monitor experiment-paper

bench-monitor: build
	@$(SETUP) python3 $(ROOT)/bench/bench_monitor.py

experiment-paper: build
	@$(SETUP) bash $(ROOT)/tools/experiment_paper.sh
