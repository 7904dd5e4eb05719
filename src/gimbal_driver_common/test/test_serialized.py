"""joint_states published as the middleware's bytes, patched per sample (ros/serialized.py):
what a subscriber deserializes is what the message path (``JointStateMessage.fill``) sends."""

from __future__ import annotations

import math

from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from gimbal_driver_common.device import JointSample
from gimbal_driver_common.ros import messages, serialized
from gimbal_driver_common.ros.serialized import JointStateLayout

JOINTS = ['pan', 'tilt']


def as_tuple(msg: JointState) -> tuple:
    """The fields, NaN made comparable."""
    def values(seq):
        return [('nan' if math.isnan(v) else v) for v in seq]
    return (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id,
            list(msg.name), values(msg.position), values(msg.velocity), values(msg.effort))


def published(message: messages.JointStateMessage, sample: JointSample,
              torque_constants=None) -> JointState:
    out = message.publishable(sample, JOINTS, torque_constants)
    assert isinstance(out, bytes)
    return deserialize_message(out, JointState)


def test_the_bytes_carry_what_the_filled_message_carries():
    message = messages.JointStateMessage()
    samples = [
        JointSample({'pan': 0.1, 'tilt': -0.2}, {'pan': 0.3, 'tilt': 0.0}, stamp=1764643000.5),
        JointSample({'pan': -3.0, 'tilt': 1e-9}, {'pan': math.nan}, stamp=1764643001.123456),
        JointSample({'pan': 2.0, 'tilt': 0.5}, {}, currents={'pan': 2.0}, stamp=1764643002.0),
    ]
    for torque_constants in (None, {'pan': 0.5, 'tilt': 0.1}):
        for sample in samples:
            expected = as_tuple(messages.JointStateMessage().fill(sample, JOINTS,
                                                                  torque_constants))
            assert as_tuple(published(message, sample, torque_constants)) == expected


def test_a_new_shape_gets_its_own_layout():
    """A joint the sample lacks, then effort appearing: each a new serialized form."""
    message = messages.JointStateMessage()
    both = JointSample({'pan': 0.1, 'tilt': 0.2}, {'pan': 0.0, 'tilt': 0.0}, stamp=1.5)
    pan_only = JointSample({'pan': 0.4}, {'pan': 0.1}, stamp=2.25)
    assert list(published(message, both).name) == JOINTS
    assert as_tuple(published(message, pan_only)) == (2, 250_000_000, '', ['pan'], [0.4],
                                                      [0.1], [])
    with_current = JointSample({'pan': 0.1, 'tilt': 0.2}, {}, currents={'tilt': 3.0}, stamp=3.0)
    msg = published(message, with_current, {'pan': 1.0, 'tilt': 2.0})
    assert msg.effort[1] == 6.0 and math.isnan(msg.effort[0])


def test_where_the_layout_is_not_found_the_message_itself_is_published(monkeypatch):
    """Another middleware's format (no sentinel found once): the filled JointState."""
    monkeypatch.setattr(serialized, 'unique_offset', lambda data, pattern: None)
    assert JointStateLayout.build(JOINTS, 0) is None
    sample = JointSample({'pan': 0.1, 'tilt': 0.2}, {'pan': 0.0, 'tilt': 0.0}, stamp=4.0)
    out = messages.JointStateMessage().publishable(sample, JOINTS)
    assert isinstance(out, JointState) and list(out.position) == [0.1, 0.2]


def test_a_layout_that_does_not_round_trip_is_refused(monkeypatch):
    monkeypatch.setattr(JointStateLayout, 'round_trips', lambda self, names, counts: False)
    assert JointStateLayout.build(JOINTS, 2) is None
