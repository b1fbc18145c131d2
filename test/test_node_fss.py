"""The fss_diagnoser node in process: windows, worker thread, events, health, bad input."""

import json
import threading

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, RosWorld
from sensor_msgs.msg import JointState

from rwa_monitor.cli.main import main
from rwa_monitor.core.fss.pipeline import diagnose, FssConfig
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import fss_diagnoser, messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS
from rwa_monitor.nodes.fss_diagnoser import FssDiagnoserNode
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
from rwa_monitor.sim.fss import simulate_fss
from rwa_monitor.telemetry import read_telemetry, write_telemetry
from rwa_monitor.telemetry.fss_model import load_model

pytestmark = pytest.mark.ros

LENGTH, PERIOD = 20_000, 10_000


def _node(world, **params):
    values = {'window_length': LENGTH, 'window_period': PERIOD, 'diagnostic_period': 0.2,
              **params}
    return world.node(FssDiagnoserNode, parameter_overrides=[
        Parameter(k, value=v) for k, v in values.items()])


def _feed(node, tele, rows):
    names = list(tele.wheels)
    for k in rows:
        node.on_wheels(messages.joint_state(
            float(tele.time[k]), names, [float(tele.wheels[w].speed[k]) for w in names],
            [float(tele.wheels[w].friction[k]) for w in names]))


@pytest.fixture(scope='module')
def tele():
    return simulate_fss(statuses=('nominal', 'dry'), n_samples=LENGTH + PERIOD, seed=21)


def test_events_equal_the_pipeline_on_the_same_window(tele):
    model = load_model()
    expected = {}
    for wheel_id, wheel in tele.wheels.items():
        out = diagnose(wheel.speed[:LENGTH], wheel.friction[:LENGTH], tele.time[:LENGTH],
                       model, FssConfig())
        expected[wheel_id] = {k for k, v in out['anomalies'].items() if v}
    assert 'dry' in expected['rw2'], 'the seeded dry wheel must be flagged'
    with RosWorld() as world:
        node = _node(world)
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        health = Collector(sink, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        _feed(node, tele, range(LENGTH))
        world.wait_until(lambda: all(w.diagnoses == 1 for w in node.wheels.values()), 60.0,
                         'one diagnosis per wheel')
        world.wait_until(lambda: sum(len(m.status) for m in anomalies.messages)
                         >= sum(map(len, expected.values())), 10.0, 'the events')

        def rw2_levels():
            return [s.level for m in health.messages for s in m.status
                    if s.hardware_id == 'rw2']
        world.wait_until(lambda: DiagnosticStatus.WARN in rw2_levels(), 10.0, 'rw2 WARN')
    events = [messages.status_event(s) for m in anomalies.messages for s in m.status]
    got = {w: {e.kind for e in events if e.component == w} for w in tele.wheels}
    assert got == expected
    for event in events:
        assert event.detector == 'fss'
        assert event.time == pytest.approx(tele.time[0])
        assert event.declared_time == pytest.approx(tele.time[LENGTH - 1])
        assert event.index == 0 and event.declared_index == LENGTH - 1


# A window long enough to hold an onset (docs/fss.md "Onsets": the level after the step
# outlasts Example 2's longest residence, 30,000 samples), the demo's step sizes.
ONSET_WINDOW = 40_000
STEPS = {'rw2': ('dry', 5_000), 'rw3': ('viscous', 8_000)}   # wheel: kind, first sample


@pytest.fixture(scope='module')
def stepped_file(tmp_path_factory):
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2', 'rw3'], n_samples=ONSET_WINDOW, rate_hz=10.0, seed=3420,
        anomalies=[Anomaly('rw2', 'dry', 500.0, delta_dry=2.0e-4),
                   Anomaly('rw3', 'viscous', 800.0, delta_viscous=1.0e-6)])
    path = tmp_path_factory.mktemp('steps') / 'steps.csv'
    write_telemetry(path, tele)
    return path


def test_events_equal_diagnose_with_the_onset_as_change_time(stepped_file, tmp_path,
                                                             repo_root):
    # The same file through `rwa-monitor diagnose` and through the node (its one window):
    # the events are equal field for field; the change is dated at the step's onset,
    # not at the window's first sample.
    params = repo_root / 'config' / 'rwa_monitor.yaml'
    out = tmp_path / 'diagnosis.json'
    assert main(['diagnose', str(stepped_file), '--params-file', str(params),
                 '-o', str(out)]) == 0
    expected = sorted(json.loads(out.read_text())['events'],
                      key=lambda e: (e['component'], e['kind']))
    tele = read_telemetry(stepped_file)
    assert {e['component']: e['kind'] for e in expected} == \
        {w: kind for w, (kind, _) in STEPS.items()}
    for event in expected:
        start = STEPS[event['component']][1]
        assert abs(event['index'] - start) <= 20   # the wGLR half-window
        assert event['time'] == tele.time[event['index']] > tele.time[0]
    with RosWorld() as world:
        node = world.node(FssDiagnoserNode, cli_args=['--ros-args', '--params-file',
                                                      str(params)],
                          parameter_overrides=[Parameter('window_length', value=ONSET_WINDOW)])
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        _feed(node, tele, range(ONSET_WINDOW))
        world.wait_until(lambda: all(w.diagnoses == 1 for w in node.wheels.values()), 60.0,
                         'one diagnosis per wheel')
        world.wait_until(lambda: sum(len(m.status) for m in anomalies.messages)
                         >= len(expected), 10.0, 'the events')
    got = sorted((messages.status_event(s).to_json() for m in anomalies.messages
                  for s in m.status), key=lambda e: (e['component'], e['kind']))
    assert got == expected


