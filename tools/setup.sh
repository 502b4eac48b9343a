#!/usr/bin/env bash
# Installs everything the package needs, idempotently and without prompts:
# Debian packages first, then the Python packages Debian lacks into .venv: the user's (requirements.txt) and the
# developers' tools (tools/requirements-dev.txt, which includes the user's).
# Fast when everything is already there (one dpkg-query, one hash comparison).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
apt_list="$root/tools/apt-packages.txt"
req_user="$root/requirements.txt"
req_dev="$root/tools/requirements-dev.txt"
venv="$root/.venv"

mapfile -t wanted < <(sed -e 's/#.*//' -e '/^\s*$/d' "$apt_list" | tr -d ' ')
missing=()
for pkg in "${wanted[@]}"; do
  status=$(dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null || true)
  [[ "$status" == "install ok installed" ]] || missing+=("$pkg")
done
if ((${#missing[@]})); then
  echo "setup: installing Debian packages: ${missing[*]}"
  sudo_cmd=()
  [[ $(id -u) -eq 0 ]] || sudo_cmd=(sudo)
  export DEBIAN_FRONTEND=noninteractive
  "${sudo_cmd[@]}" apt-get update -qq
  "${sudo_cmd[@]}" apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi

# The venv must come from Debian's Python: the pyenv python3 on PATH cannot see ROS modules.
if [[ ! -x "$venv/bin/python3" ]]; then
  echo "setup: creating $venv from /usr/bin/python3 (with system site packages for rospy)"
  /usr/bin/python3 -m venv --system-site-packages "$venv"
fi
stamp="$venv/.requirements.sha256"
want_hash=$(cat "$req_user" "$req_dev" | sha256sum | cut -d' ' -f1)
if [[ ! -f "$stamp" || "$(cat "$stamp")" != "$want_hash" ]]; then
  echo "setup: installing Python packages from $req_user and $req_dev"
  "$venv/bin/python3" -m pip install -q --disable-pip-version-check -r "$req_user" -r "$req_dev"
  echo "$want_hash" >"$stamp"
fi
