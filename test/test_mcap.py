"""MCAP telemetry files: round trip, rosbag2 layout, errors."""

from mcap.reader import make_reader
import numpy as np
import pytest
from rclpy.serialization import serialize_message

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.nodes import messages
from rwa_monitor.telemetry import mcap_io, read_telemetry, Telemetry, Wheel, write_telemetry


def _telemetry(n=50, seed=3):
    rng = np.random.default_rng(seed)
    time = 100.0 + 0.1 * np.arange(n)
    speed = rng.normal(size=(n, 2))
    speed[min(7, n - 1), 1] = np.nan
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return Telemetry(
        time=time,
        wheels={'rw1': Wheel(speed[:, 0], rng.normal(size=n)), 'rw2': Wheel(speed[:, 1])},
        gyro=rng.normal(size=(n, 3)), attitude=q, reference_rate=rng.normal(size=(n, 3)),
        aux={'rw1_temperature': rng.normal(size=n)}, truth={'rw1_dry': rng.normal(size=n)})


def test_round_trip_keeps_every_channel(tmp_path):
    tele = _telemetry()
    path = tmp_path / 'tele.mcap'
    write_telemetry(path, tele)
    back = read_telemetry(path)
    np.testing.assert_allclose(back.time, tele.time, rtol=0, atol=1e-9)
    assert list(back.wheels) == ['rw1', 'rw2']
    np.testing.assert_array_equal(back.wheels['rw1'].speed, tele.wheels['rw1'].speed)
    np.testing.assert_array_equal(back.wheels['rw1'].friction, tele.wheels['rw1'].friction)
    assert np.isnan(back.wheels['rw2'].speed[7])
    assert np.all(np.isnan(back.wheels['rw2'].friction))
    for group in ('gyro', 'attitude', 'reference_rate'):
        np.testing.assert_array_equal(getattr(back, group), getattr(tele, group))
    np.testing.assert_array_equal(back.aux['rw1_temperature'], tele.aux['rw1_temperature'])
    np.testing.assert_array_equal(back.truth['rw1_dry'], tele.truth['rw1_dry'])


def test_rosbag2_layout(tmp_path):
    path = tmp_path / 'tele.mcap'
    mcap_io.write(path, _telemetry(n=5))
    with open(path, 'rb') as handle:
        reader = make_reader(handle)
        assert reader.get_header().profile == 'ros2'
        summary = reader.get_summary()
    topics = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
    assert topics[mcap_io.WHEELS] == 'sensor_msgs/msg/JointState'
    assert topics[mcap_io.GYRO] == 'sensor_msgs/msg/Imu'
    assert all(c.message_encoding == 'cdr' for c in summary.channels.values())
    assert summary.statistics.message_count == 5 * 5


def test_only_wheels(tmp_path):
    tele = Telemetry(time=np.arange(1.0, 4.0), wheels={'a': Wheel(np.ones(3), np.zeros(3))})
    path = tmp_path / 'w.mcap'
    mcap_io.write(path, tele)
    back = mcap_io.read(path)
    assert back.gyro is None and back.attitude is None and not back.aux
    np.testing.assert_array_equal(back.time, tele.time)


def test_bad_files_name_the_problem(tmp_path):
    with pytest.raises(TelemetrySchemaError, match='no such file'):
        mcap_io.read(tmp_path / 'missing.mcap')
    junk = tmp_path / 'junk.mcap'
    junk.write_bytes(b'not an mcap file at all')
    with pytest.raises(TelemetrySchemaError, match='junk.mcap'):
        mcap_io.read(junk)


def test_channels_with_other_stamps_are_refused(tmp_path):
    from mcap.writer import Writer
    path = tmp_path / 'skew.mcap'
    with open(path, 'wb') as handle:
        writer = Writer(handle)
        writer.start(profile='ros2')
        wheels = writer.register_channel(mcap_io.WHEELS, 'cdr', writer.register_schema(
            'sensor_msgs/msg/JointState', 'ros2msg', b''))
        gyro = writer.register_channel(mcap_io.GYRO, 'cdr', writer.register_schema(
            'sensor_msgs/msg/Imu', 'ros2msg', b''))
        for t in (1.0, 2.0):
            writer.add_message(wheels, int(t * 1e9), serialize_message(
                messages.joint_state(t, ['rw1'], [1.0], [0.0])), int(t * 1e9))
            writer.add_message(gyro, int(t * 1e9), serialize_message(
                messages.imu(t + 0.5, [0.0, 0.0, 0.0])), int(t * 1e9))
        writer.finish()
    with pytest.raises(TelemetrySchemaError, match='telemetry/gyro'):
        mcap_io.read(path)