def test_callbacks_never_wait_for_the_worker(tele, monkeypatch):
    release = threading.Event()
    calls = []

    def slow(*args, **kwargs):
        calls.append(args[2][0])
        release.wait(30.0)
        return {'anomalies': {'dry': False, 'viscous': False, 'fss1': False, 'fss2': False},
                'estimates': {'base_dry_nm': 0.0, 'viscous_nms': 0.0, 'noise_std_nm': 0.0},
                'changepoints': []}
    monkeypatch.setattr(fss_diagnoser, 'diagnose', slow)
    with RosWorld() as world:
        node = _node(world, window_period=2000)
        _feed(node, tele, range(LENGTH + 4000))
        # Every sample was appended while the first diagnosis was still blocked.
        assert all(w.samples == LENGTH + 4000 for w in node.wheels.values())
        assert all(w.skipped_busy == 2 for w in node.wheels.values())
        # One worker thread: the first wheel's diagnosis runs, the second one waits.
        assert len(calls) == 1 and all(w.window.size == LENGTH for w in node.wheels.values())
        release.set()
        world.wait_until(lambda: all(w.diagnoses == 1 for w in node.wheels.values()), 30.0,
                         'the released diagnoses')


def test_bad_input_is_counted(tele):
    with RosWorld() as world:
        node = _node(world, wheels='rw1,rw2')
        node.on_wheels(JointState(name=['rw1', 'rw2'], velocity=[1.0], effort=[0.0, 0.0]))
        node.on_wheels(messages.joint_state(5.0, ['rw1', 'rw3', ''], [1.0, 1.0, 1.0],
                                            [0.0, 0.0, 0.0]))
        node.on_wheels(messages.joint_state(4.0, ['rw1'], [1.0], [0.0]))
        node.on_wheels(messages.joint_state(6.0, ['rw1'], [float('nan')], [0.0]))
        counters = node.input_counters
        assert counters['length_mismatch'] == 1
        assert counters['unknown_wheel'] == 1 and counters['empty_name'] == 1
        assert counters['non_increasing_time'] == 1
        rw1 = node.wheels['rw1']
        assert rw1.samples == 2 and rw1.window.non_finite == 1
        level, message, values = node._wheel_health(rw1)   # filling its first window
        assert values['waiting_samples'] == rw1.window.length - 2
        assert 'waiting for a full window' in message


def test_parameters(repo_root):
    with RosWorld() as world:
        with pytest.raises(ConfigError, match='window_length'):
            _node(world, window_length=10)
        with pytest.raises(ConfigError, match='model'):
            _node(world, model='/nonexistent/model.json')
        node = world.node(FssDiagnoserNode, cli_args=[
            '--ros-args', '--params-file', str(repo_root / 'config' / 'rwa_monitor.yaml')])
        assert node.params['window_length'] == 80_000 and node._config.wglr_window == 20
        result = node.set_parameters([Parameter('beam', value=0)])[0]
        assert not result.successful and 'beam' in result.reason
        assert node.set_parameters([Parameter('beam', value=64)])[0].successful
        assert node._config.beam == 64


def test_memory_is_bounded_by_the_window():
    with RosWorld() as world:
        node = _node(world, window_length=500, window_period=10_000)
        rng = np.random.default_rng(0)
        for k in range(3000):
            node.on_wheels(messages.joint_state(k * 0.1, ['rw1'], [300.0],
                                                [float(rng.normal())]))
        window = node.wheels['rw1'].window
        assert window.size == 500 and window.snapshot()[0][0] == pytest.approx(250.0)


def test_raw_bytes_fill_the_windows_as_the_messages_do(tele):
    from rclpy.serialization import serialize_message
    names = list(tele.wheels)
    rows = range(300)
    with RosWorld() as world:
        by_message, by_bytes = _node(world), _node(world)
        by_bytes.on_raw_wheels(b'\x00\x01\x00\x00not a joint state')
        for k in rows:
            msg = messages.joint_state(
                float(tele.time[k]), names, [float(tele.wheels[w].speed[k]) for w in names],
                [float(tele.wheels[w].friction[k]) for w in names])
            by_message.on_wheels(msg)
            raw = serialize_message(msg) if k % 2 else messages.encode_joint_state(
                msg.header.stamp.sec + msg.header.stamp.nanosec / 1e9, names,
                msg.velocity, msg.effort)
            by_bytes.on_raw_wheels(raw)
        assert by_bytes.input_counters['undecodable'] == 1
        assert by_bytes.input_counters['messages'] == len(rows) + 1
        for wheel_id in names:
            for a, b in zip(by_message.wheels[wheel_id].window.snapshot(),
                            by_bytes.wheels[wheel_id].window.snapshot()):
                np.testing.assert_array_equal(a, b)
