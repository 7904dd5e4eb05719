"""ros2_control's topic interface, in a process of its own, streaming a trajectory.

The joint_state_topic_hardware_interface stand-in (``gimbal_driver_testing.
topic_system``: write() with its threshold rule, read() on SensorDataQoS) cycles at 100 Hz
with the package's ``<ros2_control>`` example, as a controller manager with a
joint_trajectory_controller would: NaN commands until it starts, then it holds the joints
where they are, then runs each
trajectory (the JTC's rest-to-rest quintic of ``joint`` by ``amplitude``, alternating
direction, the other joints held), then holds the goal for ``settle_s``. Every joint_states
message the interface reads is kept with its stamp. Writes JSON to ``output``: the runs
(wall-clock start, start and goal positions), the states (stamp, position of ``joint``),
what each trajectory cycle saw (wall time, the latest state's stamp and position: a
controller's view), how late each cycle ran behind its schedule (this process waiting for a
core) and how many cycles were published.

Usage: trajectory_publisher.py SETTINGS_JSON OUTPUT
  SETTINGS_JSON: {"block": path, "joint": name, "amplitude": rad, "duration": s,
                  "settle_s": s, "runs": n}
"""

from __future__ import annotations

import json
import sys
import threading
import time
from pathlib import Path

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import JointState

from gimbal_driver_testing.topic_system import (
    TopicSystemConfig,
    TopicSystemStandIn,
    rest_to_rest,
)

#: before the controllers start, the interface publishes NaN commands
NAN_S = 0.2
#: the JTC holds the joints where they are when it starts
HOLD_S = 0.5


def wait(condition, timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f'trajectory_publisher: no {what} after {timeout:g} s')
        time.sleep(0.02)


def main() -> int:
    settings, output = json.loads(Path(sys.argv[1]).read_text()), Path(sys.argv[2])
    config = TopicSystemConfig.from_xml(Path(settings['block']).read_text())
    joint, amplitude = settings['joint'], settings['amplitude']
    duration, settle = settings['duration'], settings['settle_s']
    rclpy.init()
    node = rclpy.create_node('bench_trajectory_publisher')
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    threading.Thread(target=executor.spin, daemon=True, name='trajectory-spin').start()
    stand_in = TopicSystemStandIn(node, config)
    states: list[tuple[float, float]] = []

    def record(msg: JointState) -> None:
        if joint in msg.name:
            stamp = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
            states.append((stamp, msg.position[list(msg.name).index(joint)]))

    node.create_subscription(JointState, config.joint_states_topic, record,
                             qos_profile_sensor_data)
    wait(stand_in.subscribed, 30.0, f'subscriber on {config.joint_commands_topic}')
    wait(lambda: stand_in.states_received > 5, 30.0, f'states on {config.joint_states_topic}')
    time.sleep(1.0)  # the node sees the publisher after the publisher sees it (discovery)
    stand_in.run(NAN_S, lambda t: {})  # the controllers not started yet: NaN commands
    hold = {name: stand_in.state(name) for name in config.joint_names}  # what read() took
    stand_in.run(HOLD_S, lambda t: hold)
    runs = []
    cycles: list[tuple[float, float, float]] = []  # (wall time, state stamp, state position)
    late_from = len(stand_in.late)
    for index in range(settings['runs']):
        start = stand_in.state(joint)
        goal = start + (amplitude if index % 2 == 0 else -amplitude)
        began: list[float] = []

        def commands(t: float, start: float = start, goal: float = goal,
                     began: list[float] = began) -> dict[str, float]:
            now = time.time()
            if not began:
                began.append(now - t)
            # what a controller sees this cycle: the latest state read() took, and its stamp
            if states:
                cycles.append((now, *states[-1]))
            return {**hold, joint: rest_to_rest(start, goal, duration, t)}

        stand_in.run(duration + settle, commands)
        runs.append({'t0': began[0], 'start': start, 'goal': goal, 'duration': duration})
    late = stand_in.late[late_from:]  # how late the trajectory cycles ran
    # written whole, then renamed: the bench reads it as soon as the name exists
    partial = output.with_name(output.name + '.partial')
    partial.write_text(json.dumps({'runs': runs, 'states': states, 'seen': cycles, 'late': late,
                                  'cycles': stand_in.cycles,
                                  'published': len(stand_in.published)}))
    partial.replace(output)
    executor.shutdown(timeout_sec=1.0)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
