"""Property tests on the ROS side: generated invalid requests never reach the device.

Hypothesis generates invalid service requests, MoveTo goals and joint_command JointStates
(each built with at least one defect: unknown or repeated joint, NaN/inf, out-of-limit value,
mismatched array lengths, empty, unknown scan pattern, unstored preset, ...). They go to one
running node per registered driver (``registry.drivers()``; one node process per driver for
the module, reused across examples), built from
that node's own joint names and limits (read back from its parameters). Every service/goal
must answer success=false with a reason, and the simulator's receive side (the registry's
in-process ``SimHandle``: the requests its device model handled) must show no command that
moves, stops or changes the device.

A driver's own services get the requests its ``DriverSpec.refused_requests`` describes
(its ``<pkg>/refused_requests.py``: plain data that
``gimbal_driver_testing.refused_requests.strategy`` draws from).

A joint_command has no answer; the node counts it in its ``joint_command`` diagnostics part
(``rejected``, by reason; the log says each reason at most once every few seconds), so the
test waits for that count to rise and then checks the device side.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from sensor_msgs.msg import JointState

from gimbal_driver_common.registry import DriverSpec, drivers, resolve
from gimbal_driver_common.sim_handle import SimHandle, make_handle
from gimbal_driver_testing import DomainLease, ManagedProcess
from gimbal_driver_testing import wait_for as wait_until
from gimbal_driver_testing.refused_requests import strategy
from gimbal_driver_testing.ros import RosTestClient
from gimbal_msgs.action import MoveTo
from gimbal_msgs.srv import ClearPreset, GotoPreset, SetPreset, StartScan

pytestmark = pytest.mark.ros

#: every pattern any driver knows (the base node's, Capture's device scans)
KNOWN_PATTERNS = ('sector', 'zigzag', 'square', 'snake')
PROPERTY_SETTINGS = settings(max_examples=20, deadline=None, derandomize=True,
                             suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                    HealthCheck.too_slow])


@dataclass(frozen=True)
class JointSpace:
    """A running node's joints and limits (from its parameters), what the strategies need."""

    joints: tuple[str, ...]
    limits: dict[str, tuple[float, float]]
    velocity_max: dict[str, float]
    scan_pan: str

    def inside(self, joint: str) -> st.SearchStrategy[float]:
        low, high = self.limits[joint]
        return st.floats(low, high)


class Rig:
    def __init__(self, driver: DriverSpec, ros: RosTestClient, node: ManagedProcess,
                 device: SimHandle, space: JointSpace) -> None:
        self.driver, self.ros, self.node, self.device, self.space = (driver, ros, node,
                                                                     device, space)

    def preset_call_valid(self, service: str, index: int) -> bool:
        """A preset call the device accepts with nothing stored (``valid_preset_calls``)."""
        return any(name == service and slot in (None, index)
                   for name, slot in self.device.valid_preset_calls)

    def service(self, name: str) -> str:
        return f'/{self.driver.node_name}/{name}'

    def rejections(self) -> int:
        """joint_commands rejected so far (the node's ``joint_command`` diagnostics part)."""
        status = self.ros.wait_for_diagnostic(self.driver.node_name, 'joint_command',
                                              timeout=30)
        return int({kv.key: kv.value for kv in status.values}['rejected'])


def joint_space(ros: RosTestClient, node_name: str) -> JointSpace:
    def parameter(name: str) -> list:
        return list(ros.get_parameter(node_name, name, timeout=30))

    joints = tuple(parameter('joint_names'))
    low, high, speed = (parameter(n) for n in ('position_min', 'position_max', 'velocity_max'))
    scan_pan = 'pan' if {'pan', 'tilt'} <= set(joints) else joints[0]  # base node's rule
    return JointSpace(joints, {j: (low[i], high[i]) for i, j in enumerate(joints)},
                      {j: speed[i] for i, j in enumerate(joints)}, scan_pan)


