#!/usr/bin/env bash
# Builds the catkin workspace (devel space) and the test binaries. Extra CMake arguments pass through.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
mkdir -p "$gpl_ws/src"
ln -sfn "$gpl_root" "$gpl_ws/src/grid_puzzle_localization"
cd "$gpl_ws"
catkin_make -j"$(nproc)" -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=Release -DCATKIN_ENABLE_TESTING=ON "$@"
catkin_make -j"$(nproc)" tests
