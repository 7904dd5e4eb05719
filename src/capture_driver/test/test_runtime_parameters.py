"""Capture parameters changed while the node runs (`ros2 param set`), node against capture_sim.

The parameters are set through the node's /capture_driver/set_parameters service, as
`ros2 param set` does; the effect is watched on the node's topics.
"""

from __future__ import annotations

import pytest

pytest.importorskip('rclpy', reason='node tests need the ROS environment')
pytest.importorskip('gimbal_msgs', reason='node tests need the built workspace (make build)')
from sensor_msgs.msg import Imu, NavSatFix

pytestmark = pytest.mark.ros

PKG = 'capture_driver'
NODE = 'capture_driver'


@pytest.fixture(scope='module')
def rig(capture_rig):
    with capture_rig(['--time-scale', '4'],
                     ['publish_rate:=20.0', 'reconnect_period:=0.3', 'imu_rate:=5.0',
                      'fix_rate:=0.0']) as (started, _):
        yield started.ros, started.node


def test_frame_id_and_rate_take_effect_when_set(rig) -> None:
    ros, _ = rig
    imu = ros.wait_for_message(f'/{NODE}/imu', Imu, timeout=15)
    assert imu.header.frame_id == 'capture_imu'
    result = ros.set_parameter(NODE, 'imu_frame_id', 'mast_imu')
    assert result.successful, result.reason
    ros.wait_for_message(f'/{NODE}/imu', Imu, lambda m: m.header.frame_id == 'mast_imu',
                         timeout=15)
    # ~/fix was off (fix_rate 0); a rate set now starts it.
    result = ros.set_parameter(NODE, 'fix_rate', 2.0)
    assert result.successful, result.reason
    ros.wait_for_message(f'/{NODE}/fix', NavSatFix, timeout=15)
    assert ros.get_parameter(NODE, 'fix_rate') == 2.0


def test_invalid_values_are_refused(rig) -> None:
    ros, _ = rig
    refused = ros.set_parameter(NODE, 'acceleration', 0.0)  # range 1e-3..1000 rad/s^2
    assert not refused.successful and 'acceleration' in refused.reason
    refused = ros.set_parameter(NODE, 'gps_target_slot', 16)  # device targets 1..15
    assert not refused.successful and 'gps_target_slot' in refused.reason
    assert ros.get_parameter(NODE, 'acceleration') == 3.0
    assert ros.get_parameter(NODE, 'gps_target_slot') == 15


def test_link_mapping_and_opt_ins_need_reconfigure(rig) -> None:
    ros, node = rig
    for name, value in (('axis_ids', [2, 1]), ('joint_directions', [1.0, 1.0]),
                        ('host', '10.0.0.1'), ('allow_reboot', True)):
        refused = ros.set_parameter(NODE, name, value)
        assert not refused.successful, name
        assert f"'{name}' needs reconfigure" in refused.reason, refused.reason
    assert ros.get_parameter(NODE, 'allow_reboot') is False
    node.wait_for_output("parameter change refused: parameter 'allow_reboot'")
