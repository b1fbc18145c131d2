"""Our recordings opened by readers the project did not write: rosbags and @mcap/core."""

import json
import pathlib
import shutil
import subprocess

import pytest
from test_recordings import _all_messages, _telemetry

from rwa_monitor.telemetry import rosbag_io, write_telemetry

INTEROP = pathlib.Path(__file__).parent / 'interop'
NODE = shutil.which('node')


def _mcap_core(path):
    """Return topic -> {schema, encoding, count} as the TypeScript reader lists them."""
    if NODE is None:
        pytest.skip('node is not installed: the @mcap/core reader cannot run')
    if not (INTEROP / 'node_modules' / '@mcap' / 'core').is_dir():
        pytest.skip('@mcap/core is not installed: `make interop` (npm ci in test/interop)')
    run = subprocess.run([NODE, str(INTEROP / 'list_channels.mjs'), str(path)],
                         capture_output=True, text=True, timeout=60, check=True)
    return json.loads(run.stdout)


def _our_files(tmp_path):
    tele = _telemetry(n=30)
    write_telemetry(tmp_path / 'bag', tele)
    write_telemetry(tmp_path / 'bare.mcap', tele)
    recorder = rosbag_io.RecordingWriter(tmp_path / 'review')
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rclpy.serialization import serialize_message
    for k in range(4):
        msg = DiagnosticArray(status=[DiagnosticStatus(name='rw1', message=f'ok {k}')])
        recorder.write('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray', k,
                       serialize_message(msg))
    recorder.close()
    return {'bag': (tmp_path / 'bag', tmp_path / 'bag' / 'bag.mcap'),
            'bare': (tmp_path / 'bare.mcap', tmp_path / 'bare.mcap'),
            'review': (tmp_path / 'review', tmp_path / 'review' / 'review.mcap')}


def test_mcap_core_lists_the_channels_and_counts_rosbags_reads(tmp_path):
    files = _our_files(tmp_path)
    expected_types = {**{t: rosbag_io.MSG_TYPES[s] for s, t in rosbag_io.DEFAULT_TOPICS.items()},
                      rosbag_io.COLUMNS_TOPIC: 'sensor_msgs/msg/JointState',
                      '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray'}
    for name, (recording, mcap_file) in files.items():
        counts = _all_messages(recording)  # rosbags deserialises every message
        listed = _mcap_core(mcap_file)
        assert {t: c['count'] for t, c in listed.items()} == counts, name
        for topic, channel in listed.items():
            assert channel['schema'] == expected_types[topic]
            assert channel['encoding'] == 'cdr'
    assert _all_messages(files['review'][0]) == {'/diagnostics': 4}
    assert _all_messages(files['bag'][0])['/telemetry/gyro'] == 30
