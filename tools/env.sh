# Sourced by the tools: the catkin workspace around this package and its setup file.
# The package is the repo root. Its catkin workspace (a src/ link back to the repo, build and devel
# spaces) lives outside the repo, so rosrun's search of the package directory never walks into the
# workspace and back through the link. build/setup.bash in the repo forwards to it.
gpl_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
gpl_ws="${GPL_WS:-${XDG_CACHE_HOME:-$HOME/.cache}/grid_puzzle_localization/ws-$(printf %s "$gpl_root" | sha1sum | cut -c1-12)}"
export GPL_WS="$gpl_ws"
# catkin's Python tooling must run on Debian's Python (the pyenv python3 cannot see catkin_pkg).
export PATH="/usr/bin:$PATH"
# Test fixtures (synthetic scenes, tiles and bags) are not part of the product package: tests, rostests and the
# quick benchmarks import them as `fixtures` from test/.
export PYTHONPATH="$gpl_root/test${PYTHONPATH:+:$PYTHONPATH}"
