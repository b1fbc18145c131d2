"""Recordings: rosbag2 folders and bare .mcap/.db3 in and out, multi-rate, both encodings."""

import hashlib
import json
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from rwa_monitor.exceptions import ConfigError, TelemetrySchemaError
from rwa_monitor.telemetry import codecs, rosbag_io
from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel, write_telemetry

FORMATS = ['bag', 'tele.mcap', 'tele.db3']


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


def _digest(path):
    path = pathlib.Path(path)
    files = sorted(p for p in path.rglob('*') if p.is_file()) if path.is_dir() else [path]
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in files}


def _all_messages(path):
    """Deserialise every message with rosbags alone; return topic -> count."""
    store = rosbag_io.typestore()
    counts = {}
    with Reader(path) as reader:
        for conn, _, data in reader.messages():
            store.deserialize_cdr(data, conn.msgtype)
            counts[conn.topic] = counts.get(conn.topic, 0) + 1
    return counts


@pytest.mark.parametrize('name', FORMATS)
def test_round_trip_keeps_every_channel(tmp_path, name):
    tele = _telemetry()
    path = tmp_path / name
    write_telemetry(path, tele)
    back = read_telemetry(path)
    np.testing.assert_allclose(back.time, tele.time, rtol=0, atol=1e-9)
    assert back.present == {}
    assert list(back.wheels) == ['rw1', 'rw2']
    np.testing.assert_array_equal(back.wheels['rw1'].speed, tele.wheels['rw1'].speed)
    np.testing.assert_array_equal(back.wheels['rw1'].friction, tele.wheels['rw1'].friction)
    assert np.isnan(back.wheels['rw2'].speed[7])
    assert np.all(np.isnan(back.wheels['rw2'].friction))
    for group in ('gyro', 'attitude', 'reference_rate'):
        np.testing.assert_array_equal(getattr(back, group), getattr(tele, group))
    np.testing.assert_array_equal(back.aux['rw1_temperature'], tele.aux['rw1_temperature'])
    np.testing.assert_array_equal(back.truth['rw1_dry'], tele.truth['rw1_dry'])


@pytest.mark.parametrize('name', FORMATS)
def test_rosbags_reads_every_message_we_write(tmp_path, name):
    path = tmp_path / name
    write_telemetry(path, _telemetry(n=20))
    if name == 'bag':
        assert (path / 'metadata.yaml').is_file() and len(list(path.glob('*.mcap'))) == 1
    counts = _all_messages(path)
    assert counts == {'/telemetry/wheels': 20, '/telemetry/gyro': 20,
                      '/telemetry/star_tracker': 20, '/telemetry/reference_rate': 20,
                      rosbag_io.COLUMNS_TOPIC: 20}


@pytest.mark.parametrize('name', FORMATS)
def test_same_input_same_bytes(tmp_path, name):
    tele = _telemetry()
    write_telemetry(tmp_path / 'a' / name, tele)
    write_telemetry(tmp_path / 'b' / name, tele)
    first, second = _digest(tmp_path / 'a' / name), _digest(tmp_path / 'b' / name)
    assert first == second and first


def test_simulate_twice_same_seed_same_bytes(tmp_path):
    for run in ('a', 'b'):
        subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', 'simulate', 'friction',
                        '--seconds', '60', '--seed', '4', '-o', str(tmp_path / run / 'bag')],
                       check=True, capture_output=True, timeout=120)
    assert _digest(tmp_path / 'a' / 'bag') == _digest(tmp_path / 'b' / 'bag')


def test_writing_replaces_a_recording_whole_and_refuses_other_folders(tmp_path):
    path = tmp_path / 'bag'
    write_telemetry(path, _telemetry(n=10))
    write_telemetry(path, _telemetry(n=4))
    assert len(read_telemetry(path)) == 4
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag']  # no temporary left
    other = tmp_path / 'notes'
    other.mkdir()
    (other / 'keep.txt').write_text('x')
    from rwa_monitor.exceptions import OutputError
    with pytest.raises(OutputError, match='not part of a rosbag2 recording'):
        write_telemetry(other, _telemetry(n=4))
    assert (other / 'keep.txt').read_text() == 'x'


