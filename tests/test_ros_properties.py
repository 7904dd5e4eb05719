"""Property tests on the ROS side: generated invalid requests never reach the device.

Hypothesis generates invalid service requests, MoveTo goals and joint_command JointStates
(each built with at least one defect: unknown or repeated joint, NaN/inf, out-of-limit value,
mismatched array lengths, empty, unknown scan pattern, unstored preset, ...). They go to one
running reference node (virtual gimbal, the shared base node's behaviour; one node process
for the module, reused across examples). Every service/goal must answer success=false with a
reason, and the simulator's receive side (its server's receive hook and the request lines of
the device model) must show no command that moves, stops or changes the device.

A joint_command has no answer; the node logs ``joint_command rejected, nothing sent: <why>``,
so the test waits for that line (one per message) and then checks the device side.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from sensor_msgs.msg import JointState

from gimbal_driver_common.ros.testing import RosTestClient
from gimbal_driver_common.testing import DomainLease, ManagedProcess, wait_for
from gimbal_driver_common.virtual_gimbal import make_server
from gimbal_msgs.action import MoveTo
from gimbal_msgs.srv import ClearPreset, GotoPreset, SetPreset, StartScan

pytestmark = pytest.mark.ros

PKG = 'gimbal_driver_common'
JOINTS = ('pan', 'tilt')
LIMITS = {'pan': (-math.pi, math.pi), 'tilt': (-math.pi / 2, math.pi / 2)}
VELOCITY_MAX = 1.5  # virtual_gimbal_node's default velocity_max
#: the device verbs that move, stop or change the device (ID and GET only read)
DEVICE_CHANGING = ('MOVE', 'JOG', 'STOP', 'HOME', 'RESET', 'FAULT')
REJECTED = 'joint_command rejected, nothing sent'
PROPERTY_SETTINGS = settings(max_examples=25, deadline=None, derandomize=True,
                             suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                    HealthCheck.too_slow])


class DeviceSide:
    """What reached the simulated device: every request (a line of the virtual gimbal, a
    command name of the Capture controller), plus a receive-hook count of the server."""

    def __init__(self, server, changing: Callable[[str], bool]) -> None:
        self._lock = threading.Lock()
        self._changing = changing
        self.requests: list[str] = []
        self.receptions = 0

        def received() -> None:
            with self._lock:
                self.receptions += 1

        server.add_receive_hook(received)

    def record(self, request: str) -> None:
        with self._lock:
            self.requests.append(request)

    def mark(self) -> int:
        with self._lock:
            return len(self.requests)

    def changes_since(self, mark: int) -> list[str]:
        with self._lock:
            return [r for r in self.requests[mark:] if self._changing(r)]


def virtual_gimbal_device():
    """The reference simulator; changing = MOVE/JOG/STOP/HOME/RESET/FAULT lines."""
    server, device = make_server(0)
    side = DeviceSide(server, lambda line: line.split()[:1] != [] and
                      line.split()[0].upper() in DEVICE_CHANGING)
    handle = device.handle

    def recorded(line: str) -> str:
        side.record(line.strip())
        return handle(line)

    device.handle = recorded
    return side, ['port:=' + str(server.port)], server.stop


def capture_reads(name: str) -> bool:
    """Capture commands that only read: no argument and a returned value (queries such as
    MOT_GetLoadPosition, COM_SysState), and the COM_Connect handshake."""
    from capture_driver.protocol import COMMANDS, DataType

    command = COMMANDS.get(name)
    return name == 'COM_Connect' or (command is not None and command.arg is DataType.NONE
                                      and command.ret is not DataType.NONE)


def capture_device():
    """The Capture simulator over TCP; changing = any command that is not a query."""
    from capture_driver.protocol import BY_OPCODE
    from capture_driver.sim import CaptureSimulator, PedestalModel

    sim = CaptureSimulator(PedestalModel(), tcp_port=0).start()
    side = DeviceSide(sim.tcp, lambda name: not capture_reads(name))
    handle = sim.model.handle

    def recorded(frame, session):
        known = BY_OPCODE.get(frame.opcode)
        side.record(known.name if known is not None else f'0x{frame.opcode:04X}')
        return handle(frame, session)

    sim.model.handle = recorded
    return side, ['transport:=tcp', 'host:=127.0.0.1', f'port:={sim.tcp.port}',
                           'status_period:=0.5'], sim.stop


#: rig name -> (package, executable, node name, simulator factory)
RIGS = {
    'virtual_gimbal': (PKG, 'virtual_gimbal_node', 'virtual_gimbal', virtual_gimbal_device),
    'capture': ('capture_driver', 'capture_driver_node', 'capture_driver', capture_device),
}


class Rig:
    def __init__(self, name: str, ros: RosTestClient, node: ManagedProcess,
                 device: DeviceSide) -> None:
        self.name, self.ros, self.node, self.device = name, ros, node, device

    def service(self, name: str) -> str:
        return f'/{self.name}/{name}'

    def rejections(self) -> int:
        return self.node.output().count(REJECTED)


@pytest.fixture(scope='module', params=sorted(RIGS))
def rig(request, tmp_path_factory):
    package, executable, name, make_device = RIGS[request.param]
    side, device_params, stop_device = make_device()
    presets = tmp_path_factory.mktemp('presets') / 'presets.yaml'
    lease = DomainLease()
    domain = lease.acquire()
    low, high = zip(*(LIMITS[j] for j in JOINTS), strict=True)
    params = [*device_params, f'presets_file:={presets}', 'publish_rate:=10.0',
              f'position_min:={list(low)}', f'position_max:={list(high)}',
              f'velocity_max:=[{VELOCITY_MAX}, {VELOCITY_MAX}]']
    node = ManagedProcess.ros(package, executable, domain,
                              ['--ros-args', *[x for p in params for x in ('-p', p)]])
    ros = RosTestClient(domain, 'property_client')
    try:
        ros.wait_for_message('/joint_states', JointState, timeout=60)
        assert side.receptions > 0  # the hook sees the node's polls
        yield Rig(name, ros, node, side)
    finally:
        ros.close()
        node.stop()
        stop_device()
        lease.release()
    assert 'Traceback' not in node.output(), node.output()[-3000:]


# ------------------------------------------------------------------------- strategies
finite = st.floats(allow_nan=False, allow_infinity=False, width=64)
non_finite = st.sampled_from([math.nan, math.inf, -math.inf])
unknown_name = st.text(min_size=0, max_size=12).filter(lambda s: s not in JOINTS)


@st.composite
def out_of_limit(draw, joint: str) -> float:
    low, high = LIMITS[joint]
    return draw(st.one_of(st.floats(min_value=high + 1e-3, max_value=1e300),
                          st.floats(min_value=-1e300, max_value=low - 1e-3)))


@st.composite
def invalid_joint_command(draw) -> JointState:
    """A JointState with at least one defect the node must reject as a whole."""
    names = draw(st.lists(st.sampled_from(JOINTS), min_size=1, max_size=2, unique=True))
    positions = [draw(st.floats(*LIMITS[n])) for n in names]
    velocities: list[float] = []
    defect = draw(st.sampled_from(('unknown', 'repeated', 'non_finite_position',
                                   'out_of_limit', 'position_length', 'velocity_length',
                                   'nothing_given', 'jog_too_fast', 'empty')))
    if defect == 'unknown':
        names.insert(draw(st.integers(0, len(names))), draw(unknown_name))
        positions.insert(0, draw(finite))
    elif defect == 'repeated':
        names.append(names[0])
        positions.append(positions[0])
    elif defect == 'non_finite_position':
        positions[draw(st.integers(0, len(names) - 1))] = draw(st.sampled_from(
            [math.inf, -math.inf]))
    elif defect == 'out_of_limit':
        index = draw(st.integers(0, len(names) - 1))
        positions[index] = draw(out_of_limit(names[index]))
    elif defect == 'position_length':
        extra = draw(st.lists(finite, min_size=1, max_size=3))
        positions = positions + extra if draw(st.booleans()) or len(names) == 1 \
            else positions[:-1]
    elif defect == 'velocity_length':
        velocities = [0.1] * draw(st.sampled_from([n for n in range(1, 5) if n != len(names)]))
    elif defect == 'nothing_given':
        positions[0] = math.nan
    elif defect == 'jog_too_fast':
        positions = [math.nan] * len(names)
        velocities = [draw(st.one_of(non_finite, st.floats(VELOCITY_MAX + 1e-3, 1e300)))
                      for _ in names]
    else:
        names, positions = [], draw(st.lists(finite, max_size=2))
    return JointState(name=names, position=positions, velocity=velocities)


@st.composite
def invalid_move_goal(draw) -> MoveTo.Goal:
    names = list(JOINTS)
    positions = [draw(st.floats(*LIMITS[n])) for n in names]
    defect = draw(st.sampled_from(('unknown', 'non_finite', 'out_of_limit', 'length',
                                   'empty')))
    if defect == 'unknown':
        names[draw(st.integers(0, 1))] = draw(unknown_name)
    elif defect == 'non_finite':
        positions[draw(st.integers(0, 1))] = draw(non_finite)
    elif defect == 'out_of_limit':
        index = draw(st.integers(0, 1))
        positions[index] = draw(out_of_limit(names[index]))
    elif defect == 'length':
        positions = positions[:1] if draw(st.booleans()) else [*positions, 0.0]
    else:
        names, positions = [], []
    return MoveTo.Goal(joint_names=names, positions=positions)


@st.composite
def invalid_scan(draw) -> StartScan.Request:
    request = StartScan.Request(pattern='sector', pan_min=-0.2, pan_max=0.2, tilt_min=0.0,
                                tilt_max=0.1, speed=0.5, tilt_step=0.1, dwell=0.0)
    defect = draw(st.sampled_from(('pattern', 'non_finite', 'speed', 'out_of_limit')))
    if defect == 'pattern':
        request.pattern = draw(st.text(max_size=10).filter(
            lambda s: s not in ('sector', 'zigzag', 'square', 'snake')))
    elif defect == 'non_finite':
        setattr(request, draw(st.sampled_from(('pan_min', 'pan_max', 'speed'))),
                draw(non_finite))
    elif defect == 'speed':
        request.speed = draw(st.floats(max_value=0.0, allow_nan=False))
    else:
        request.pan_max = draw(out_of_limit('pan'))
    return request


@st.composite
def invalid_preset_request(draw):
    """(service type, name, request) of a preset request that must be refused; no preset is
    ever stored, so every goto/clear of an index is invalid too."""
    kind = draw(st.sampled_from(('set', 'goto', 'clear')))
    index = draw(st.integers(0, 65535))
    if kind == 'goto':
        return GotoPreset, 'goto_preset', GotoPreset.Request(index=index, speed=draw(finite))
    if kind == 'clear':
        return ClearPreset, 'clear_preset', ClearPreset.Request(index=index, all=False)
    names = list(JOINTS)
    positions = [0.1, 0.1]
    defect = draw(st.sampled_from(('unknown', 'non_finite', 'length', 'empty')))
    if defect == 'unknown':
        names[0] = draw(unknown_name)
    elif defect == 'non_finite':
        positions[draw(st.integers(0, 1))] = draw(non_finite)
    elif defect == 'length':
        positions = positions[:1]
    else:
        names, positions = [], []
    return SetPreset, 'set_preset', SetPreset.Request(
        index=index, name=draw(st.text(max_size=8)), use_current_position=False,
        joint_names=names, positions=positions)


# ------------------------------------------------------------------------- properties
@PROPERTY_SETTINGS
@given(msg=invalid_joint_command())
def test_invalid_joint_commands_are_rejected_and_send_nothing(rig, msg) -> None:
    mark, rejected = rig.device.mark(), rig.rejections()
    rig.ros.publish('/joint_command', msg)
    wait_for(lambda: rig.rejections() > rejected, 20, f'the rejection of {msg}')
    assert rig.device.changes_since(mark) == []


@PROPERTY_SETTINGS
@given(goal=invalid_move_goal())
def test_invalid_move_goals_fail_with_a_reason_and_send_nothing(rig, goal) -> None:
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
@given(request=invalid_scan())
def test_invalid_scans_are_refused_with_a_reason_and_send_nothing(rig, request) -> None:
    mark = rig.device.mark()
    reply = rig.ros.call(StartScan, rig.service('start_scan'), request, timeout=20)
    assert not reply.success, request
    assert reply.message
    assert rig.device.changes_since(mark) == []


@PROPERTY_SETTINGS
@given(call=invalid_preset_request())
def test_invalid_preset_requests_are_refused_with_a_reason_and_send_nothing(rig, call) -> None:
    srv_type, name, request = call
    # the Capture controller stores presets itself: clearing an empty slot is a valid no-op
    assume(not (rig.name == 'capture_driver' and name == 'clear_preset'))
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
    assert rig.ros.lifecycle_state(rig.name) == 'active'
    assert rig.device.changes_since(mark) == []