def quiet(ros: RosTestClient, device: SimHandle, samples: int = 20) -> bool:
    """True when ``samples`` more joint_states came and the device saw no change meanwhile
    (the node has finished configuring the device at start-up)."""
    mark = device.mark()
    ros.wait_for_message('/joint_states', JointState, timeout=30)
    states = ros.subscribe('/joint_states', JointState)
    count = len(states)
    wait_until(lambda: len(states) >= count + samples, 30, f'{samples} joint_states')
    return device.changes_since(mark) == []


def receive_side_sees_a_valid_move(ros: RosTestClient, device: SimHandle) -> None:
    """The check can fail: a valid joint_command shows on the device's receive side as a
    change. Then the axes settle and the node is quiet again."""
    goal = device.takeover_goal
    mark = device.mark()
    ros.publish('/joint_command', JointState(name=list(goal), position=list(goal.values())))
    wait_until(lambda: device.changes_since(mark), 30, 'the valid move on the device')
    wait_until(lambda: not any(device.moving(j) for j in goal), 60, 'the axes to stop')
    wait_until(lambda: quiet(ros, device), 60, 'the node to be quiet after the move')


@pytest.fixture(scope='module', params=[spec for spec in drivers() if spec.sim_handle],
                ids=lambda spec: spec.name)
def rig(request, tmp_path_factory):
    driver: DriverSpec = request.param
    workdir = tmp_path_factory.mktemp(driver.name)
    device = make_handle(driver, workdir, process_tests=True)
    device.start()
    lease = DomainLease()
    domain = lease.acquire()
    params = [*device.link_parameters(),
              f'presets_file:={workdir / "presets.yaml"}', 'publish_rate:=10.0',
              'diagnostics_period:=0.2']
    node = ManagedProcess.ros(driver.package, driver.node_executable, domain,
                              ['--ros-args', *[x for p in params for x in ('-p', p)]])
    ros = RosTestClient(domain, 'property_client')
    try:
        ros.wait_for_message('/joint_states', JointState, timeout=60)
        assert device.receptions > 0  # the hook sees the node's polls
        space = joint_space(ros, driver.node_name)
        wait_until(lambda: quiet(ros, device), 60, 'the node to finish its start-up commands')
        receive_side_sees_a_valid_move(ros, device)
        yield Rig(driver, ros, node, device, space)
    finally:
        ros.close()
        node.stop()
        device.stop()
        lease.release()
    assert 'Traceback' not in node.output(), node.output()[-3000:]


# ------------------------------------------------------------------------- strategies
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])


def unknown_name(space: JointSpace) -> st.SearchStrategy[str]:
    return st.text(min_size=0, max_size=12).filter(lambda s: s not in space.joints)


@st.composite
def out_of_limit(draw, space: JointSpace, joint: str) -> float:
    low, high = space.limits[joint]
    return draw(st.one_of(st.floats(min_value=high + 1e-3, max_value=1e300),
                          st.floats(min_value=-1e300, max_value=low - 1e-3)))


@st.composite
def invalid_joint_command(draw, space: JointSpace) -> JointState:
    """A JointState with at least one defect the node must reject as a whole."""
    names = draw(st.lists(st.sampled_from(space.joints), min_size=1,
                          max_size=len(space.joints), unique=True))
    positions = [draw(space.inside(n)) for n in names]
    velocities: list[float] = []
    # (NaN alone is no defect: it means "no command for this joint", docs/interface.md)
    defect = draw(st.sampled_from(('unknown', 'repeated', 'non_finite_position',
                                   'out_of_limit', 'position_length', 'velocity_length',
                                   'jog_too_fast', 'empty')))
    if defect == 'unknown':
        names.insert(draw(st.integers(0, len(names))), draw(unknown_name(space)))
        positions.insert(0, draw(finite))
    elif defect == 'repeated':
        names.append(names[0])
        positions.append(positions[0])
    elif defect == 'non_finite_position':
        positions[draw(st.integers(0, len(names) - 1))] = draw(st.sampled_from(
            [math.inf, -math.inf]))
    elif defect == 'out_of_limit':
        index = draw(st.integers(0, len(names) - 1))
        positions[index] = draw(out_of_limit(space, names[index]))
    elif defect == 'position_length':
        extra = draw(st.lists(finite, min_size=1, max_size=3))
        positions = positions + extra if draw(st.booleans()) or len(names) == 1 \
            else positions[:-1]
    elif defect == 'velocity_length':
        velocities = [0.01] * draw(st.sampled_from([n for n in range(1, 5) if n != len(names)]))
    elif defect == 'jog_too_fast':
        positions = [math.nan] * len(names)
        velocities = [draw(st.one_of(st.sampled_from([math.inf, -math.inf]),
                                     st.floats(space.velocity_max[n] + 1e-3, 1e300)))
                      for n in names]
    else:
        names, positions = [], draw(st.lists(finite, max_size=2))
    return JointState(name=names, position=positions, velocity=velocities)