def test_hand_codecs_are_canonical_cdr():
    """The replay's fast encoders give the bytes of the reference serialiser."""
    store = rosbag_io.typestore()
    t = store.types
    hdr = t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](sec=12, nanosec=5),
                                   frame_id='')
    ref = store.serialize_cdr(t['sensor_msgs/msg/JointState'](
        header=hdr, name=['rw1', 'rw22', 'w'], position=np.zeros(0),
        velocity=np.array([1.0, 2.0, 3.0]), effort=np.array([4.0, 5.0, 6.0])),
        'sensor_msgs/msg/JointState')
    mine = codecs.JointStateCodec(['rw1', 'rw22', 'w']).encode(12.000000005, [1.0, 2.0, 3.0],
                                                               [4.0, 5.0, 6.0])
    assert bytes(ref) == mine
    hdr.frame_id = 'body'
    vec = store.serialize_cdr(t['geometry_msgs/msg/Vector3Stamped'](
        header=hdr, vector=t['geometry_msgs/msg/Vector3'](x=1.0, y=2.0, z=3.0)),
        'geometry_msgs/msg/Vector3Stamped')
    assert bytes(vec) == codecs.vector3_codec().encode(12.000000005, [1.0, 2.0, 3.0])
    quat = store.serialize_cdr(t['geometry_msgs/msg/QuaternionStamped'](
        header=hdr, quaternion=t['geometry_msgs/msg/Quaternion'](x=0.5, y=0.5, z=0.5, w=0.5)),
        'geometry_msgs/msg/QuaternionStamped')
    assert bytes(quat) == codecs.quaternion_codec().encode(12.000000005, [0.5] * 4)
    unknown = np.zeros(9)
    unknown[0] = -1.0
    vec3 = t['geometry_msgs/msg/Vector3']
    imu = store.serialize_cdr(t['sensor_msgs/msg/Imu'](
        header=hdr, orientation=t['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=unknown, angular_velocity=vec3(x=1.0, y=2.0, z=3.0),
        angular_velocity_covariance=np.zeros(9), linear_acceleration=vec3(x=0.0, y=0.0, z=0.0),
        linear_acceleration_covariance=unknown), 'sensor_msgs/msg/Imu')
    assert bytes(imu) == codecs.imu_codec().encode(12.000000005, [1.0, 2.0, 3.0])
    hdr.frame_id = ''
    columns = store.serialize_cdr(t['sensor_msgs/msg/JointState'](
        header=hdr, name=['truth_a', 'b'], position=np.array([1.0, 2.0]), velocity=np.zeros(0),
        effort=np.zeros(0)), 'sensor_msgs/msg/JointState')
    assert bytes(columns) == codecs.encode_columns(12.000000005, ['truth_a', 'b'], [1.0, 2.0])


def _write_bag(path, topics, storage=StoragePlugin.MCAP, raw=None):
    """Write a recording with rosbags directly: topic -> (type, [(stamp_ns, msg), ...])."""
    store = rosbag_io.typestore()
    with Writer(path, version=9, storage_plugin=storage) as writer:
        for topic, (msgtype, items) in topics.items():
            conn = writer.add_connection(topic, msgtype, typestore=store)
            for stamp, msg in items:
                data = msg if isinstance(msg, bytes) else store.serialize_cdr(msg, msgtype)
                writer.write(conn, stamp, data)


def _header(ns, frame='body'):
    t = rosbag_io.typestore().types
    return t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
        sec=ns // 10**9, nanosec=ns % 10**9), frame_id=frame)


def _multi_rate(path, storage=StoragePlugin.MCAP, seconds=60.0):
    """Wheels at 10 Hz, gyro at 4 Hz, star tracker at 4 Hz 10 ms later, other topic names."""
    t = rosbag_io.typestore().types
    rng = np.random.default_rng(1)
    wheel_ns = [int(k * 1e8) for k in range(int(seconds * 10))]
    gyro_ns = [int(k * 2.5e8) for k in range(int(seconds * 4))]
    star_ns = [s + 10_000_000 for s in gyro_ns]
    wheels = [(s, t['sensor_msgs/msg/JointState'](
        header=_header(s, ''), name=['rw1', 'rw2'], position=np.zeros(0),
        velocity=rng.normal(size=2), effort=1e-3 + 1e-5 * rng.normal(size=2)))
        for s in wheel_ns]
    unknown = np.zeros(9)
    unknown[0] = -1.0
    vec = t['geometry_msgs/msg/Vector3']
    gyro = [(s, t['sensor_msgs/msg/Imu'](
        header=_header(s), orientation=t['geometry_msgs/msg/Quaternion'](
            x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=unknown,
        angular_velocity=vec(*rng.normal(scale=1e-3, size=3)),
        angular_velocity_covariance=np.zeros(9), linear_acceleration=vec(x=0.0, y=0.0, z=0.0),
        linear_acceleration_covariance=unknown)) for s in gyro_ns]
    star = [(s, t['geometry_msgs/msg/QuaternionStamped'](
        header=_header(s), quaternion=t['geometry_msgs/msg/Quaternion'](
            x=0.0, y=0.0, z=0.0, w=1.0))) for s in star_ns]
    _write_bag(path, {'/sc/rw/state': ('sensor_msgs/msg/JointState', wheels),
                      '/sc/imu': ('sensor_msgs/msg/Imu', gyro),
                      '/sc/st/q': ('geometry_msgs/msg/QuaternionStamped', star)}, storage)
    return wheel_ns, gyro_ns, star_ns


TOPICS = 'wheels=/sc/rw/state,gyro=/sc/imu,star_tracker=/sc/st/q'


@pytest.mark.parametrize('storage', [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_multi_rate_recording_with_other_topic_names(tmp_path, storage):
    path = tmp_path / 'rec'
    wheel_ns, gyro_ns, star_ns = _multi_rate(path, storage, seconds=10.0)
    with pytest.raises(TelemetrySchemaError, match='no telemetry topic.*--topics'):
        read_telemetry(path)
    tele = read_telemetry(path, TOPICS)
    assert len(tele) == len(set(wheel_ns) | set(gyro_ns) | set(star_ns))
    for stream, stamps in (('wheels', wheel_ns), ('gyro', gyro_ns),
                           ('star_tracker', star_ns)):
        np.testing.assert_allclose(tele.time[tele.rows(stream)], np.array(stamps) / 1e9,
                                   atol=1e-12)
    only = tele.only('wheels')
    assert len(only) == len(wheel_ns) and np.all(np.isfinite(only.wheels['rw1'].friction))
    assert np.isnan(tele.gyro[~tele.present['gyro']]).all()


def test_multi_rate_pipelines_use_each_stream_at_its_own_rate(tmp_path):
    from rwa_monitor.core.gyro_runner import pair_rows
    from rwa_monitor.pipelines import llr, vsadc
    from rwa_monitor.pipelines.runners import gyro_columns
    path = tmp_path / 'rec'
    wheel_ns, gyro_ns, _ = _multi_rate(path, seconds=60.0)
    tele = read_telemetry(path, TOPICS)
    _, summary = llr.run_with_summary(tele, {'window': 50})
    assert summary['rw1']['samples'] == len(wheel_ns)
    assert not any(summary['rw1']['rejected'].values())
    rows, quats, _ = pair_rows(gyro_columns(tele), np.zeros(3), 1e-3)
    assert len(rows) == len(gyro_ns) and all(q is None for q in quats)  # 10 ms apart
    rows, quats, _ = pair_rows(gyro_columns(tele), np.zeros(3), 0.02)
    assert all(q == [0.0, 0.0, 0.0, 1.0] for q in quats)
    _, vs = vsadc.run_with_summary(tele, {'pair_tolerance': 0.02, 'window': 20})
    assert vs['counters']


def test_detect_runs_on_a_multi_rate_recording(tmp_path):
    path = tmp_path / 'rec'
    _multi_rate(path, seconds=60.0)
    out = tmp_path / 'events.json'
    run = subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', 'detect', str(path),
                          '--topics', TOPICS, '-o', str(out)], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode in (0, 1, 3), run.stderr  # detect's result codes, 2 = error
    summary = json.loads(out.read_text())['summary']
    assert 'llr' in json.dumps(summary) and 'vsadc' in json.dumps(summary)


def test_both_encodings_of_empty_sequences_are_read(tmp_path):
    """Read both: rclpy appends padding after trailing empty sequences, canonical CDR not."""
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    store = rosbag_io.typestore()
    names = ['rw1_temperature', 'a', 'b', 'c', 'd', 'e']
    wheels, padded, canonical = [], [], []
    for k in range(5):
        stamp = k * 100_000_000
        msg = JointState(name=names, position=[float(k)] * 6)
        msg.header.stamp = codecs.to_stamp(stamp / 1e9)
        padded.append((stamp, serialize_message(msg)))
        canonical.append((stamp, bytes(store.serialize_cdr(
            _canonical(msg), 'sensor_msgs/msg/JointState'))))
        wheels.append((stamp, codecs.encode_joint_state(stamp / 1e9, ['rw1'], [1.0], [0.5])))
    assert len(padded[0][1]) > len(canonical[0][1])  # the two encodings differ
    with pytest.raises(Exception, match='size mismatch'):  # rosbags alone refuses rclpy's
        store.deserialize_cdr(padded[0][1], 'sensor_msgs/msg/JointState')
    for name, items in (('padded', padded), ('canonical', canonical)):
        path = tmp_path / name
        _write_bag(path, {'/telemetry/wheels': ('sensor_msgs/msg/JointState', wheels),
                          rosbag_io.COLUMNS_TOPIC: ('sensor_msgs/msg/JointState', items)})
        tele = read_telemetry(path)
        np.testing.assert_array_equal(tele.aux['rw1_temperature'], np.arange(5.0))
        np.testing.assert_array_equal(tele.aux['e'], np.arange(5.0))


def _canonical(msg):
    t = rosbag_io.typestore().types
    return t['sensor_msgs/msg/JointState'](
        header=_header(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec, ''),
        name=list(msg.name), position=np.array(msg.position), velocity=np.zeros(0),
        effort=np.zeros(0))


def test_bad_recordings_name_the_file(tmp_path):
    with pytest.raises(TelemetrySchemaError, match='missing.mcap.*no such'):
        read_telemetry(tmp_path / 'missing.mcap')
    for name in ('junk.mcap', 'junk.db3'):
        junk = tmp_path / name
        junk.write_bytes(b'not a recording at all\x00\xff' * 10)
        with pytest.raises(TelemetrySchemaError, match=f'{name}.*not a readable rosbag2'):
            read_telemetry(junk)
    folder = tmp_path / 'folder'
    folder.mkdir()
    with pytest.raises(TelemetrySchemaError, match='without metadata.yaml'):
        read_telemetry(folder)
    wrong = tmp_path / 'wrong'
    _multi_rate(wrong, seconds=1.0)
    with pytest.raises(TelemetrySchemaError, match='/sc/imu is sensor_msgs/msg/Imu'):
        read_telemetry(wrong, 'wheels=/sc/imu')
    with pytest.raises(ConfigError, match="unknown stream 'wheel'"):
        read_telemetry(wrong, 'wheel=/sc/imu')


@pytest.mark.parametrize('content', [
    b'\xef\xbb\xbftime,rw1_speed,rw1_friction\r\n0.0,1.0,0.5\r\n0.1,2.0,0.25\r\n',
    b'time,rw1_speed,rw1_friction\r\n0.0,1.0,0.5\r\n0.1,2.0,\r\n'])
def test_csv_with_byte_order_mark_and_crlf(tmp_path, content):
    path = tmp_path / 'bom.csv'
    path.write_bytes(content)
    tele = read_telemetry(path)
    np.testing.assert_array_equal(tele.time, [0.0, 0.1])
    np.testing.assert_array_equal(tele.wheels['rw1'].speed, [1.0, 2.0])


def test_undecodable_files_give_one_line_naming_the_file(tmp_path):
    db3 = tmp_path / 'rec.db3'
    write_telemetry(db3, _telemetry(n=5))
    disguised = tmp_path / 'rec.csv'
    disguised.write_bytes(db3.read_bytes())
    latin = tmp_path / 'latin.csv'
    latin.write_bytes(b'time,rw1_speed,rw1_friction\n0.0,1.0,0.5 \xb0C\n')
    for path in (disguised, latin):
        run = subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', 'detect',
                              str(path)], capture_output=True, text=True, timeout=60,
                             env={**os.environ, 'PYTHONWARNINGS': 'ignore'})
        assert run.returncode != 0
        lines = run.stderr.strip().splitlines()
        assert len(lines) == 1 and str(path) in lines[0] and 'not a CSV text file' in lines[0]


@pytest.mark.slow
@pytest.mark.parametrize('name', ['interrupted_bag', 'interrupted.mcap', 'interrupted.csv'])
def test_an_interrupted_simulate_leaves_no_half_written_output(tmp_path, name):
    """SIGINT while the output is being written: no output and no temporary are left.

    On a loaded machine the signal can arrive after the last byte, when the output is
    switched in whole: then the run ends 0 with the complete output and no temporary
    (the other outcome the atomic write allows); 6 hours of data make that window rare.
    """
    import signal
    import time
    command = [sys.executable, '-m', 'rwa_monitor.cli.main', 'simulate', 'friction',
               '--hours', '6', '--seed', '2', '-o', str(tmp_path / name)]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    end = time.monotonic() + 120
    while not any(tmp_path.iterdir()) and proc.poll() is None and time.monotonic() < end:
        time.sleep(0.005)
    assert proc.poll() is None, 'the run ended before its output was being written'
    temporaries = [p.name for p in tmp_path.iterdir()]
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    assert temporaries and all(t.startswith(f'.{name}.') for t in temporaries)
    if proc.returncode == 0:                       # the signal came after the switch
        assert [p.name for p in tmp_path.iterdir()] == [name]
        from rwa_monitor.telemetry import read_telemetry
        assert len(read_telemetry(tmp_path / name)) == 6 * 3600 * 10
        return
    assert proc.returncode == 130, proc.stderr.read()
    assert list(tmp_path.iterdir()) == []
