"""ROS messages built from the controller's state: joint_states, /diagnostics, ~/status."""

from __future__ import annotations

import math
from array import array
from collections.abc import Mapping
from typing import SupportsInt

from diagnostic_msgs.msg import DiagnosticArray
from sensor_msgs.msg import JointState

from gimbal_driver_common.controller import GimbalController, LinkState
from gimbal_driver_common.device import DeviceInfo, JointSample
from gimbal_driver_common.diagnostics import FrequencyMonitor, Level, StatusPart
from gimbal_driver_common.ros.diagnostics import to_message
from gimbal_msgs.msg import AxisState, GimbalStatus


def torques(sample: JointSample, names: list[str],
            torque_constants: Mapping[str, float]) -> list[float]:
    """joint_states ``effort``: torque (N*m; N for a linear axis) = motor current (A) times
    the joint's torque constant (N*m/A, N/A), as sensor_msgs/JointState defines effort.

    Empty (sensor_msgs allows it) unless the user set ``torque_constants`` and the device
    reports current: amperes are never published as effort. NaN for a joint the sample
    has no current for.
    """
    if not torque_constants or not sample.currents:
        return []
    return [sample.currents.get(n, math.nan) * torque_constants.get(n, math.nan)
            for n in names]


class JointStateMessage:
    """joint_states in the configured joint order, stamped when the data arrived: one
    message refilled for each sample (the device thread is its one user, and ``publish``
    serialises it before it returns).

    Building a new JointState per sample (its constructor and each field's checking
    setter) cost the device thread about 45 us a sample at 50 Hz on the bench machine;
    refilled, the names are set only when they change and the values go in as
    ``array.array('d')``, which the setters take without checking each element.
    """

    def __init__(self) -> None:
        self.msg = JointState()

    def fill(self, sample: JointSample, joint_names: list[str],
             torque_constants: Mapping[str, float] | None = None) -> JointState:
        """The message for ``sample``; effort only as torque (:func:`torques`)."""
        msg = self.msg
        sec = math.floor(sample.stamp)
        msg.header.stamp.sec = int(sec)
        msg.header.stamp.nanosec = int((sample.stamp - sec) * 1e9)
        positions, velocities = sample.positions, sample.velocities
        names = [n for n in joint_names if n in positions]
        if names != msg.name:
            msg.name = names
        msg.position = array('d', [positions[n] for n in names])
        msg.velocity = array('d', [velocities.get(n, math.nan) for n in names])
        efforts = torques(sample, names, torque_constants) if torque_constants else []
        if efforts or msg.effort:
            msg.effort = array('d', efforts)
        return msg


def diagnostic_parts(
    ctl: GimbalController | None, joint_names: list[str], rate: FrequencyMonitor,
    active: bool,
) -> list[StatusPart]:
    """connection, joint_states frequency, then the device's own parts (or STALE per joint)."""
    info = ctl.device_info if ctl else DeviceInfo()
    connected = bool(ctl and ctl.connected)
    connection = StatusPart('connection', values=[
        ('connected', str(connected)),
        ('lifecycle', 'active' if active else 'inactive'),
        ('reconnects', str(ctl.reconnects if ctl else 0)),
        ('model', info.model), ('serial_number', info.serial_number),
        ('firmware', info.firmware_version),
    ])
    if connected:
        connection.message = 'connected'
    else:
        connection.level = Level.ERROR
        connection.message = f'disconnected: {ctl.link_error if ctl else "not configured"}'
    parts = [connection]
    if ctl is None or not connected:
        return parts + [StatusPart(n, Level.STALE, 'no data: device disconnected')
                        for n in joint_names]
    if active:
        rate.follow_publish_rate(ctl.config.publish_rate)  # a new rate restarts the window
        rate.expected_hz = ctl.device.expected_rate(ctl.config.publish_rate)
        level, message = rate.status()
        parts.append(StatusPart('joint_states frequency', level, message, [
            ('expected_hz', f'{rate.expected_hz:g}'), ('measured_hz', f'{rate.rate_hz:.2f}')]))
    report = ctl.device.capabilities.status
    if report is not None:
        try:
            parts.extend(report.parts())
        except Exception as exc:  # noqa: BLE001 - a status read may fail while the link drops
            parts.append(StatusPart('device', Level.WARN, f'status unavailable: {exc}'))
    return with_axis_parts(parts, ctl, joint_names)