@st.composite
def invalid_move_goal(draw, space: JointSpace) -> MoveTo.Goal:
    names = list(space.joints)
    positions = [draw(space.inside(n)) for n in names]
    defect = draw(st.sampled_from(('unknown', 'non_finite', 'out_of_limit', 'length',
                                   'empty')))
    index = draw(st.integers(0, len(names) - 1))
    if defect == 'unknown':
        names[index] = draw(unknown_name(space))
    elif defect == 'non_finite':
        positions[index] = draw(non_finite)
    elif defect == 'out_of_limit':
        positions[index] = draw(out_of_limit(space, names[index]))
    elif defect == 'length':
        positions = positions[:-1] if draw(st.booleans()) else [*positions, 0.0]
    else:
        names, positions = [], []
    return MoveTo.Goal(joint_names=names, positions=positions)


@st.composite
def invalid_scan(draw, space: JointSpace) -> StartScan.Request:
    """A scan with one defect; the rest is a small sector around the middle of the pan
    range."""
    low, high = space.limits[space.scan_pan]
    middle = (low + high) / 2
    request = StartScan.Request(pattern='sector', pan_min=middle - 0.2, pan_max=middle + 0.2,
                                tilt_min=0.0, tilt_max=0.1, speed=0.1, tilt_step=0.1,
                                dwell=0.0)
    defect = draw(st.sampled_from(('pattern', 'non_finite', 'speed', 'out_of_limit')))
    if defect == 'pattern':
        request.pattern = draw(st.text(max_size=10).filter(
            lambda s: s not in KNOWN_PATTERNS))
    elif defect == 'non_finite':
        setattr(request, draw(st.sampled_from(('pan_min', 'pan_max', 'speed'))),
                draw(non_finite))
    elif defect == 'speed':
        request.speed = draw(st.floats(max_value=0.0, allow_nan=False))
    else:
        request.pan_max = draw(out_of_limit(space, space.scan_pan))
    return request


@st.composite
def invalid_preset_request(draw, space: JointSpace):
    """(service type, name, request) of a preset request that must be refused; no preset is
    ever stored, so every goto/clear of an index is invalid too."""
    kind = draw(st.sampled_from(('set', 'goto', 'clear')))
    index = draw(st.integers(0, 65535))
    if kind == 'goto':
        return GotoPreset, 'goto_preset', GotoPreset.Request(index=index, speed=draw(finite))
    if kind == 'clear':
        return ClearPreset, 'clear_preset', ClearPreset.Request(index=index, all=False)
    names = list(space.joints)
    positions = [(low + high) / 2 for low, high in (space.limits[n] for n in names)]
    defect = draw(st.sampled_from(('unknown', 'non_finite', 'length', 'empty')))
    which = draw(st.integers(0, len(names) - 1))
    if defect == 'unknown':
        names[which] = draw(unknown_name(space))
    elif defect == 'non_finite':
        positions[which] = draw(non_finite)
    elif defect == 'length':
        positions = positions[:-1]
    else:
        names, positions = [], []
    return SetPreset, 'set_preset', SetPreset.Request(
        index=index, name=draw(st.text(max_size=8)), use_current_position=False,
        joint_names=names, positions=positions)


