#!/usr/bin/env bash
# make test-noetic-era: the package as a Noetic user gets it, on Debian 11 (bullseye), the closest stand-in for
# Ubuntu 20.04 + Noetic these machines run (g++-9 9.3, Ceres 1.14, Eigen 3.3, PCL 1.11, Boost 1.74, Python 3.9,
# catkin 0.8.9, ros_comm 1.15.9). Needs root (debootstrap, chroot, mounts). docs/development.md says more.
#  1. a bullseye root made once with debootstrap, cached in the catkin workspace folder ($GPL_WS/noetic_era; outside
#     the package, whose directory rostest walks) and reused while it exists (`make clean` removes it);
#  2. Debian's ROS 1 packages for package.xml's ROS keys (debian_ros_packages.txt) and the apt packages that
#     rosdep resolves for package.xml's system keys (tools/check_rosdep.py), then requirements.txt with pip;
#     (`--prepare` stops here: .ci/run prepares the root while Debian 12 builds);
#  3. the checkout's files copied into a catkin workspace's src/, and inside.sh run there: catkin_make with g++-9
#     and tests on, every gtest, pytest and rostest, catkin_make install and a tracking run from the install space.
set -euo pipefail
source "$(dirname "${BASH_SOURCE[0]}")/../env.sh"
repo="$gpl_root"
era="$gpl_ws/noetic_era"
rootfs="$era/root"
mirror="http://deb.debian.org/debian"
here="$repo/tools/noetic_era"
started=$SECONDS

log() { printf '== noetic-era %4ss: %s\n' "$((SECONDS - started))" "$*"; }

make_root() {
  [[ -f "$rootfs/.gpl-bootstrapped" ]] && return
  log "debootstrap bullseye into $rootfs (once)"
  rm -rf "$rootfs.tmp"
  mkdir -p "$era"
  debootstrap --variant=minbase bullseye "$rootfs.tmp" "$mirror" >"$era/debootstrap.log" 2>&1 \
    || { tail -20 "$era/debootstrap.log"; exit 1; }
  # A throw-away root: dpkg need not sync every file it unpacks (Boost's headers alone are 15,000 files).
  echo force-unsafe-io >"$rootfs.tmp/etc/dpkg/dpkg.cfg.d/unsafe-io"
  touch "$rootfs.tmp/.gpl-bootstrapped"
  rm -rf "$rootfs"
  mv "$rootfs.tmp" "$rootfs"
}

mounted=()
mount_root() {
  local dir
  for dir in proc sys dev; do
    mountpoint -q "$rootfs/$dir" && continue
    case $dir in
      proc) mount -t proc proc "$rootfs/proc" ;;
      *) mount --rbind "/$dir" "$rootfs/$dir" && mount --make-rslave "$rootfs/$dir" ;;
    esac
    mounted+=("$rootfs/$dir")
  done
  cp /etc/resolv.conf "$rootfs/etc/resolv.conf"
  # debootstrap writes no /etc/hosts, and ROS nodes must resolve localhost and this machine's name.
  printf '127.0.0.1\tlocalhost\n127.0.1.1\t%s\n::1\tlocalhost ip6-localhost ip6-loopback\n' "$(hostname)" \
    >"$rootfs/etc/hosts"
  # pip inside the root reaches the package index only with the host's CA certificates.
  cp /etc/ssl/certs/ca-certificates.crt "$rootfs/etc/host-ca-certificates.crt"
}

unmount_root() {
  local dir
  for dir in "${mounted[@]}"; do umount -R -l "$dir" || true; done
}

in_root() {
  chroot "$rootfs" /usr/bin/env -i HOME=/root LANG=C.UTF-8 PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin \
    DEBIAN_FRONTEND=noninteractive "$@"
}

# The apt packages: Debian's ROS packages for package.xml's ROS keys, what rosdep resolves for its system keys, and
# the build tools a Noetic user has (build-essential, g++-9, python3-pip for requirements.txt).
apt_packages() {
  local key missing=0
  while read -r key; do
    local line
    line=$(grep -E "^$key:" "$here/debian_ros_packages.txt" || true)
    if [[ -z "$line" ]]; then
      echo "test-noetic-era: ROS key '$key' of package.xml has no Debian packages in $here/debian_ros_packages.txt" >&2
      missing=1
    fi
    printf '%s\n' ${line#*:}
  done < <(/usr/bin/python3 "$repo/tools/check_rosdep.py" --ros-keys)
  ((missing == 0)) || return 1
  /usr/bin/python3 "$repo/tools/check_rosdep.py" --apt-names debian:bullseye
  # What a Noetic user builds with (g++-9, pip for requirements.txt), strace for the install-space run's file list,
  # and the two test programs no rosdep key names (package.xml says so): nginx and pcl-tools.
  printf '%s\n' build-essential g++-9 python3-dev python3-pip ca-certificates strace nginx-light pcl-tools
}

install_packages() {
  local wanted stamp="$rootfs/.gpl-packages"
  wanted=$( (apt_packages; sha256sum "$repo/requirements.txt") | sort -u)
  [[ -f "$stamp" && "$(cat "$stamp")" == "$wanted" ]] && return
  log "apt-get install in the root: $(apt_packages | sort -u | tr '\n' ' ')"
  in_root apt-get update -qq
  # shellcheck disable=SC2046
  in_root apt-get install -y -qq --no-install-recommends $(apt_packages | sort -u) >"$era/apt.log" 2>&1 \
    || { tail -30 "$era/apt.log"; exit 1; }
  log "pip install -r requirements.txt in the root"
  cp "$repo/requirements.txt" "$rootfs/tmp/requirements.txt"
  in_root python3 -m pip install -q --cert /etc/host-ca-certificates.crt -r /tmp/requirements.txt
  printf '%s\n' "$wanted" >"$stamp"
}

# The checkout as a user clones it: the files git knows (tracked, and new ones not ignored), nothing built. Only the
# files that changed since the last run are copied (with the time of the copy), so catkin_make rebuilds exactly
# what they touch: a file's own modification time may be older than the objects built from its previous version.
copy_checkout() {
  local stage="$era/checkout"
  rm -rf "$stage"
  mkdir -p "$stage" "$rootfs/ws/src/grid_puzzle_localization"
  git -C "$repo" ls-files -z --cached --others --exclude-standard \
    | tar -C "$repo" --null --no-recursion --ignore-failed-read -T - -cf - 2>/dev/null | tar -xf - -C "$stage"
  rsync -rlp --checksum --delete "$stage/" "$rootfs/ws/src/grid_puzzle_localization/"
}

if [[ ${1:-} == --unmount ]]; then  # make clean: what a killed run left mounted
  for dir in proc sys dev; do mountpoint -q "$rootfs/$dir" && mounted+=("$rootfs/$dir"); done
  unmount_root
  exit 0
fi
[[ $(id -u) -eq 0 ]] || { echo "test-noetic-era: needs root (debootstrap, chroot, bind mounts)"; exit 2; }
make_root
trap unmount_root EXIT
mount_root
install_packages
if [[ ${1:-} == --prepare ]]; then  # .ci/run: the root and its packages only, beside the Debian 12 build
  log "root ready"
  exit 0
fi
copy_checkout
log "catkin workspace /ws in the root: build, test, install"
in_root bash /ws/src/grid_puzzle_localization/tools/noetic_era/inside.sh
log "done"
