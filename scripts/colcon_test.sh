#!/usr/bin/env bash
# `colcon test` as the ROS build farm runs it, for the given packages (default: gimbal_msgs
# virtual_gimbal_driver): a fresh workspace holding a copy of src/ only (so a test that reads
# a file outside its package fails here), built with colcon's defaults (BUILD_TESTING on,
# no colcon.meta), then `colcon test --packages-select PKGS` and `colcon test-result
# --verbose`, whose exit status is this script's. WORKSPACE=dir keeps the workspace there.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
PACKAGES=("$@")
[ ${#PACKAGES[@]} -gt 0 ] || PACKAGES=(gimbal_msgs virtual_gimbal_driver)
WS=${WORKSPACE:-$(mktemp -d -t colcon-test-XXXXXX)}
mkdir -p "$WS/src"
# a copy, not a link: Path(__file__).resolve() must not lead back into the repository
tar -C "$ROOT/src" --exclude=__pycache__ --exclude=.pytest_cache -cf - . | tar -C "$WS/src" -xf -
# shellcheck source=scripts/ros_env.sh
source "$ROOT/scripts/ros_env.sh" --no-workspace
cd "$WS"
echo "colcon test: building ${PACKAGES[*]} and their dependencies in $WS"
# --packages-up-to takes each selected package's direct dependencies of every kind, its
# test_depends included (colcon_core.package_decorator.add_recursive_dependencies: no
# direct categories given means all), so a driver's gimbal_driver_testing is built with it.
# gimbal_driver_common's tests use gimbal_driver_testing undeclared (the declaration would
# be a cycle, tests/test_package_dependencies.py CYCLES): it is named here for them.
colcon build --packages-up-to "${PACKAGES[@]}" gimbal_driver_testing \
  --cmake-args "-DPython3_EXECUTABLE=$ROOT/.venv/bin/python" \
  --event-handlers console_stderr- console_start_end- status- summary+ 2>&1 \
  | grep -v -e 'AMENT_PREFIX_PATH doesn.t contain' -e 'had stderr output'
set +u
# shellcheck disable=SC1091
source install/setup.bash
set -u
colcon test --packages-select "${PACKAGES[@]}" \
  --event-handlers console_stderr- console_start_end+ status- summary+
colcon test-result --verbose
