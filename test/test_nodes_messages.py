"""Message conversions: stamps, the hand-written JointState CDR, events as statuses."""

import math

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.nodes import messages


@pytest.mark.parametrize('seconds', [0.0, 0.3, 1234.5678, 86399.9, 1.9999999999, 7.0])
def test_stamps_round_trip_to_the_nanosecond(seconds):
    stamp = messages.to_stamp(seconds)
    assert 0 <= stamp.nanosec < 1_000_000_000
    assert messages.to_seconds(stamp) == pytest.approx(seconds, abs=1e-9)
    assert messages.to_seconds(Time(sec=0, nanosec=300_000_000)) == 0.3


def _message(names, velocity, effort, position=(), frame='', seconds=12.25):
    msg = JointState()
    msg.header.stamp = messages.to_stamp(seconds)
    msg.header.frame_id = frame
    msg.name, msg.position, msg.velocity, msg.effort = names, position, velocity, effort
    return msg


CASES = [
    (['rw1', 'rw2', 'rw3', 'rw4'], [1.0, -2.0, 3.5, 4.0], [1e-4, 2e-4, -3e-4, 0.0], (), ''),
    (['rw1'], [1.0], [2.0, 3.0], (), 'ab'),          # lengths differ
    ([''], [math.nan], [math.inf], (0.5,), 'body'),   # empty name, non-finite values
    ([], [], [], (), ''),
    (['wheel_ä', 'x' * 13], [0.1, 0.2], [], (1.0, 2.0, 3.0), 'abc'),
]


@pytest.mark.parametrize('names,velocity,effort,position,frame', CASES)
def test_decoder_reads_what_rclpy_serialises(names, velocity, effort, position, frame):
    buffer = serialize_message(_message(names, velocity, effort, position, frame))
    seconds, got_names, got_velocity, got_effort = messages.decode_joint_state(buffer)
    assert seconds == 12.25 and got_names == names
    np.testing.assert_array_equal(got_velocity, velocity)
    np.testing.assert_array_equal(got_effort, effort)


@pytest.mark.parametrize('names,velocity,effort,position,frame', CASES)
def test_encoder_writes_what_rclpy_reads(names, velocity, effort, position, frame):
    buffer = messages.encode_joint_state(12.25, names, velocity, effort, frame)
    msg = deserialize_message(buffer, JointState)
    assert messages.to_seconds(msg.header.stamp) == 12.25
    assert list(msg.name) == names and msg.header.frame_id == frame
    assert len(msg.position) == 0
    np.testing.assert_array_equal(msg.velocity, velocity)
    np.testing.assert_array_equal(msg.effort, effort)


def test_decoder_refuses_garbage():
    with pytest.raises(ValueError):
        messages.decode_joint_state(b'\x00\x01\x00\x00\x01')
    with pytest.raises(ValueError):
        messages.decode_joint_state(b'\x00\x00\x00\x00' + bytes(40))


def test_samples_of_rules():
    seconds, samples = messages.samples_of(1.0, ['a', '', 'a', 'b'], [1, 2, 3, 4],
                                           [5, 6, 7, 8])
    assert samples == [('a', 1, 5), ('b', 4, 8)]
    problems = messages.wheel_name_problems(['a', '', 'a', 'b'])
    assert problems == {'empty_name': 1, 'duplicate_name': 1}
    with pytest.raises(messages.BadMessage) as err:
        messages.samples_of(1.0, ['a'], [1.0], [])
    assert err.value.reason == 'length_mismatch'


def test_event_status_round_trip():
    event = AnomalyEvent('llr', 'rw2', 'both', 150.0 + 1e-7, 1500, 180.1, 1801,
                         3.0e-12, 1, {'delta_dry_nm': 2.0e-4 / 3, 'z_dry': -1.5})
    status = messages.event_status(event, 'llr_detector')
    assert status.level == DiagnosticStatus.ERROR
    assert status.name == 'llr_detector: rw2 anomaly' and status.hardware_id == 'rw2'
    assert messages.status_event(status) == event
    assert messages.event_level('both') != messages.event_level('dry')


@pytest.mark.parametrize('names', [['rw1', 'rw2', 'rw3', 'rw4'], ['a'], ['wheel_ä', 'bb'], []])
def test_fixed_layout_codec_agrees_with_rclpy(names):
    codec = messages.JointStateCodec(names)
    speeds = [float(i) + 0.5 for i in range(len(names))]
    frictions = [math.nan if i == 0 else -1e-4 * i for i in range(len(names))]
    msg = deserialize_message(codec.encode(3.75, speeds, frictions), JointState)
    assert messages.to_seconds(msg.header.stamp) == 3.75 and list(msg.name) == names
    np.testing.assert_array_equal(msg.velocity, speeds)
    np.testing.assert_array_equal(msg.effort, frictions)
    assert len(msg.position) == 0
    seconds, got_names, velocity, effort = codec.decode(
        serialize_message(_message(names, speeds, frictions, seconds=3.75)))
    assert seconds == 3.75 and got_names == names
    np.testing.assert_array_equal(velocity, speeds)
    np.testing.assert_array_equal(effort, frictions)


def test_fixed_layout_codec_declines_other_layouts():
    codec = messages.JointStateCodec(['rw1', 'rw2'])
    others = [_message(['rw1', 'rw3'], [1.0, 2.0], [0.0, 0.0]),
              _message(['rw1', 'rw2'], [1.0], [0.0, 0.0]),
              _message(['rw1', 'rw2'], [1.0, 2.0], [0.0, 0.0, 1.0]),
              _message(['rw1', 'rw2'], [1.0, 2.0], [0.0, 0.0], position=(1.0, 2.0)),
              _message(['rw1', 'rw2'], [1.0, 2.0], [0.0, 0.0], frame='body'),
              _message(['rw1'], [1.0], [0.0])]
    for msg in others:
        assert codec.decode(serialize_message(msg)) is None
    assert codec.decode(b'\x00\x01') is None


def test_fixed_layout_codec_ignores_padding_bytes():
    codec = messages.JointStateCodec(['rw1', 'rw22'])
    clean = codec.encode(1.5, [1.0, 2.0], [3.0, 4.0])
    dirty = bytearray(clean)
    dirty[17:20] = b'\xaa\xbb\xcc'  # the padding after the empty frame_id
    dirty[41:44] = b'\xdd\xee\xff'  # the padding after 'rw22'
    assert codec.decode(bytes(dirty)) == codec.decode(clean)
    assert codec.decode(bytes(dirty))[2] == (1.0, 2.0)


@pytest.mark.parametrize('frame', ['body', '', 'star_tracker_1'])
def test_stamped_codecs_equal_the_message_builders(frame):
    values = [0.1, -0.2, 0.3, 0.9]
    cases = [(messages.imu_codec(frame), Imu, messages.imu, values[:3]),
             (messages.quaternion_codec(frame), QuaternionStamped, messages.quaternion,
              values),
             (messages.vector3_codec(frame), Vector3Stamped, messages.vector3, values[:3])]
    for codec, msg_type, build, data in cases:
        decoded = deserialize_message(codec.encode(86399.25, data), msg_type)
        assert decoded == build(86399.25, data, frame)
