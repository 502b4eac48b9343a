#!/usr/bin/env bash
# Runs inside the Debian 11 root (tools/noetic_era/run.sh), as a Noetic user would in a catkin workspace /ws with
# this package in src/: catkin_make with g++-9 and tests on (catkin's default), the tests, catkin_make install, and
# a tracking run of `gpm experiment` (the demo's launch, grid puzzle mode) from the install space alone.
set -euo pipefail
ws=/ws
pkg=$ws/src/grid_puzzle_localization
check=/tmp/gpl_install_check
started=$SECONDS
log() { printf '== noetic-era %4ss (in the root): %s\n' "$((SECONDS - started))" "$*"; }

cd "$ws"
log "catkin_make (g++-9, tests on)"
catkin_make -j"$(nproc)" -DCMAKE_C_COMPILER=gcc-9 -DCMAKE_CXX_COMPILER=g++-9 -DCMAKE_BUILD_TYPE=Release >"$ws/build.log" 2>&1 \
  || { tail -60 "$ws/build.log"; exit 1; }
catkin_make -j"$(nproc)" tests >>"$ws/build.log" 2>&1 || { tail -60 "$ws/build.log"; exit 1; }
grep -E "warning:" "$ws/build.log" | sort -u | sed 's/^/build warning: /' || true

log "tests: every gtest, pytest and rostest"
status=0
GPL_WS=$ws bash "$pkg/tools/run_tests.sh" gtest pytest rostest || status=1

log "catkin_make install; a short simulated drive from the devel space"
catkin_make -j"$(nproc)" install >>"$ws/build.log" 2>&1 || { tail -60 "$ws/build.log"; exit 1; }
rm -rf "$check" && mkdir -p "$check"
(set +u && source devel/setup.bash && gpm simulate courtyard --scale 0.2 --duration 8 --seed 2 -o "$check/scenario" --quiet)

log "gpm experiment from the install space alone (devel space and sources moved away)"
restore() {  # returns 0 when there is nothing to move back: as the EXIT trap, under set -e, its status is the script's
  if [[ -d $ws/devel.away ]]; then mv "$ws/devel.away" "$ws/devel"; fi
  if [[ -d $ws/src.away ]]; then mv "$ws/src.away" "$ws/src"; fi
}
trap restore EXIT
cp "$pkg/tools/noetic_era/install_space_report.py" "$check/"
mv "$ws/devel" "$ws/devel.away"
mv "$ws/src" "$ws/src.away"
(
  cd "$check"
  set +u  # the setup files read unset variables (Debian's /etc/catkin/profile.d: ROS_DISTRO)
  source "$ws/install/setup.bash"
  strace -f -qq -e trace=openat,execve -e signal=none -o "$check/files.trace" \
    gpm experiment "$check/scenario" -o "$check/out" --modes grid_puzzle --preset demo --settle 1.5 >"$check/experiment.log" 2>&1 \
    || { tail -40 "$check/experiment.log"; exit 1; }
  python3 "$check/install_space_report.py" "$check/out/summary.json" "$check/files.trace" "$ws/install" \
    --max-rmse 0.05 --out "$check/install_space.json"
) || status=1
restore
# The failing tests again, after the install-space run's long listing: a log's tail then names them.
if [[ -s $pkg/test_results/failed.txt ]]; then cat "$pkg/test_results/failed.txt"; fi
log "done (status $status)"
exit $status