# ------------------------------------------------------------------------- properties
@PROPERTY_SETTINGS
@given(data=st.data())
def test_invalid_joint_commands_are_rejected_and_send_nothing(rig, data) -> None:
    msg = data.draw(invalid_joint_command(rig.space), label='joint_command')
    mark, rejected = rig.device.mark(), rig.rejections()
    rig.ros.publish('/joint_command', msg)
    wait_until(lambda: rig.rejections() > rejected, 20, f'the rejection of {msg}')
    assert rig.device.changes_since(mark) == []


@PROPERTY_SETTINGS
@given(data=st.data())
def test_invalid_move_goals_fail_with_a_reason_and_send_nothing(rig, data) -> None:
    goal = data.draw(invalid_move_goal(rig.space), label='goal')
    mark = rig.device.mark()
    try:
        result, _, _ = rig.ros.run_action(MoveTo, rig.service('move_to'), goal, timeout=20)
    except AssertionError:
        result = None  # rejected at goal time: an answer as well
    if result is not None:
        assert not result.success
        assert result.message
    assert rig.device.changes_since(mark) == []


@PROPERTY_SETTINGS
@given(data=st.data())
def test_invalid_scans_are_refused_with_a_reason_and_send_nothing(rig, data) -> None:
    request = data.draw(invalid_scan(rig.space), label='request')
    mark = rig.device.mark()
    reply = rig.ros.call(StartScan, rig.service('start_scan'), request, timeout=20)
    assert not reply.success, request
    assert reply.message
    assert rig.device.changes_since(mark) == []


@PROPERTY_SETTINGS
@given(data=st.data())
def test_invalid_preset_requests_are_refused_with_a_reason_and_send_nothing(rig, data) -> None:
    srv_type, name, request = data.draw(invalid_preset_request(rig.space), label='call')
    # presets a device keeps itself (SimHandle.valid_preset_calls) are valid with nothing stored
    assume(not rig.preset_call_valid(name, request.index))
    mark = rig.device.mark()
    reply = rig.ros.call(srv_type, rig.service(name), request, timeout=20)
    assert not reply.success, request
    assert reply.message
    assert rig.device.changes_since(mark) == []


#: the transitions the active state has (lifecycle_msgs/Transition ids and labels)
ACTIVE_TRANSITIONS = {Transition.TRANSITION_DEACTIVATE, Transition.TRANSITION_ACTIVE_SHUTDOWN}
ACTIVE_LABELS = {'deactivate', 'shutdown'}


@PROPERTY_SETTINGS
@given(transition_id=st.integers(0, 255).filter(lambda i: i not in ACTIVE_TRANSITIONS),
       label=st.one_of(st.just(''), st.text(max_size=12).filter(
           lambda s: s not in ACTIVE_LABELS)))
def test_impossible_lifecycle_transitions_are_refused_and_the_node_lives_on(
        rig, transition_id, label) -> None:
    """rclpy's own ~/change_state raised out of the executor here and ended the node
    (ros2/rclpy#1209, fixed upstream in #1319 after the pinned Jazzy wheel); the base node
    answers success=false instead."""
    mark = rig.device.mark()
    request = ChangeState.Request(transition=Transition(id=transition_id, label=label))
    reply = rig.ros.call(ChangeState, rig.service('change_state'), request, timeout=20)
    assert not reply.success
    assert rig.node.running
    assert rig.ros.lifecycle_state(rig.driver.node_name) == 'active'
    assert rig.device.changes_since(mark) == []


@PROPERTY_SETTINGS
@given(data=st.data())
def test_refused_driver_requests_answer_with_a_reason_and_send_nothing(rig, data) -> None:
    """Each driver's own services: unknown commands and modes, out-of-scope (weapon) names,
    and commands that can cut off or brick the device without their opt-in parameter."""
    if not rig.driver.refused_requests:
        pytest.skip(f'{rig.driver.name} has no services of its own')
    refused = strategy(resolve(rig.driver.refused_requests)())
    srv_type, name, request = data.draw(refused, label='call')
    mark = rig.device.mark()
    reply = rig.ros.call(srv_type, rig.service(name), request, timeout=20)
    assert not reply.success, request
    assert reply.message
    assert rig.device.changes_since(mark) == []
