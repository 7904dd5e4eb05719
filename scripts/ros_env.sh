# Source me: the venv, the ROS wheels and (unless --no-workspace) the built workspace,
# with DDS kept on loopback. ROS_DOMAIN_ID defaults to one derived from this shell's PID
# so concurrent runs on one machine do not see each other; tests pick their own per test.
_ros_env_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
# shellcheck disable=SC1091
source "$_ros_env_root/.venv/bin/activate"
export CMAKE_PREFIX_PATH="$VIRTUAL_ENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$(( $$ % 90 + 110 ))}
export RCUTILS_COLORIZED_OUTPUT=0
if [ "${1:-}" != "--no-workspace" ] && [ -f "$_ros_env_root/install/setup.bash" ]; then
  # colcon's setup scripts read unset variables: relax `set -u` while sourcing them.
  case $- in *u*) _ros_env_nounset=1; set +u ;; *) _ros_env_nounset=0 ;; esac
  # shellcheck disable=SC1091
  source "$_ros_env_root/install/setup.bash"
  [ "$_ros_env_nounset" = 1 ] && set -u
  unset _ros_env_nounset
fi
unset _ros_env_root
