"""A stand-in for ros2_control's ``joint_state_topic_hardware_interface``, and the joint
trajectory controller's interpolation, to drive a node as a ros2_control stack does.

It replays exactly what the plugin does (ros-controls/topic_based_hardware_interfaces,
``joint_state_topic_hardware_interface/src/joint_state_topic_hardware_interface.cpp``,
``JointStateTopicSystem``, release 1.1.0):

* ``on_init``: the command publisher on ``joint_commands_topic`` with ``rclcpp::QoS(1)``
  (reliable, volatile, keep-last 1), the state subscription on ``joint_states_topic`` with
  ``rclcpp::SensorDataQoS()`` (best effort, keep-last 5); ``trigger_joint_command_threshold``
  defaults to 1e-5 (the header's member initialiser).
* ``read()``: the latest JointState's finite position/velocity/effort go to the state
  interfaces of the joints with the same name.
* ``write()``: ``diff`` is the sum over every joint and each of its position/velocity/effort
  command interfaces of ``|state - command|``; when ``diff <= threshold`` nothing is
  published this cycle. Otherwise one JointState with every joint's name and, joint by
  joint, its position, velocity and effort commands appended to the arrays of the same name.
  Command interfaces start NaN (ros2_control's ``hardware_interface/handle.hpp``: a
  command interface without ``initial_value`` holds ``quiet_NaN``) until a controller
  writes them; ``|state - NaN|`` is NaN and ``NaN <= threshold`` is false, so NaN commands
  are published every cycle. A threshold of -1 publishes every cycle.

The controller manager calls ``read()``, the controllers, then ``write()`` once per cycle
(``update_rate``, 100 Hz in the examples). :func:`rest_to_rest` is what the
joint_trajectory_controller commands between two points given with positions, velocities
and accelerations (ros2_controllers ``joint_trajectory_controller/src/trajectory.cpp``,
``interpolate_between_points``: a quintic spline when both points have velocities and
accelerations, as MoveIt sends them; zero at both ends here).

The ``<ros2_control>`` block is read from the package's example
(``config/<package>.ros2_control.xacro``) by :meth:`TopicSystemConfig.from_xml`.
"""

from __future__ import annotations

import math
import threading
import time
import xml.etree.ElementTree as ET
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from itertools import pairwise

from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_profile_sensor_data
from sensor_msgs.msg import JointState

PLUGIN = 'joint_state_topic_hardware_interface/JointStateTopicSystem'
#: the plugin's own defaults (on_init)
DEFAULT_COMMANDS_TOPIC = '/robot_joint_commands'
DEFAULT_STATES_TOPIC = '/robot_joint_states'
DEFAULT_THRESHOLD = 1e-5
#: the command interfaces write() publishes (others are skipped with a warning)
INTERFACES = ('position', 'velocity', 'effort')
#: the controller manager's update rate in the examples (config/<package>_controllers.yaml)
UPDATE_RATE_HZ = 100.0


@dataclass(frozen=True)
class TopicJoint:
    """One ``<joint>`` of the block: its interfaces, and each command interface's limits."""

    name: str
    command_interfaces: tuple[str, ...]
    state_interfaces: tuple[str, ...]
    #: command interface -> (min, max) from its ``<param name="min|max">`` (None: not given)
    limits: Mapping[str, tuple[float | None, float | None]]


