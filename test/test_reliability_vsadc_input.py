"""The VSADC node reads its input bytes by hand (issue 17: it was the slowest reader).

Before, every gyro, star-tracker and reference message was built as a generated Python
message (an Imu alone cost more than the detector); the node fell furthest behind under
load and a kill lost its whole backlog. Now the subscriptions are raw and decode the
bytes with :func:`messages.decode_stamped`; these tests check that the bytes of both
serialisers (the replay's hand codecs and rclpy's) give the same samples, and that
bytes nobody can read are counted, not fatal.
"""

from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
import pytest
from rclpy.parameter import Parameter
from rclpy.serialization import serialize_message
from ros_harness import RosWorld
from sensor_msgs.msg import Imu

from rwa_monitor.nodes import messages
from rwa_monitor.nodes.vsadc_detector import VsadcDetectorNode
from rwa_monitor.sim.aocs import named_fault, simulate_aocs

FRAMES = ['body', '', 'a_longer_frame_name']


@pytest.mark.parametrize('frame', FRAMES)
def test_decode_stamped_reads_both_serialisers(frame):
    values = (0.1, -0.2, 0.3, 0.9)
    cases = [(Imu, messages.imu, messages.imu_codec(frame), values[:3]),
             (QuaternionStamped, messages.quaternion, messages.quaternion_codec(frame),
              values),
             (Vector3Stamped, messages.vector3, messages.vector3_codec(frame), values[:3])]
    for msg_type, build, codec, data in cases:
        count = messages.STAMPED_SIZES[msg_type.__name__]
        for buffer in (codec.encode(86399.25, data),
                       serialize_message(build(86399.25, data, frame))):
            t, got = messages.decode_stamped(buffer, count)
            if msg_type is Imu:
                got = got[messages.IMU_ANGULAR_VELOCITY]
            assert t == 86399.25 and got == data


def test_decode_stamped_refuses_other_bytes():
    imu = serialize_message(messages.imu(1.0, [0.1, 0.2, 0.3]))
    for bad in (b'', b'\x00\x01', b'\x01\x00' + imu[2:], imu[:-8], imu + bytes(8),
                serialize_message(messages.vector3(1.0, [1.0, 2.0, 3.0]))):
        with pytest.raises(ValueError):
            messages.decode_stamped(bad, messages.STAMPED_SIZES['Imu'])


def _callbacks(node):
    return {sub.topic_name.rsplit('/', 1)[-1]: sub for sub in node.subscriptions
            if sub.topic_name.startswith('/telemetry/')}


@pytest.mark.ros
def test_node_reads_raw_bytes_and_gives_the_events_of_the_message_path():
    tele = simulate_aocs(600.0, fault=named_fault('fast', 'y', 200.0), seed=31)
    config = {'window': 40, 'sigma_window': 40, 'reference_window': 200}
    overrides = [Parameter(k, value=v) for k, v in config.items()]
    imu, quat, vec = messages.imu_codec(), messages.quaternion_codec(), messages.vector3_codec()
    with RosWorld() as world:
        by_bytes = world.node(VsadcDetectorNode, parameter_overrides=overrides)
        by_message = world.node(VsadcDetectorNode, parameter_overrides=overrides,
                                namespace='other')
        subs = _callbacks(by_bytes)
        assert all(sub.raw for sub in subs.values()), 'input subscriptions must be raw'
        for k, t in enumerate(tele.time.tolist()):
            g, q, r = (tele.gyro[k].tolist(), tele.attitude[k].tolist(),
                       tele.reference_rate[k].tolist())
            # Odd rows as rclpy's bytes, even rows as the replay's: both must read.
            if k % 2:
                subs['reference_rate'].callback(serialize_message(messages.vector3(t, r)))
                subs['star_tracker'].callback(serialize_message(messages.quaternion(t, q)))
                subs['gyro'].callback(serialize_message(messages.imu(t, g)))
            else:
                subs['reference_rate'].callback(vec.encode(t, r))
                subs['star_tracker'].callback(quat.encode(t, q))
                subs['gyro'].callback(imu.encode(t, g))
            by_message.on_reference(messages.vector3(t, r))
            by_message.on_star_tracker(messages.quaternion(t, q))
            by_message.on_gyro(messages.imu(t, g))
        assert by_bytes.samples == by_message.samples == len(tele)
        assert by_bytes.events and [(e.component, e.kind, e.index) for e in by_bytes.events] \
            == [(e.component, e.kind, e.index) for e in by_message.events]
        assert by_bytes.counters == by_message.counters
        for name, sub in subs.items():
            sub.callback(b'\x00\x01\x00\x00garbage')
        assert by_bytes.counters['undecodable'] == 3
        assert by_bytes.counters['gyro_messages'] == len(tele) + 1


@pytest.mark.ros
@pytest.mark.parametrize('order', ['gyro_first', 'reference_first'])
def test_a_replay_loop_gives_the_file_events_again_with_the_file_rows(order):
    # A replay loop restarts the detector; the events of the second pass must be the
    # file pipeline's, change index = file row (as llr_detector), whichever of the three
    # topics brings the first sample of the new pass.
    from rwa_monitor.pipelines import vsadc as pipeline
    tele = simulate_aocs(400.0, fault=named_fault('fast', 'y', 150.0), seed=33)
    config = {'window': 40, 'sigma_window': 40, 'reference_window': 200}
    expected = [(e.component, e.kind, e.index)
                for e in pipeline.run(tele, {**pipeline.DEFAULTS, **config})]
    assert expected
    overrides = [Parameter(k, value=v) for k, v in config.items()]
    with RosWorld() as world:
        node = world.node(VsadcDetectorNode, parameter_overrides=overrides)
        for _ in range(2):
            for k, t in enumerate(tele.time.tolist()):
                calls = [(node.on_gyro, messages.imu(t, tele.gyro[k].tolist())),
                         (node.on_star_tracker, messages.quaternion(t, tele.attitude[k])),
                         (node.on_reference, messages.vector3(t, tele.reference_rate[k]))]
                for call, msg in (calls if order == 'gyro_first' else calls[::-1]):
                    call(msg)
        got = [(e.component, e.kind, e.index) for e in node.events]
        assert node.counters['time_jump_reset'] == 1
        assert node.counters['unpaired_gyro'] == 0
    assert got == expected + expected
