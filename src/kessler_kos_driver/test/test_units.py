"""The SI <-> rotation rule (units.py), and the one example rig everywhere it is written:
the simulator's calibrated ranges, registration.SIM_RIG, config/kessler_kos_driver_sim.yaml
and the node's default limits (the URDF equals those: test/test_description_files.py)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import yaml

from kessler_kos_driver.registration import SIM_RIG, SPEC, sim_rig_parameters
from kessler_kos_driver.sim import DEFAULT_RANGES
from kessler_kos_driver.units import MOTOR_RADIANS, JointUnits, joint_units

PACKAGE = Path(__file__).resolve().parent.parent


def test_a_calibrated_axis_with_a_span_reports_offset_plus_its_share_of_the_span():
    tilt = JointUnits(span=math.pi, offset=-math.pi / 2).conversion(-40.0)
    assert tilt.from_span and tilt.per_rotation == pytest.approx(-math.pi / 40)
    assert tilt.to_si(0.0) == pytest.approx(-math.pi / 2)      # the begin mark
    assert tilt.to_si(-40.0) == pytest.approx(math.pi / 2)     # the end mark
    assert tilt.to_rotations(0.0) == pytest.approx(-20.0)
    assert tilt.rate_to_si(-4.0) == pytest.approx(math.pi / 10)   # velocities: no offset
    assert tilt.rate_to_rotations(math.pi / 10) == pytest.approx(-4.0)
    assert tilt.magnitude_to_si(65.0) == pytest.approx(65.0 * math.pi / 40)
    assert tilt.describe() == 'SI (calibrated_spans)'


def test_without_a_span_or_calibration_joint_scales_and_the_offset_apply():
    uncalibrated = JointUnits(span=1.5, offset=0.2, scale=0.01).conversion(0.0)
    assert not uncalibrated.from_span
    assert uncalibrated.to_si(10.0) == pytest.approx(0.3)
    assert uncalibrated.describe() == 'SI (joint_scales)'
    default = JointUnits().conversion(200.0)
    assert default.to_si(1.0) == pytest.approx(2 * math.pi)
    assert default.motor_radians and default.describe() == MOTOR_RADIANS
    assert JointUnits(scale=-2 * math.pi).conversion(0.0).describe() == MOTOR_RADIANS


@pytest.mark.parametrize(('spans', 'offsets', 'scales', 'message'), [
    ([1.0, 0.0], [0.0, 0.0], [1.0, 0.0], 'joint_scales: need 2 finite non-zero'),
    ([1.0, math.inf], [0.0, 0.0], [1.0, 1.0], 'calibrated_spans: need 2 finite values'),
    ([1.0], [0.0, 0.0], [1.0, 1.0], r'calibrated_spans: need 2 .*\(0 = no span'),
    ([1.0, 0.0], [0.0, math.nan], [1.0, 1.0], 'joint_offsets: need 2 finite'),
])
def test_bad_unit_parameters_name_the_parameter(spans, offsets, scales, message):
    with pytest.raises(ValueError, match=message):
        joint_units(2, spans, offsets, scales)


def test_the_sim_rig_spans_lie_over_the_simulators_calibrated_ranges():
    """Every joint of the example rig spans exactly its node limits, begin to end."""
    for joint, rig in SIM_RIG.items():
        units = JointUnits(rig.span, rig.offset).conversion(DEFAULT_RANGES[joint])
        ends = sorted((units.to_si(0.0), units.to_si(DEFAULT_RANGES[joint])))
        assert ends == pytest.approx([rig.lower, rig.upper]), joint
    parameters = SPEC.node_parameters
    assert {k: parameters[k] for k in sim_rig_parameters()} == sim_rig_parameters(SPEC.joints)


def test_the_sim_config_file_is_the_sim_rig():
    config = yaml.safe_load((PACKAGE / 'config' / 'kessler_kos_driver_sim.yaml').read_text())
    parameters = config['/**']['ros__parameters']
    expected = sim_rig_parameters(tuple(parameters['joint_names']))
    for name, values in expected.items():
        assert parameters[name] == pytest.approx(values, abs=1e-12), name


def test_the_node_defaults_are_the_sim_rig():
    pytest.importorskip('rclpy', reason='the node class needs the ROS environment')
    pytest.importorskip('gimbal_msgs', reason='the node class needs the built workspace')
    from kessler_kos_driver.node import KosDriverNode

    joints = tuple(KosDriverNode.DEFAULT_JOINT_NAMES)
    expected = sim_rig_parameters(joints)
    assert list(KosDriverNode.DEFAULT_POSITION_MIN) == pytest.approx(expected['position_min'])
    assert list(KosDriverNode.DEFAULT_POSITION_MAX) == pytest.approx(expected['position_max'])
    assert list(KosDriverNode.DEFAULT_VELOCITY_MAX) == pytest.approx(expected['velocity_max'])