@dataclass(frozen=True)
class TopicSystemConfig:
    """The ``<ros2_control>`` block as the plugin reads it."""

    name: str
    plugin: str
    joint_commands_topic: str
    joint_states_topic: str
    threshold: float
    joints: tuple[TopicJoint, ...]

    @classmethod
    def from_xml(cls, text: str) -> TopicSystemConfig:
        """The first ``<ros2_control>`` element of a URDF/xacro text."""
        root = ET.fromstring(text)
        block = root if root.tag == 'ros2_control' else root.find('.//ros2_control')
        if block is None:
            raise ValueError('no <ros2_control> element')
        hardware = block.find('hardware')
        params = {p.get('name'): (p.text or '').strip() for p in hardware.findall('param')}
        joints = []
        for joint in block.findall('joint'):
            limits = {}
            for interface in joint.findall('command_interface'):
                bounds = {p.get('name'): float(p.text) for p in interface.findall('param')
                          if p.get('name') in ('min', 'max')}
                limits[interface.get('name')] = (bounds.get('min'), bounds.get('max'))
            joints.append(TopicJoint(
                joint.get('name'),
                tuple(i.get('name') for i in joint.findall('command_interface')),
                tuple(i.get('name') for i in joint.findall('state_interface')), limits))
        return cls(block.get('name'), (hardware.findtext('plugin') or '').strip(),
                   params.get('joint_commands_topic', DEFAULT_COMMANDS_TOPIC),
                   params.get('joint_states_topic', DEFAULT_STATES_TOPIC),
                   float(params.get('trigger_joint_command_threshold', DEFAULT_THRESHOLD)),
                   tuple(joints))

    @property
    def joint_names(self) -> list[str]:
        return [joint.name for joint in self.joints]

    def with_command_interfaces(self, interfaces: tuple[str, ...],
                                threshold: float) -> TopicSystemConfig:
        """The same block with other command interfaces on every joint (velocity mode)."""
        return replace(self, threshold=threshold, joints=tuple(
            replace(joint, command_interfaces=interfaces) for joint in self.joints))


class TopicSystem:
    """The plugin's state and command interfaces with its ``read()`` and ``write()``."""

    def __init__(self, config: TopicSystemConfig) -> None:
        self.config = config
        # interfaces without an initial_value start NaN (handle.hpp)
        self.states = {(j.name, i): math.nan for j in config.joints for i in j.state_interfaces}
        self.commands = {(j.name, i): math.nan for j in config.joints
                         for i in j.command_interfaces}

    def read(self, msg: JointState) -> None:
        """Finite values of the joints of this block go to their state interfaces."""
        known = set(self.config.joint_names)
        for field in INTERFACES:
            values = getattr(msg, field)
            if not values:
                continue
            for name, value in zip(msg.name, values, strict=False):
                if name in known and math.isfinite(value) and (name, field) in self.states:
                    self.states[(name, field)] = value

    def write(self) -> JointState | None:
        """The JointState this cycle publishes, or None when the threshold skips it."""
        diff = 0.0
        for joint in self.config.joints:
            for interface in joint.command_interfaces:
                if interface in INTERFACES:
                    diff += abs(self.states.get((joint.name, interface), math.nan)
                                - self.commands[(joint.name, interface)])
        if diff <= self.config.threshold:
            return None
        msg = JointState()
        for joint in self.config.joints:
            msg.name.append(joint.name)
            for interface in joint.command_interfaces:
                if interface in INTERFACES:
                    getattr(msg, interface).append(self.commands[(joint.name, interface)])
        return msg


def rest_to_rest(start: float, goal: float, duration: float, t: float) -> float:
    """The joint_trajectory_controller's quintic from ``start`` to ``goal`` in ``duration``
    s, velocity and acceleration zero at both ends; ``goal`` after it."""
    s = min(max(t / duration, 0.0), 1.0)
    return start + (goal - start) * s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s)


def rest_to_rest_peak_speed(start: float, goal: float, duration: float) -> float:
    """The highest speed of :func:`rest_to_rest` (at half time): 15/8 of the mean."""
    return 1.875 * abs(goal - start) / duration


