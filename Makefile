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
	@echo "make demo: not yet implemented (the experiment runner lands with issue 6)"

clean:
	rm -rf $(ROOT)/.catkin_ws $(ROOT)/test_results

# ---------------------------------------------------------------- NDT localizer (issue 4)
.PHONY: bench-localizer tsan-localizer
bench-localizer: build
	@$(SETUP) python3 $(ROOT)/bench/bench_localizer.py

# ThreadSanitizer build of the ROS-free localizer core (update worker, NDT target, localizer) and its
# gtests, in a separate build tree; roscpp itself is not instrumented. OMP_NUM_THREADS=1: Debian's libgomp
# is not instrumented, so TSan would report its barrier-synchronised team as races; the threads under test
# are the map worker and the scan thread, which this leaves intact.
TSAN_BUILD := $(ROOT)/.catkin_ws/tsan
tsan-localizer: setup
	cmake -S $(ROOT)/test/tsan -B $(TSAN_BUILD) -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
	cmake --build $(TSAN_BUILD) -j2
	cd $(ROOT) && OMP_NUM_THREADS=1 TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" $(TSAN_BUILD)/tsan_localizer_tests
