# Sourced by the tools: the catkin workspace around this package and its setup file.
# The package is the repo root; the workspace lives in .catkin_ws with a link back to it.
gpl_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
gpl_ws="${GPL_WS:-$gpl_root/.catkin_ws}"
# catkin's Python tooling must run on Debian's Python (the pyenv python3 cannot see catkin_pkg).
export PATH="/usr/bin:$PATH"