class TopicSystemStandIn:
    """The plugin's topics on a test node, cycled by the caller at the update rate.

    Each :meth:`cycle` does what one controller-manager cycle does for this hardware: read()
    the latest state, let the controllers set the commands (``commands``: joint -> value
    for each joint's command interface; a joint left out keeps its command, NaN at start),
    write(). ``published`` keeps every message sent, ``cycles`` how many ran and ``late``
    how late each of :meth:`run` ran (a machine busy with other work). :meth:`longest_gap`
    tells whether either side stalled: the stand-in between two publishes, or the node
    between two joint_states it stamped.
    """

    def __init__(self, node: Node, config: TopicSystemConfig) -> None:
        self.system = TopicSystem(config)
        self._lock = threading.Lock()
        self._latest: JointState | None = None
        self.states_received = 0
        self.published: list[JointState] = []
        self.cycles = 0
        self.late: list[float] = []  # s each cycle of run() ran behind its schedule
        self.published_at: list[float] = []  # monotonic s of each publish
        self.state_stamps: list[float] = []  # header stamps (s) of the joint_states read
        # rclcpp::QoS(1): reliable, volatile, keep-last 1
        self._publisher = node.create_publisher(JointState, config.joint_commands_topic,
                                                QoSProfile(depth=1))
        self._subscription = node.create_subscription(
            JointState, config.joint_states_topic, self._on_state, qos_profile_sensor_data)

    def _on_state(self, msg: JointState) -> None:
        with self._lock:
            self._latest = msg
            self.states_received += 1
            self.state_stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)

    @property
    def config(self) -> TopicSystemConfig:
        return self.system.config

    def reconfigure(self, config: TopicSystemConfig) -> None:
        """Other command interfaces or threshold (the commands start NaN again, the states
        stay)."""
        states = self.system.states
        self.system = TopicSystem(config)
        self.system.states.update({k: v for k, v in states.items() if k in self.system.states})

    def subscribed(self) -> bool:
        """Whether the node's joint_command subscription has matched the publisher."""
        return self._publisher.get_subscription_count() > 0

    def state(self, joint: str, interface: str = 'position') -> float:
        """The value read() last put into a state interface."""
        return self.system.states[(joint, interface)]

    def cycle(self, commands: Mapping[str, float] | None = None,
              interface: str | None = None) -> JointState | None:
        """read(), the controllers' commands (on ``interface``, default each joint's first
        command interface), write(); returns what was published."""
        with self._lock:
            latest = self._latest
        if latest is not None:
            self.system.read(latest)
        for joint, value in (commands or {}).items():
            spec = next(j for j in self.config.joints if j.name == joint)
            self.system.commands[(joint, interface or spec.command_interfaces[0])] = value
        msg = self.system.write()
        self.cycles += 1
        if msg is not None:
            self._publisher.publish(msg)
            self.published.append(msg)
            self.published_at.append(time.monotonic())
        return msg

    def mark(self) -> tuple[int, int]:
        """Where the records stand now: the start of a window for :meth:`longest_gap`."""
        with self._lock:
            return len(self.published_at), len(self.state_stamps)

    def longest_gap(self, since: tuple[int, int]) -> float:
        """The longest pause (s) since ``since`` between two of this stand-in's publishes
        or two joint_states stamps of the node: a process starved of CPU for that long."""
        with self._lock:
            stamps = sorted(self.state_stamps[since[1]:])
        gaps = [b - a for series in (self.published_at[since[0]:], stamps)
                for a, b in pairwise(series)]
        return max(gaps, default=0.0)

    def run(self, seconds: float, commands: Callable[[float], Mapping[str, float]],
            interface: str | None = None, rate_hz: float = UPDATE_RATE_HZ) -> None:
        """Cycle at ``rate_hz`` for ``seconds`` (a steady timer, as the controller manager's);
        ``commands(t)`` gives the controllers' commands ``t`` s into the run, ``t`` the time
        the cycle really runs (the trajectory controller samples its trajectory at the
        cycle's time). How late each cycle ran behind its schedule goes to ``late``."""
        period = 1.0 / rate_hz
        start = time.monotonic()
        for k in range(round(seconds * rate_hz)):
            delay = start + k * period - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            t = time.monotonic() - start
            self.late.append(t - k * period)
            self.cycle(commands(t), interface)
