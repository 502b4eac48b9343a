# A new user needs two commands: `make demo` and `make test`. Both install and build what they need.
SHELL := /bin/bash
ROOT := $(abspath $(dir $(lastword $(MAKEFILE_LIST))))
SETUP := source $(ROOT)/tools/env.sh && source $(ROOT)/build/setup.bash &&
CXX_SOURCES = $(shell git -C $(ROOT) ls-files '*.cpp' '*.hpp' '*.h')
PY_SOURCES = src scripts test bench tools

.PHONY: setup build test lint format demo clean check-rosdep

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
	$(ROOT)/.venv/bin/vermin -q --no-tips --violations -t=3.8- $(PY_SOURCES)

# package.xml against rosdep, offline (../shared/rosdistro): every key resolves for Ubuntu 20.04 with Noetic, the
# system keys for Debian 12 and 11, and every find_package and third-party Python import is covered by a key.
check-rosdep: setup
	@$(ROOT)/.venv/bin/python3 $(ROOT)/tools/check_rosdep.py

format: setup
	clang-format -i $(CXX_SOURCES)
	$(ROOT)/.venv/bin/ruff check --fix $(PY_SOURCES)
	$(ROOT)/.venv/bin/ruff format $(PY_SOURCES)

demo: build
	@$(SETUP) bash $(ROOT)/tools/demo.sh

clean:
	bash $(ROOT)/tools/noetic_era/run.sh --unmount
	source $(ROOT)/tools/env.sh && rm -rf --one-file-system "$$GPL_WS" $(ROOT)/build $(ROOT)/test_results

# ---------------------------------------------------------------- the Noetic-era stack (Debian 11 root)
.PHONY: test-noetic-era
# A Debian 11 root (cached in $GPL_WS/noetic_era): Debian's ROS 1 and what rosdep resolves from package.xml, then
# catkin_make with g++-9, every gtest, pytest and rostest, and a run from the install space (docs/development.md).
test-noetic-era: setup
	@bash $(ROOT)/tools/noetic_era/run.sh

# ---------------------------------------------------------------- tiler benchmark
.PHONY: bench-tiling
bench-tiling: build
	@$(SETUP) python3 $(ROOT)/bench/bench_tiling.py

# ---------------------------------------------------------------- tile provider benchmark
.PHONY: bench-provider
bench-provider: build
	@$(SETUP) python3 $(ROOT)/bench/bench_provider.py

# ---------------------------------------------------------------- NDT scan matcher
.PHONY: bench-ndt tsan

# Builds bench/bench_ndt.cpp in the catkin workspace and prints one JSON line per configuration.
# Build output goes to build/bench_ndt_build.log so stdout holds only the JSON lines.
bench-ndt: setup
	@log=$(ROOT)/build/bench_ndt_build.log; mkdir -p $(ROOT)/build; \
	  { bash $(ROOT)/tools/build.sh && $(SETUP) cd $$GPL_WS && catkin_make -j2 bench_ndt; } >$$log 2>&1 \
	  || { tail -40 $$log; exit 1; }
	@$(SETUP) $$GPL_WS/devel/lib/grid_puzzle_localization/bench_ndt

# ThreadSanitizer run of the snapshot/background-update test in its own plain CMake build dir.
tsan: setup
	cmake -S $(ROOT)/test/tsan -B $(ROOT)/build/build_tsan -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
	cmake --build $(ROOT)/build/build_tsan -j2
	TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" $(ROOT)/build/build_tsan/test_ndt_concurrency_tsan

# ---------------------------------------------------------------- NDT localizer
.PHONY: bench-localizer tsan-localizer
# Build output goes to build/bench_localizer_build.log so stdout holds only the JSON lines.
bench-localizer: setup
	@log=$(ROOT)/build/bench_localizer_build.log; mkdir -p $(ROOT)/build; \
	  bash $(ROOT)/tools/build.sh >$$log 2>&1 || { tail -40 $$log; exit 1; }
	@$(SETUP) python3 $(ROOT)/bench/bench_localizer.py

# ThreadSanitizer build of the ROS-free localizer core (update worker, NDT target, localizer) and its
# gtests in a separate build tree (see test/tsan_localizer); roscpp itself is not instrumented.
tsan-localizer: setup
	cmake -S $(ROOT)/test/tsan_localizer -B $(ROOT)/build/build_tsan_localizer -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
	cmake --build $(ROOT)/build/build_tsan_localizer -j2
	cd $(ROOT) && TSAN_OPTIONS="halt_on_error=1 second_deadlock_stack=1" $(ROOT)/build/build_tsan_localizer/tsan_localizer_tests

# ---------------------------------------------------------------- memory against map size
.PHONY: bench-scaling
# Build output goes to build/bench_scaling_build.log so stdout holds only the JSON lines.
bench-scaling: setup
	@log=$(ROOT)/build/bench_scaling_build.log; mkdir -p $(ROOT)/build; \
	  bash $(ROOT)/tools/build.sh >$$log 2>&1 || { tail -40 $$log; exit 1; }
	@$(SETUP) python3 $(ROOT)/bench/bench_scaling.py $(ARGS)

# ---------------------------------------------------------------- scenario simulator
.PHONY: bench-sim
# Build output goes to build/bench_sim_build.log so stdout holds only the JSON.
bench-sim: setup
	@log=$(ROOT)/build/bench_sim_build.log; mkdir -p $(ROOT)/build; \
	  bash $(ROOT)/tools/build.sh >$$log 2>&1 || { tail -40 $$log; exit 1; }
	@$(SETUP) python3 $(ROOT)/bench/bench_sim.py

