#!/usr/bin/env bash
# Build the whole environment from nothing (or reuse what is there):
#   1. .venv with CPython 3.11 (the ROS 2 Jazzy wheels are cp311),
#   2. pinned wheels from requirements.txt + constraints.txt (only when they changed),
#   3. the wheels' CMake export paths re-pointed to this interpreter (idempotent),
#   4. colcon build of src/ into build/ and install/ (skipped when src/ is unchanged).
# Usage: scripts/setup_env.sh [--no-build]
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=$ROOT/.venv

find_python() {
  for candidate in "${PYTHON:-}" python3.11 python3; do
    [ -n "$candidate" ] || continue
    if command -v "$candidate" >/dev/null 2>&1 &&
       "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
      command -v "$candidate"; return 0
    fi
  done
  echo "setup: CPython 3.11 is required (ROS 2 Jazzy wheels are cp311); set PYTHON=" >&2
  return 1
}

if [ ! -x "$VENV/bin/python" ]; then
  PY=$(find_python)
  echo "setup: creating $VENV with $PY"
  "$PY" -m venv "$VENV"
fi

stamp=$VENV/.requirements.sha256
want=$(cat requirements.txt constraints.txt | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  echo "setup: installing pinned wheels (requirements.txt)"
  "$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
    -r requirements.txt -c constraints.txt
  echo "$want" > "$stamp"
else
  echo "setup: wheels up to date"
fi

"$VENV/bin/python" scripts/patch_ros_wheels.py "$VENV"

[ "${1:-}" = "--no-build" ] && exit 0

# The build is skipped when nothing it reads changed since the last one this script made:
# the same tracked and untracked (not ignored) files under src/ with the same contents, the
# same colcon.meta and wheels, and colcon's latest build log still the one it wrote (a build
# run by hand since, e.g. --symlink-install, is built over). Outside a git work tree it
# always builds. colcon itself re-runs every package's setup.py however little changed
# (11 s of a make test).
build_state() {
  git rev-parse --is-inside-work-tree > /dev/null 2>&1 || return 1
  { git ls-files -s -- src colcon.meta; git diff --no-ext-diff --binary -- src colcon.meta
    git ls-files -z --others --exclude-standard -- src | xargs -0 -r sha256sum
    cat "$stamp"; readlink log/latest_build; } | sha256sum | cut -d' ' -f1
}
build_stamp=install/.setup_env_build
if [ -f install/setup.bash ] && [ -f "$build_stamp" ] && state=$(build_state) &&
   [ "$(cat "$build_stamp")" = "$state" ]; then
  echo "setup: install/ up to date (src/ unchanged since the last build)"
  exit 0
fi
rm -f "$build_stamp"

# shellcheck source=scripts/ros_env.sh
source scripts/ros_env.sh --no-workspace
echo "setup: colcon build"
colcon build --base-paths src \
  --cmake-args "-DPython3_EXECUTABLE=$VENV/bin/python" -DBUILD_TESTING=OFF \
  --event-handlers console_stderr- console_start_end- summary+ status- 2>&1 \
  | grep -v -e 'AMENT_PREFIX_PATH doesn.t contain' -e 'had stderr output' || {
  echo "setup: colcon build failed (see log/latest_build)" >&2; exit 1; }
[ -f install/setup.bash ] || { echo "setup: colcon build produced no install/" >&2; exit 1; }
# Byte-compile what colcon installed, as pip does for every wheel: setuptools skips it when
# PYTHONDONTWRITEBYTECODE is set (as in this machine's shells), and every node, simulator
# and test process would then compile the packages' sources again at each start (0.1-0.15 s
# of CPU a start; docs/testing.md "Where the time goes"). Idempotent: up-to-date files are
# left alone.
echo "setup: byte-compiling install/"
python -m compileall -q -j 0 install > /dev/null || {
  echo "setup: byte-compiling install/ failed" >&2; exit 1; }
if state=$(build_state); then echo "$state" > "$build_stamp"; fi