def with_axis_parts(parts: list[StatusPart], ctl: GimbalController,
                    joint_names: list[str]) -> list[StatusPart]:
    """One status per axis (the contract), and an axis the motion watch found commanded but
    not moving reads WARN in it, one whose stop the axis does not confirm ERROR. A device
    that reports no part of its own for an axis gets one from what the controller knows
    (OK unless a watch says otherwise)."""
    by_name = {part.part: part for part in parts}
    for joint in joint_names:
        if joint not in by_name:
            by_name[joint] = StatusPart(joint, values=[('source', 'driver (the device '
                                                        'reports no axis status)')])
            parts.append(by_name[joint])
    timeout = ctl.config.motion_start_timeout
    for joint, episode in ctl.motion_watch.stalled().items():
        part = by_name.get(joint)
        if part is None:
            continue
        reason = episode.describe(joint, timeout).split(': ', 1)[1]
        part.message = reason if part.level == Level.OK else f'{part.message}; {reason}'
        part.level = max(part.level, Level.WARN)
        part.values = [('motion', 'commanded but not moving'),
                       ('commanded', 'jog' if episode.target is None
                        else f'{episode.target:.4f}'),
                       ('position', f'{episode.position:.4f}'), *part.values]
    for joint, stop in ctl.stop_watch.unconfirmed().items():
        part = by_name.get(joint)
        if part is None:
            continue
        reason = stop.describe()
        part.message = reason if part.level == Level.OK else f'{reason}; {part.message}'
        part.level = max(part.level, Level.ERROR)
        part.values = [('stop', 'not confirmed'), ('stops_sent', str(stop.sent)), *part.values]
    return parts


def diagnostic_array(
    node_name: str, stamp: object, hardware_id: str, parts: list[StatusPart]
) -> DiagnosticArray:
    array = DiagnosticArray()
    array.header.stamp = stamp
    array.status = [to_message(node_name, hardware_id, part) for part in parts]
    return array


def _state_code(value: object) -> int:
    """An ``axis_details`` state (an AxisStateCode) as AxisState's integer code."""
    if not isinstance(value, SupportsInt):
        raise TypeError(f'axis state {value!r} is not an AxisStateCode')
    return int(value)


def gimbal_status(ctl: GimbalController | None, joint_names: list[str],
                  torque_constants: Mapping[str, float] | None = None) -> GimbalStatus:
    """~/status: link, identity, mode, errors and one AxisState per joint (``current`` in
    A as the device reports it, ``effort`` the torque joint_states carries, else NaN)."""
    msg = GimbalStatus()
    connected = bool(ctl and ctl.connected)
    if connected:
        msg.connection = GimbalStatus.CONNECTION_CONNECTED
    elif ctl and (ctl.reconnects or ctl.link_state in (LinkState.LOST, LinkState.RECONNECTING)):
        msg.connection = GimbalStatus.CONNECTION_CONNECTING
    else:
        msg.connection = GimbalStatus.CONNECTION_DISCONNECTED
    if ctl is None:
        msg.axes = [AxisState(name=n, position=math.nan, velocity=math.nan, effort=math.nan,
                              target_position=math.nan, current=math.nan)
                    for n in joint_names]
        return msg
    info = ctl.device_info
    msg.link = ctl.device.description()
    msg.device_model, msg.serial_number = info.model, info.serial_number
    msg.firmware_version, msg.reconnects = info.firmware_version, ctl.reconnects
    report = ctl.device.capabilities.status
    try:
        if connected and report is not None:
            msg.mode, msg.active_errors = report.mode(), report.errors()
    except Exception as exc:  # noqa: BLE001
        msg.active_errors = [f'status unavailable: {exc}']
    sample = ctl.latest
    jogging = set(ctl.watchdog.jogging)
    for name in joint_names:
        axis = AxisState(name=name)
        axis.position = sample.positions.get(name, math.nan) if sample else math.nan
        axis.velocity = sample.velocities.get(name, math.nan) if sample else math.nan
        axis.current = sample.currents.get(name, math.nan) if sample else math.nan
        axis.effort = axis.current * (torque_constants or {}).get(name, math.nan)
        axis.target_position = ctl.commanded_targets.get(name, math.nan)
        if not connected:
            axis.state = AxisState.STATE_UNKNOWN
        elif name in jogging:
            axis.state = AxisState.STATE_JOGGING
        elif ctl.moving(name):
            axis.state = AxisState.STATE_MOVING
        else:
            axis.state = AxisState.STATE_IDLE
        try:
            for key, value in (report.axis_details(name) if report else {}).items():
                setattr(axis, key, _state_code(value) if key == 'state' else value)
        except Exception as exc:  # noqa: BLE001
            axis.active_errors = [f'status unavailable: {exc}']
        msg.axes.append(axis)
    return msg