# ---------------------------------------------------------------- global localization
.PHONY: bench-global-localization
# make bench-global-localization [ARGS="--quick" | ARGS="--trials 100 --datasets mulran_riverside02"]
# Build output goes to build/bench_global_localization_build.log so stdout holds only the JSON lines.
bench-global-localization: setup
	@log=$(ROOT)/build/bench_global_localization_build.log; mkdir -p $(ROOT)/build; \
	  bash $(ROOT)/tools/build.sh >$$log 2>&1 || { tail -40 $$log; exit 1; }
	@$(SETUP) python3 $(ROOT)/bench/bench_global_localization.py $(ARGS)

# ---------------------------------------------------------------- map store (tiles over HTTP)
.PHONY: bench-map-store
# make bench-map-store [ARGS="--quick"]: tiles fetched from nginx on localhost, then a drive through the localizer
# with its tiles fetched through a delaying proxy, the server stopped mid-drive (docs/map_store.md).
# Build output goes to build/bench_map_store_build.log so stdout holds only the JSON lines.
bench-map-store: setup
	@log=$(ROOT)/build/bench_map_store_build.log; mkdir -p $(ROOT)/build; \
	  bash $(ROOT)/tools/build.sh >$$log 2>&1 || { tail -40 $$log; exit 1; }
	@$(SETUP) python3 $(ROOT)/bench/bench_map_store.py $(ARGS)

# make bench-map-worker [ARGS="--quick"]: the map worker's CPU per metre driven on kitti00_far per window update
# distance (docs/map_store.md).
.PHONY: bench-map-worker
bench-map-worker: setup
	@log=$(ROOT)/build/bench_map_worker_build.log; mkdir -p $(ROOT)/build; \
	  bash $(ROOT)/tools/build.sh >$$log 2>&1 || { tail -40 $$log; exit 1; }
	@$(SETUP) python3 $(ROOT)/bench/bench_map_worker.py $(ARGS)

# ---------------------------------------------------------------- block maps
.PHONY: bench-blocks
bench-blocks: build
	@$(SETUP) python3 $(ROOT)/bench/bench_blocks.py

# ---------------------------------------------------------------- monitor and experiment
.PHONY: bench-monitor experiment-paper

bench-monitor: build
	@$(SETUP) python3 $(ROOT)/bench/bench_monitor.py

# make experiment-paper [SCENARIOS="courtyard urban"]
experiment-paper: build
	@$(SETUP) bash $(ROOT)/tools/experiment_paper.sh $(SCENARIOS)

# ---------------------------------------------------------------- reliability: fuzzing, sanitizers, faults
.PHONY: fuzz-build fuzz asan reliability
FUZZ_SECONDS ?= 60
FUZZ_PARALLEL ?= 2

# libFuzzer binaries (clang, ASan + UBSan) of test/fuzz in their own build tree.
fuzz-build: setup
	cmake -S $(ROOT)/test/fuzz -B $(ROOT)/build/build_fuzz -DCMAKE_CXX_COMPILER=clang++-14 \
	  -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
	cmake --build $(ROOT)/build/build_fuzz -j2

# make fuzz FUZZ_SECONDS=600: every fuzz target (C++ and Python) for that long; one JSON line per target.
fuzz: fuzz-build
	$(ROOT)/.venv/bin/python3 $(ROOT)/tools/fuzz.py --seconds $(FUZZ_SECONDS) --parallel $(FUZZ_PARALLEL)

# Every gtest of test/cpp under AddressSanitizer and UndefinedBehaviorSanitizer, in its own build tree.
asan: setup
	cmake -S $(ROOT)/test/asan -B $(ROOT)/build/build_asan -DCMAKE_BUILD_TYPE=RelWithDebInfo >/dev/null
	cmake --build $(ROOT)/build/build_asan -j2
	cd $(ROOT) && status=0; for t in $(ROOT)/build/build_asan/test_*; do \
	  echo "== asan $$(basename $$t)"; \
	  ASAN_OPTIONS="detect_leaks=1" UBSAN_OPTIONS="print_stacktrace=1" $$t || status=1; \
	done; exit $$status

# make reliability [FUZZ_SECONDS=600]: every fuzz target (at niceness 19, FUZZ_PARALLEL at a time), the fault
# tests and the replay of the inputs fuzzing found; prints a markdown report, writes build/reliability/report.jsonl.
reliability: fuzz-build build
	@$(SETUP) $(ROOT)/.venv/bin/python3 $(ROOT)/tools/reliability.py --fuzz-seconds $(FUZZ_SECONDS) \
	  --parallel $(FUZZ_PARALLEL)

# ---------------------------------------------------------------- tracking on real and hard recordings
.PHONY: experiment-real experiment-hard
# One JSON line per variant and mode (tools/experiment_tracking.py, also in build/experiment_tracking/results.jsonl);
# long-running (real-time playback), not in CI.
# make experiment-real: KITTI-00 keyframes (../shared/data/real/kitti00_far), both stretches: as recorded, 20 %
#   dropped with an 8 s gap, a start 20 m and 90 deg off, a hint (sigma 20 m), no start at all.
# make experiment-hard: simulated hand-held walks (10 Hz and 2 Hz scans) and a recording with gaps.
# VARIANTS="kitti_s1 kitti_s1_hint20 handheld_2hz ..." runs only those; TRACKING_ARGS=--cpu-hog keeps core 1 busy,
# TRACKING_ARGS="--modes global grid_puzzle" runs only those modes (default: also grid_puzzle_rospy).
experiment-real: build
	@$(SETUP) python3 $(ROOT)/tools/experiment_tracking.py $(or $(VARIANTS),real) $(TRACKING_ARGS)

experiment-hard: build
	@$(SETUP) python3 $(ROOT)/tools/experiment_tracking.py $(or $(VARIANTS),hard) $(TRACKING_ARGS)
