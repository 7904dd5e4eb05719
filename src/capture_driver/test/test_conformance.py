"""The conformance suite against capture_driver_node (a process) and the Capture simulator
over TCP: the registry's handle (``CaptureSimHandle``) in the test process, so the suite
sees every command the pedestal received."""

from __future__ import annotations

import pytest

pytest.importorskip('gimbal_msgs', reason='needs the colcon-built workspace (make build)')

from sensor_msgs.msg import Imu, JointState
from std_srvs.srv import Trigger

from gimbal_driver_testing import wait_for
from gimbal_driver_testing.conformance import ConformanceRig, DriverConformance
from gimbal_driver_testing.silent_request_conformance import SilentRequest
from gimbal_driver_testing.stop_conformance import request_name
from gimbal_msgs.srv import DeviceCommand

#: s SCN_StopScan is answered late: "Stop scan can take up to 500 milliseconds before
#: sending ACK" (protocol 4.3.9), a little beyond
STOP_SCAN_LATE_S = 0.55
#: the commands that stop a Capture axis in a stop
AXIS_STOP = ('MOT_SetSpeedMode', 'MOT_SetSpeed', 'MOT_Update')


class TestCaptureConformance(DriverConformance):
    __test__ = True
    driver = 'capture'
    reports_current = True  # motor current (A) in ~/status; effort via torque_constants
    joints = ('pan', 'tilt')
    small_move = {'pan': 0.4, 'tilt': -0.2}
    far_move = ('pan', -2.5, 0.1)
    jog = ('pan', 0.3)
    tolerance = 2e-3
    preset_index = 2
    scan = dict(pattern='snake', pan_min=-0.2, pan_max=0.2, tilt_min=0.0, tilt_max=0.2,
                speed=0.5, tilt_step=0.1)

    # the kinds of request a controller may leave unanswered (the simulator's mute/delay)
    silent_requests = (
        # the IMU is read while ~/imu has a subscriber, as in the measurement of the issue
        SilentRequest('sensor getter', 'IMU_GetRoll', periodic=True,
                      timeout_parameter='request_timeout', topic=('imu', Imu)),
        SilentRequest('status register', 'ERR_OperationRegister', periodic=True,
                      timeout_parameter='request_timeout'),
        SilentRequest('identity read', 'COM_GetPn', at_connect=True),
        SilentRequest('service request', 'COM_GetFw', timeout_parameter='request_timeout',
                      service=(DeviceCommand, 'command',
                               lambda: DeviceCommand.Request(command='COM_GetFw'))),
    )
    # The first jog from position mode used to wait behind a muted IMU read (issue 45: its
    # MOT_SetSpeedMode went out only after the read's timeout): a motion set-up no longer
    # waits behind a read (answers.AnswerBook.motion_first), so no figure is a gap here.
    # a loaded run refused one ros2_control command: "MOT_Update (axis 1): no reply within
    # 0.5 s" from the simulator starved in the test process (docs/testing.md)
    answer_parameters = ('request_timeout:=5.0',)
    required_request = ('COM_Connect', 'COM_Connect')
    handshake_request = 'COM_Connect'

    @pytest.mark.ros
    def test_stop_scan_answered_after_500_ms_still_stops_the_axes(
            self, rig: ConformanceRig) -> None:
        """~/stop while SCN_StopScan takes its documented 500 ms: the axes are told to stop
        first (device motion before scans), they rest, and ~/stop says so."""
        timeout = rig.ros.get_parameter(self.node_name, 'command_timeout')
        # no dead-man stop in between: the only stop is ~/stop's
        assert rig.ros.set_parameter(self.node_name, 'command_timeout', 60.0).successful
        try:
            with self.device_fault(rig):
                # one jog, whole at the simulator once the axis moves: what follows the
                # mark is ~/stop's alone
                joint, velocity = self.jog
                rig.ros.publish('joint_command', JointState(name=[joint], velocity=[velocity]))
                wait_for(lambda: rig.sim.moving(joint), 20.0, f'{joint} to start jogging')
                rig.sim.delay('SCN_StopScan', STOP_SCAN_LATE_S)
                mark = rig.sim.mark()
                reply = rig.ros.call(Trigger, self.srv('stop'), Trigger.Request(),
                                     timeout=60.0)
                self.check_stopped_axes_first(rig, mark, reply)
        finally:
            assert rig.ros.set_parameter(self.node_name, 'command_timeout', timeout).successful

    def check_stopped_axes_first(self, rig: ConformanceRig, mark: int,
                                 reply: Trigger.Response) -> None:
        """At rest, the axes told to stop before the scan stop went out, ~/stop says so."""
        self.wait_stopped(rig, self.jog[0], 'the axes to rest with SCN_StopScan answered late')
        names = [request_name(r) for r in rig.sim.requests()[mark:]]
        assert 'SCN_StopScan' in names, names
        first_axis_stop = next((i for i, n in enumerate(names) if n in AXIS_STOP), None)
        assert first_axis_stop is not None, f'the axes were never told to stop: {names}'
        assert first_axis_stop < names.index('SCN_StopScan'), (
            f'the scan stop went before the axes were told to stop: {names}')
        assert reply.success, reply.message
