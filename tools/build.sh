#!/usr/bin/env bash
# Builds the catkin workspace (devel space) and the test binaries. Extra CMake arguments pass through.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/env.sh"
mkdir -p "$gpl_ws/src"
ln -sfn "$gpl_root" "$gpl_ws/src/grid_puzzle_localization"
cd "$gpl_ws"
# The venv's python (made from /usr/bin/python3 with system site packages) sees rospy and catkin_pkg as
# well as the pip packages Debian lacks (python-lzf); catkin writes it into the shebang of the devel
# relays of catkin_install_python scripts, which roslaunch runs.
catkin_make -j"$(nproc)" -DPYTHON_EXECUTABLE="$gpl_root/.venv/bin/python3" -DCMAKE_BUILD_TYPE=Release -DCATKIN_ENABLE_TESTING=ON "$@"
catkin_make -j"$(nproc)" tests
