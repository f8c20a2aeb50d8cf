#!/usr/bin/env bash
# One-shot, idempotent set-up of everything fr5_rl needs, driven by `make setup`.
#
#   1. ROS 1: /opt/ros/noetic when present (Ubuntu 20.04), otherwise Debian's own ROS 1
#      packages, installed with apt (through sudo when not root).
#   2. A virtual environment .venv/ made from the ROS interpreter with
#      --system-site-packages, so rospy/tf2 from the system and our pinned wheels coexist.
#   3. A catkin workspace whose src/ links to this repository, built once. It lives OUTSIDE
#      the package (default ~/.cache/fr5_rl/ws-<name>-<hash of this clone's path>, or
#      $FR5_RL_WORKSPACE): rosrun searches the package directory with `find -L`, and a
#      workspace inside it would show every script several times over (devel/, build/, and the
#      src/ link back to the package, a file-system loop).
#   4. env.sh, the one file a user sources to enter the environment.
# Every step leaves a stamp keyed on its inputs and is skipped when nothing changed.
set -euo pipefail

repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$repo"
venv="$repo/.venv"
clone_id="$(basename "$repo" | tr -c 'A-Za-z0-9_.\n-' '_')-$(printf '%s' "$repo" | sha1sum | cut -c1-10)"
ws="${FR5_RL_WORKSPACE:-${XDG_CACHE_HOME:-${HOME:-/tmp}/.cache}/fr5_rl/ws-$clone_id}"
stamps="$ws/.stamps"
log() { printf '[setup] %s\n' "$*"; }
if [ "${1:-}" = "--clean" ]; then  # `make clean`: everything this script made for this clone
  rm -rf "$venv" "$ws" "$repo/.catkin_ws" "$repo/env.sh"; log "removed $venv, $ws and env.sh"; exit 0
fi

# Debian package names of everything the package runs and tests with.
debian_ros_packages=(
  ros-base python3-rospy python3-roslaunch python3-rostest python3-rosnode python3-rostopic
  python3-rosservice rosbash ros-robot-state-publisher joint-state-publisher rviz
  python3-tf2-ros python3-tf2-geometry-msgs python3-sensor-msgs python3-geometry-msgs
  python3-std-msgs python3-std-srvs python3-visualization-msgs ros-diagnostic-msgs python3-diagnostic-msgs
  python3-shape-msgs
  ros-message-generation ros-message-runtime ros-std-msgs ros-geometry-msgs ros-shape-msgs
  libstd-msgs-dev libgeometry-msgs-dev libshape-msgs-dev
  catkin librostest-dev liburdfdom-tools catkin-lint python3-venv python3-pip
  xvfb x11-apps imagemagick python3-message-filters libegl1 libegl-mesa0 python3-rosbag
)
# The same on Ubuntu 20.04 with the ROS Noetic apt repository.
noetic_packages=(
  ros-noetic-ros-base ros-noetic-rospy ros-noetic-roslaunch ros-noetic-rostest
  ros-noetic-robot-state-publisher ros-noetic-joint-state-publisher ros-noetic-rviz
  ros-noetic-tf2-ros ros-noetic-tf2-geometry-msgs ros-noetic-sensor-msgs ros-noetic-geometry-msgs
  ros-noetic-std-msgs ros-noetic-std-srvs ros-noetic-visualization-msgs ros-noetic-diagnostic-msgs
  ros-noetic-shape-msgs ros-noetic-message-generation ros-noetic-message-runtime
  liburdfdom-tools python3-catkin-lint python3-venv python3-pip xvfb x11-apps imagemagick
  ros-noetic-message-filters ros-noetic-rosbag libegl1 libegl-mesa0
)

