#!/usr/bin/env bash
# Runs every test (gtest binaries, pytest, rostest) from a shell that sourced the devel space, then
# judges the run by the result files, not by exit codes alone.
# Usage: run_tests.sh [gtest|pytest|rostest|bench|fuzz ...]
# bench: every `make bench-*` in its quick mode (test/bench), so a broken benchmark fails the run.
# fuzz: a short pass of every fuzz target.
set -o pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
source "$gpl_ws/devel/setup.bash"
results="$gpl_root/test_results"
rm -rf "$results"
mkdir -p "$results/gtest" "$results/pytest" "$results/rostest" "$results/bench" "$results/fuzz"
suites=("$@")
((${#suites[@]})) || suites=(gtest pytest rostest bench fuzz)
status=0

run_gtest() {
  local bin_dir="$gpl_ws/devel/lib/grid_puzzle_localization" found=0
  for bin in "$bin_dir"/test_*; do
    [[ -x "$bin" && -f "$bin" ]] || continue
    found=1
    echo "== gtest $(basename "$bin")"
    (cd "$gpl_root" && "$bin" --gtest_output="xml:$results/gtest/$(basename "$bin").xml") || status=1
  done
  ((found)) || { echo "run_tests: no gtest binaries in $bin_dir"; status=1; }
}

run_pytest() {
  echo "== pytest"
  # Two workers (pytest-xdist), each test file on one of them: a file's module fixtures (a whole experiment run,
  # say) run once. Every test passes with a core taken by another process, so the two share the machine.
  (cd "$gpl_root" && python3 -m pytest -q -n 2 --dist loadfile test/python --junitxml="$results/pytest/pytest.xml")
  local rc=$?
  # 5 = no tests collected: the result check below reports that as a failure with a reason.
  ((rc == 0 || rc == 5)) || status=1
}

run_bench() {
  echo "== bench (quick modes)"
  (cd "$gpl_root" && python3 -m pytest -q test/bench --junitxml="$results/bench/bench.xml") || status=1
}

# GPL_ROSTEST_JOBS rostest files at a time (default 2): each starts its own master on a free port, and their nodes
# mostly wait on simulated time, so two share the machine as the tests' busy-machine runs do. Each file's output is
# printed whole once it ends.
run_rostest() {
  export ROS_TEST_RESULTS_DIR="$results/rostest"
  local jobs=${GPL_ROSTEST_JOBS:-2} logs name
  logs=$(mktemp -d)
  for t in "$gpl_root"/test/rostest/*.test; do
    while (($(jobs -rp | wc -l) >= jobs)); do wait -n; done
    name=$(basename "$t")
    (
      rostest --results-base-dir="$results/rostest" grid_puzzle_localization "$name" >"$logs/$name.log" 2>&1
      echo $? >"$logs/$name.rc"
      { flock 9 && echo "== rostest $name" && cat "$logs/$name.log"; } 9>"$logs/print.lock"
    ) &
  done
  wait
  for t in "$gpl_root"/test/rostest/*.test; do
    name=$(basename "$t")
    [[ $(cat "$logs/$name.rc" 2>/dev/null) == 0 ]] || { echo "run_tests: rostest $name failed"; status=1; }
  done
  rm -rf "$logs"
}

# A short pass of every fuzz target (FUZZ_SECONDS each, default 3) after replaying the inputs fuzzing found.
run_fuzz() {
  echo "== fuzz"
  make -s -C "$gpl_root" fuzz-build >/dev/null || { status=1; return; }
  "$gpl_root/.venv/bin/python3" "$gpl_root/tools/fuzz.py" --seconds "${FUZZ_SECONDS:-3}" \
    --junit "$results/fuzz/fuzz.xml" || status=1
}

for suite in "${suites[@]}"; do "run_$suite"; done
python3 "$gpl_root/tools/check_results.py" "$results" "${suites[@]}" || status=1
exit $status
