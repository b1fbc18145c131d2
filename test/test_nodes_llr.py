"""Launch-free integration tests of the llr_detector node (with the replay node)."""

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, RosWorld
from sensor_msgs.msg import JointState
from test_node_vsadc import assert_same_fields

from rwa_monitor.core import keys
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS, telemetry_qos
from rwa_monitor.nodes.llr_detector import LLRDetectorNode
from rwa_monitor.nodes.replay import TelemetryReplay
from rwa_monitor.pipelines import llr
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
from rwa_monitor.telemetry import read_telemetry, write_telemetry

pytestmark = pytest.mark.ros

CONFIG = {'window': 200, 'k_verif': 'auto', 'false_alarm_rate': 1.0e-5,
          'noise_std': 'auto'}


def _seeded(tmp_path, n=3000):
    """Two wheels at 10 Hz, a dry step on rw2 at 150 s; return (file, telemetry)."""
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=n, rate_hz=10.0, seed=11,
        anomalies=[Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    path = tmp_path / 'seeded.csv'
    write_telemetry(path, tele)
    return path, read_telemetry(path)


def _detector(world, **params):
    overrides = [Parameter('use_sim_time', value=True)]
    overrides += [Parameter(k, value=v) for k, v in {**CONFIG, **params}.items()]
    return world.node(LLRDetectorNode, parameter_overrides=overrides)


def _replay(world, path, **params):
    values = {'file': str(path), 'rate': 0.0, 'burst': 50, 'exit_when_done': False, **params}
    return world.node(TelemetryReplay, parameter_overrides=[
        Parameter(k, value=v) for k, v in values.items()])


def _events(collector):
    return [messages.status_event(s) for m in collector.messages for s in m.status]


def _key(event):
    return (event.component, event.kind, event.index, event.declared_index, event.revision)


def _samples(detector):
    return sum(w.samples for w in detector.wheels.values())


def live(events: list) -> list:
    """Return detect's events without the end-of-record ones (a live node has no end)."""
    return [e for e in events if not e.details.get(keys.FINAL)]


def test_node_events_equal_detect_pipeline(tmp_path):
    path, tele = _seeded(tmp_path)
    expected = live(llr.run(tele, CONFIG))
    assert expected, 'the seeded file must contain a detectable anomaly'
    with RosWorld('events') as world:
        detector = _detector(world)
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        replay = _replay(world, path)
        world.wait_until(lambda: replay.done and _samples(detector) == 2 * len(tele), 60.0,
                         'every sample through the detector')
        world.wait_until(lambda: len(_events(anomalies)) >= len(expected), 10.0, 'events')
        got = _events(anomalies)
    assert [_key(e) for e in got] == [_key(e) for e in expected]
    for mine, theirs in zip(got, expected):
        assert mine.time == pytest.approx(theirs.time, abs=1e-6)
        assert mine.declared_time == pytest.approx(theirs.declared_time, abs=1e-6)
        assert mine.p_value == pytest.approx(theirs.p_value, rel=1e-9, abs=1e-300)
        assert mine.detector == 'llr'


def test_node_events_equal_detect_field_for_field(tmp_path):
    # The node cannot know the end of a record: the replay publishes rows and /clock, and
    # nothing on a topic says "the record ended" (a live stream has no end; a loop starts
    # again). So the node has no finish path and never publishes detect's end-of-record
    # (``final``) categorisations; every event before them must match field for field,
    # and the node's detectors, finished by hand, give detect's final events.
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=3000, rate_hz=10.0, seed=3901,
        anomalies=[Anomaly('rw1', 'viscous', 120.0, delta_viscous=4e-5),
                   Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    path = tmp_path / 'seeded.csv'
    write_telemetry(path, tele)
    tele = read_telemetry(path)
    every = llr.run(tele, CONFIG)
    expected = live(every)
    assert {e.component for e in expected} == {'rw1', 'rw2'}
    assert any(e.revision for e in expected) and len(every) > len(expected)
    with RosWorld('events') as world:
        detector = _detector(world)
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        replay = _replay(world, path)
        world.wait_until(lambda: replay.done and _samples(detector) == 2 * len(tele), 60.0,
                         'every sample through the detector')
        world.wait_until(lambda: len(_events(anomalies)) >= len(expected), 10.0, 'events')
        world.spin_for(0.2)     # nothing more may follow
        got = _events(anomalies)
        # What `rwa-monitor demo` does in-process once the replay is done: the wheels'
        # detectors finish as detect does at the end of the file.
        finals = [e for w in ('rw1', 'rw2') for e in detector.wheels[w].runner.finish()]
    # Per wheel in order (across wheels the order of a row's events is not a contract).
    for wheel in ('rw1', 'rw2'):
        assert_same_fields([e for e in got if e.component == wheel],
                           [e for e in expected if e.component == wheel])
    assert len(got) == len(expected)
    assert_same_fields(finals, [e for e in every if e.details.get(keys.FINAL)])


def _wheel_statuses(collector, wheel):
    return [s for m in collector.messages for s in m.status if s.hardware_id == wheel]


def test_health_transitions_then_stale(tmp_path):
    path, tele = _seeded(tmp_path)
    rw2_events = [e for e in llr.run(tele, CONFIG) if e.component == 'rw2']
    first = rw2_events[0]
    with RosWorld('events') as world:
        detector = _detector(world, stale_timeout=0.5, diagnostic_period=0.5)
        sink = world.node(Node, 'sink')
        diagnostics = Collector(sink, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        replay = _replay(world, path, burst=20)
        world.wait_until(lambda: replay.done and _samples(detector) == 2 * len(tele), 60.0,
                         'the replay to finish')

        def levels():
            return [s.level for s in _wheel_statuses(diagnostics, 'rw2')]

        world.wait_until(lambda: DiagnosticStatus.STALE in levels(), 10.0, 'STALE')
    statuses = _wheel_statuses(diagnostics, 'rw2')
    assert statuses[0].name == 'llr_detector: rw2 friction'
    sequence = [s.level for s in statuses]

    def compact(levels):
        return [lvl for i, lvl in enumerate(levels) if i == 0 or lvl != levels[i - 1]]
    # OK until the first event, then the level of each event in turn, then STALE.
    expected = [DiagnosticStatus.OK, *(messages.event_level(e.kind) for e in rw2_events),
                DiagnosticStatus.STALE]
    # /diagnostics is published on wall time (once per diagnostic_period): a fast replay
    # may declare before the first status, so the leading OK may not be seen.
    assert compact(sequence) in (compact(expected), compact(expected)[1:])
    alarm = messages.event_level(first.kind)
    alarm_values = messages.status_fields(statuses[sequence.index(alarm)])
    assert alarm_values['kind'] == first.kind
    assert alarm_values['change_time_s'] == pytest.approx(first.time, abs=1e-6)
    stale_values = messages.status_fields(statuses[-1])
    assert stale_values['last_level'] in ('WARN', 'ERROR')
    assert stale_values['samples'] == len(tele)
    rw1 = [s.level for s in _wheel_statuses(diagnostics, 'rw1')]
    assert set(rw1) == {DiagnosticStatus.OK, DiagnosticStatus.STALE}


def test_parameters_from_yaml_file(tmp_path, repo_root):
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    use_sim_time: true\n'
                      'llr_detector:\n  ros__parameters:\n    window: 123\n    k_verif: 7\n'
                      '    false_alarm_rate: 1.0e-3\n    noise_std: 2.5e-5\n'
                      '    wheels: "rw1, rw3"\n')
    with RosWorld() as world:
        node = world.node(LLRDetectorNode, cli_args=['--ros-args', '--params-file',
                                                     str(params)])
        assert node.get_parameter('use_sim_time').value is True
        assert node.params['window'] == 123 and node.params['k_verif'] == 7
        assert node.params['false_alarm_rate'] == 1.0e-3
        kwargs = {k: node._values[k] for k in ('window', 'k_verif', 'false_alarm_rate',
                                               'noise_std')}
        assert kwargs == {'window': 123, 'k_verif': 7, 'false_alarm_rate': 1.0e-3,
                          'noise_std': 2.5e-5}
        assert node._allowed == {'rw1', 'rw3'}
        shipped = world.node(LLRDetectorNode, cli_args=[
            '--ros-args', '--params-file', str(repo_root / 'config' / 'rwa_monitor.yaml')])
        assert shipped.params['false_alarm_rate'] > 0


@pytest.mark.parametrize('name,value', [
    ('window', 1), ('k_verif', -1), ('false_alarm_rate', 0.0), ('false_alarm_rate', 1.5),
    ('noise_std', -1.0), ('time_jump', 0.0), ('stale_timeout', 0.0),
    ('diagnostic_period', 0.0), ('max_wheels', 0), ('window', 'big'), ('wheels', 5),
])
def test_bad_start_up_parameter_is_named(name, value):
    with RosWorld() as world:
        with pytest.raises(ConfigError, match=name):
            world.node(LLRDetectorNode, parameter_overrides=[Parameter(name, value=value)])


def test_k_verif_must_stay_below_window():
    with RosWorld() as world:
        with pytest.raises(ConfigError, match='k_verif'):
            world.node(LLRDetectorNode, parameter_overrides=[
                Parameter('window', value=100), Parameter('k_verif', value=100)])


@pytest.mark.parametrize('name,value', [
    ('window', 1), ('k_verif', 10000), ('false_alarm_rate', 2.0), ('noise_std', -1.0),
    ('time_jump', -1.0), ('false_alarm_rate', 'x'),
])
def test_bad_run_time_parameter_is_rejected_with_reason(name, value):
    with RosWorld() as world:
        node = _detector(world)
        before = node.params[name]
        result = node.set_parameters([Parameter(name, value=value)])[0]
        assert not result.successful
        assert name in result.reason
        assert node.params[name] == before


def test_read_only_and_good_run_time_changes():
    with RosWorld() as world:
        node = _detector(world)
        assert not node.set_parameters([Parameter('max_wheels', value=3)])[0].successful
        assert node.set_parameters([Parameter('false_alarm_rate', value=1.0e-3)])[0].successful
        assert node._values['false_alarm_rate'] == 1.0e-3
        assert node.set_parameters([Parameter('wheels', value='rw9')])[0].successful
        assert node._allowed == {'rw9'}


class _Feeder:
    """Publish hand-made JointStates to a detector and wait until it has taken each."""

    def __init__(self, world, detector):
        self.world, self.detector = world, detector
        self.node = world.node(Node, 'feeder')
        self.pub = self.node.create_publisher(JointState, 'telemetry/wheels', telemetry_qos())
        world.wait_for_subscribers(self.pub)

    def send(self, msgs, chunk=50):
        base = self.detector.input_counters['messages']
        for start in range(0, len(msgs), chunk):
            for msg in msgs[start:start + chunk]:
                self.pub.publish(msg)
            sent = base + min(start + chunk, len(msgs))
            self.world.wait_until(lambda: self.detector.input_counters['messages'] >= sent,
                                  20.0, 'the detector to take the messages')


def _clean_messages(tele):
    names = list(tele.wheels)
    return [messages.joint_state(t, names, [tele.wheels[n].speed[i] for n in names],
                                 [tele.wheels[n].friction[i] for n in names])
            for i, t in enumerate(tele.time.tolist())]


def test_bad_messages_are_counted_and_never_poison(tmp_path):
    _, tele = _seeded(tmp_path)
    expected = live(llr.run(tele, CONFIG))
    clean = _clean_messages(tele)
    nan, inf = math.nan, math.inf
    stream, injected = [], {}

    def inject(kind, msg):
        stream.append(msg)
        injected[kind] = injected.get(kind, 0) + 1

    for i, msg in enumerate(clean):
        stream.append(msg)
        t = tele.time[i]
        if i % 300 == 10:
            inject('length_mismatch', messages.joint_state(t + 0.05, ['rw1', 'rw2'], [1.0],
                                                           [0.0, 0.0]))
            inject('empty_name', messages.joint_state(t + 0.05, [''], [1.0], [1.0]))
            inject('duplicate_stamp', messages.joint_state(t, ['rw1', 'rw2'], [9.0, 9.0],
                                                           [9.0, 9.0]))
            inject('out_of_order', messages.joint_state(t - 0.05, ['rw1', 'rw2'],
                                                        [9.0, 9.0], [9.0, 9.0]))
            inject('non_finite', messages.joint_state(t + 0.01, ['rw1', 'rw2'], [nan, 1.0],
                                                      [1.0, inf]))
            inject('unknown_wheel', messages.joint_state(t + 0.02, ['rwX'], [1.0], [1.0]))
            inject('duplicate_name', messages.joint_state(t + 0.03, ['rw1', 'rw1'],
                                                          [nan, 9.0], [nan, 9.0]))
    with RosWorld('events') as world:
        detector = _detector(world, wheels='rw1,rw2')
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        _Feeder(world, detector).send(stream)
        world.wait_until(lambda: len(_events(anomalies)) >= len(expected), 10.0, 'events')
        got = _events(anomalies)
        counters = detector.input_counters
        wheels = detector.wheels
        health = {w: messages.status_fields(detector.diagnostics.status(
            detector.diagnostics.components[w])) for w in ('rw1', 'rw2', 'telemetry/wheels')}
    k = injected['length_mismatch']
    assert counters['messages'] == len(stream)
    assert counters['length_mismatch'] == k and counters['empty_name'] == k
    assert counters['unknown_wheel'] == k and counters['duplicate_name'] == k
    assert set(wheels) == {'rw1', 'rw2'}
    for w in ('rw1', 'rw2'):
        assert wheels[w].counters['duplicate_stamp'] == k
        assert wheels[w].counters['out_of_order'] == k
    # non_finite: one per wheel per injection, plus the NaN rw1 of the duplicate-name message
    assert wheels['rw1'].totals()[0]['non_finite'] == 2 * k
    assert wheels['rw2'].totals()[0]['non_finite'] == k
    assert health['rw1']['rejected_non_finite'] == 2 * k
    assert health['rw2']['out_of_order'] == k
    assert health['telemetry/wheels']['length_mismatch'] == k
    # Never poisoned: the same changes, kinds and declarations as on the clean file.
    assert [(e.component, e.kind, e.revision) for e in got] == \
        [(e.component, e.kind, e.revision) for e in expected]
    for mine, theirs in zip(got, expected):
        assert mine.time == pytest.approx(theirs.time, abs=1e-6)
        assert mine.declared_time == pytest.approx(theirs.declared_time, abs=1e-6)


def test_new_wheel_mid_run_gets_its_own_detector(tmp_path):
    with RosWorld('events') as world:
        detector = _detector(world)
        feeder = _Feeder(world, detector)
        feeder.send([messages.joint_state(1.0 + 0.1 * i, ['rw1'], [5.0], [1e-4])
                     for i in range(10)])
        feeder.send([messages.joint_state(2.0 + 0.1 * i, ['rw1', 'rw5'], [5.0, 3.0],
                                          [1e-4, 2e-4]) for i in range(10)])
        assert set(detector.wheels) == {'rw1', 'rw5'}
        assert detector.wheels['rw5'].samples == 10 and detector.wheels['rw1'].samples == 20
        assert 'rw5' in detector.diagnostics.components


def test_too_many_wheels_are_counted():
    with RosWorld('events') as world:
        detector = _detector(world)
        detector.params._values['max_wheels'] = 2
        names = ['a', 'b', 'c', 'd']
        _Feeder(world, detector).send([messages.joint_state(1.0 + i, names, [1.0] * 4,
                                                            [0.0] * 4) for i in range(3)])
        assert set(detector.wheels) == {'a', 'b'}
        assert detector.input_counters['too_many_wheels'] == 6


def test_replay_loop_time_jump_restarts_detector(tmp_path):
    path, tele = _seeded(tmp_path)
    expected = live(llr.run(tele, CONFIG))
    with RosWorld('events') as world:
        detector = _detector(world)
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        replay = _replay(world, path, loop=True)
        world.wait_until(lambda: _samples(detector) >= 2 * 2 * len(tele), 90.0, 'two passes')
        replay.params._values['loop'] = False
        world.wait_until(lambda: len(_events(anomalies)) >= 2 * len(expected), 10.0,
                         'the events of both passes')
        got = _events(anomalies)
        resets = {w: detector.wheels[w].counters['time_jump_reset'] for w in detector.wheels}
    assert replay.loops >= 1
    assert all(count >= 1 for count in resets.values())
    per_pass = [_key(e) for e in expected]
    assert [_key(e) for e in got[:2 * len(expected)]] == per_pass + per_pass


def test_undecodable_bytes_are_counted_not_fatal():
    with RosWorld('events') as world:
        detector = _detector(world)
        feeder = _Feeder(world, detector)
        feeder.pub.publish(b'\x00\x01\x00\x00\xff\xff\xff\x7f')
        world.wait_until(lambda: detector.input_counters['undecodable'] == 1, 10.0,
                         'the undecodable message to be counted')
        feeder.send([messages.joint_state(1.0 + 0.1 * i, ['rw1'], [5.0], [1e-4])
                     for i in range(5)])
        assert detector.wheels['rw1'].samples == 5


def test_best_effort_option_hears_a_sensor_data_publisher():
    from rclpy.qos import qos_profile_sensor_data
    with RosWorld('events') as world:
        detector = _detector(world, telemetry_reliability='best_effort')
        source = world.node(Node, 'sensor_bus')
        pub = source.create_publisher(JointState, 'telemetry/wheels', qos_profile_sensor_data)
        world.wait_for_subscribers(pub)
        pub.publish(messages.joint_state(1.0, ['rw1'], [5.0], [1e-4]))
        world.wait_until(lambda: 'rw1' in detector.wheels, 10.0, 'the best-effort sample')
        assert detector.describe_parameter('telemetry_reliability').read_only