as_root() {
  if [ "$(id -u)" -eq 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
    echo "[setup] need root to install system packages: run as root or install sudo" >&2; exit 1; fi
}

apt_install_missing() {
  local missing=()
  for pkg in "$@"; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "ok installed" || missing+=("$pkg")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    log "installing system packages: ${missing[*]}"
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  fi
}

# ---------------------------------------------------------------- 1. ROS
if [ -f /opt/ros/noetic/setup.bash ]; then
  ros_flavour=noetic
  apt_install_missing "${noetic_packages[@]}"
  set +u; source /opt/ros/noetic/setup.bash; set -u
else
  ros_flavour=debian
  if ! command -v apt-get >/dev/null; then
    echo "[setup] no /opt/ros/noetic and no apt-get: install ROS Noetic first (see docs/setup.md)" >&2; exit 1
  fi
  apt_install_missing "${debian_ros_packages[@]}"
fi
ros_python=/usr/bin/python3
log "ROS: $ros_flavour, interpreter $($ros_python --version 2>&1)"

# ---------------------------------------------------------------- 2. venv
req_hash=$(cat requirements.txt | sha1sum | cut -c1-12)
mkdir -p "$stamps"
if [ ! -x "$venv/bin/python" ]; then
  log "creating $venv from $ros_python (with system site-packages for rospy/tf2)"
  "$ros_python" -m venv --system-site-packages "$venv"
fi
# The requirements stamp lives in the venv: a new venv installs again.
if [ ! -f "$venv/.fr5_rl-pip-$req_hash" ]; then
  log "installing pinned Python requirements (requirements.txt)"
  "$venv/bin/python" -m pip install -q --disable-pip-version-check -r requirements.txt
  rm -f "$venv"/.fr5_rl-pip-*; touch "$venv/.fr5_rl-pip-$req_hash"
fi

# ---------------------------------------------------------------- 3. catkin workspace
# Earlier versions built the workspace inside the package, where rosrun finds duplicates.
[ -d "$repo/.catkin_ws" ] && { log "removing the old in-package workspace $repo/.catkin_ws"; rm -rf "$repo/.catkin_ws"; }
mkdir -p "$ws/src"
[ "$(readlink "$ws/src/fr5_rl" 2>/dev/null)" = "$repo" ] || ln -sfn "$repo" "$ws/src/fr5_rl"
build_hash=$(cat package.xml CMakeLists.txt setup.py msg/*.msg srv/*.srv | sha1sum | cut -c1-12)
if [ ! -f "$stamps/catkin-$build_hash" ] || [ ! -f "$ws/devel/setup.bash" ]; then
  log "building catkin workspace $ws"
  (
    set +u; [ "$ros_flavour" = noetic ] && source /opt/ros/noetic/setup.bash; set -u
    cd "$ws" && catkin_make -DPYTHON_EXECUTABLE="$venv/bin/python" -DCATKIN_ENABLE_TESTING=ON >"$ws/build.log" 2>&1
  ) || { echo "[setup] catkin_make failed, see $ws/build.log" >&2; tail -30 "$ws/build.log" >&2; exit 1; }
  rm -f "$stamps"/catkin-*; touch "$stamps/catkin-$build_hash"
fi

# rviz asks rospack for the Ogre media other packages export, through a package named
# media_export that Debian's ROS 1 does not ship; without it every rviz start prints
# "[rospack] Error: no such package media_export" (harmless: there is nothing to export). A
# package of that name that exports nothing ends the lookup quietly; only where none exists.
stubs="$ws/stubs"
if ! (set +u; [ "$ros_flavour" = noetic ] && source /opt/ros/noetic/setup.bash; rospack find media_export) >/dev/null 2>&1; then
  mkdir -p "$stubs/media_export"
  cat > "$stubs/media_export/package.xml" <<'XML'
<?xml version="1.0"?>
<package format="2">
  <name>media_export</name>
  <version>0.0.0</version>
  <description>Exports no Ogre media: written by fr5_rl's tools/setup.sh where ROS 1 lacks media_export.</description>
  <maintainer email="fr5_rl@example.com">fr5_rl</maintainer>
  <license>BSD</license>
  <buildtool_depend>catkin</buildtool_depend>
</package>
XML
fi

# ---------------------------------------------------------------- 4. env.sh
cat > "$repo/env.sh" <<ENV
# Generated by tools/setup.sh: source this file to use fr5_rl (roslaunch, rosrun, python).
_fr5_repo="\$(cd "\$(dirname "\${BASH_SOURCE[0]:-\$0}")" && pwd)"
export FR5_RL_WORKSPACE="$ws"   # the catkin workspace (outside the package: see tools/setup.sh)
[ -f /opt/ros/noetic/setup.bash ] && source /opt/ros/noetic/setup.bash
source "\$FR5_RL_WORKSPACE/devel/setup.bash"
[ -d "\$FR5_RL_WORKSPACE/stubs" ] && export ROS_PACKAGE_PATH="\$ROS_PACKAGE_PATH:\$FR5_RL_WORKSPACE/stubs"
source "\$_fr5_repo/.venv/bin/activate"
export PYTHONPATH="\$_fr5_repo/src\${PYTHONPATH:+:\$PYTHONPATH}"
export ROSCONSOLE_FORMAT='[\${severity}] [\${node}]: \${message}'
unset _fr5_repo
ENV
log "ready: source env.sh to enter the environment"
