"""Launch-free integration tests of the vsadc_detector node (with the replay node)."""

import math

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, RosWorld

from rwa_monitor.core import keys
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS, telemetry_qos
from rwa_monitor.nodes.replay import TelemetryReplay
from rwa_monitor.nodes.vsadc_detector import VsadcDetectorNode
from rwa_monitor.pipelines import vsadc as pipeline
from rwa_monitor.sim.aocs import named_fault, simulate_aocs
from rwa_monitor.telemetry import read_telemetry, write_telemetry

pytestmark = pytest.mark.ros

# Short windows so that a 900 s record holds start-up, a drift and a bias.
CONFIG = {'window': 40, 'sigma_window': 40, 'reference_window': 200}


def _detector(world, **params):
    overrides = [Parameter(k, value=v) for k, v in {**CONFIG, **params}.items()]
    return world.node(VsadcDetectorNode, parameter_overrides=overrides)


def _events(collector):
    return [messages.status_event(s) for m in collector.messages for s in m.status]


def _key(e):
    return (e.component, e.kind, e.index, e.declared_index)


def test_node_events_equal_detect_pipeline(tmp_path):
    tele = simulate_aocs(900.0, fault=named_fault('fast', 'y', 300.0), seed=21)
    path = tmp_path / 'gyro.csv'
    write_telemetry(path, tele)
    tele = read_telemetry(path)
    expected = pipeline.run(tele, {**pipeline.DEFAULTS, **CONFIG})
    assert expected and expected[0].component == 'gyro_y'
    with RosWorld('events') as world:
        detector = _detector(world)
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('rate', value=0.0),
            Parameter('burst', value=20), Parameter('min_subscribers', value=1),
            Parameter('exit_when_done', value=False)])
        world.wait_until(lambda: replay.done and detector.samples == len(tele), 60.0,
                         'every row through the detector')
        world.wait_until(lambda: len(_events(anomalies)) >= len(expected), 10.0, 'events')
        got = _events(anomalies)
        assert detector.counters['reference_from_parameter'] == 0
        assert detector.counters['unpaired_gyro'] == 0
    assert [_key(e) for e in got] == [_key(e) for e in expected]
    assert all(e.detector == 'vsadc' for e in got)


# Fields that cross a message boundary as a ROS time stamp (sec, nanosec): the node's
# times are the stamps of the replayed messages, detect's the file's floats, so they agree
# to the stamp's resolution (1 ns, plus the rounding of sec + nanosec / 1e9).
STAMP_FIELDS = (keys.CHANGE_TIME, keys.DECLARATION_TIME)
STAMP_RESOLUTION = 1.0e-9


def _comparable(value):
    # NaN stands for "none" (p_value, a sigma not yet known): equal to itself here, and
    # kept apart from inf, which the JSON form would also write as null.
    return 'nan' if isinstance(value, float) and math.isnan(value) else value


def assert_same_fields(got, expected):
    """Assert the events agree field for field.

    ``fields()`` is what both forms write: the node's KeyValues and, renamed with
    non-finite floats as null, detect's ``to_json``; comparing it is the stricter test.
    """
    assert len(got) == len(expected)
    for mine, theirs in zip(got, expected):
        mine, theirs = mine.fields(), theirs.fields()
        for name in STAMP_FIELDS:
            assert mine.pop(name) == pytest.approx(theirs.pop(name), abs=STAMP_RESOLUTION)
        # Every other field exactly (the KeyValues carry floats as repr).
        assert {k: _comparable(v) for k, v in mine.items()} == \
            {k: _comparable(v) for k, v in theirs.items()}


def test_node_events_equal_detect_field_for_field(tmp_path):
    tele = simulate_aocs(600.0, fault=named_fault('fast', 'x', 200.0), seed=3900)
    path = tmp_path / 'gyro.csv'
    write_telemetry(path, tele)
    tele = read_telemetry(path)
    expected = pipeline.run(tele, {**pipeline.DEFAULTS, **CONFIG})
    assert [(e.component, e.kind) for e in expected] == [('gyro_x', 'drift'),
                                                         ('gyro_x', 'bias')]
    with RosWorld('events') as world:
        detector = _detector(world)
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('rate', value=0.0),
            Parameter('burst', value=20), Parameter('min_subscribers', value=1),
            Parameter('exit_when_done', value=False)])
        world.wait_until(lambda: replay.done and detector.samples == len(tele), 60.0,
                         'every row through the detector')
        world.wait_until(lambda: len(_events(anomalies)) >= len(expected), 10.0, 'events')
        world.spin_for(0.2)     # nothing more may follow
        got = _events(anomalies)
    assert_same_fields(got, expected)


def _publish_rows(world, pubs, tele, rows, with_star=True):
    gyro_pub, star_pub = pubs
    for k in rows:
        t = float(tele.time[k])
        if with_star:
            star_pub.publish(messages.quaternion(t, tele.attitude[k]))
        gyro_pub.publish(messages.imu(t, tele.gyro[k]))
        world.spin_once(0.0)


def test_star_tracker_that_stops_makes_the_axes_stale_not_drift():
    # Healthy data; after 300 rows the star tracker goes silent while the gyro goes on:
    # the gyro samples wait (max_lag), then are held; no event; the axes turn STALE after
    # stale_timeout of steady time while the input itself is still alive.
    tele = simulate_aocs(200.0, seed=22)
    with RosWorld() as world:
        detector, pubs, diags, events = _node_with_publishers(world, stale_timeout=0.5,
                                                              max_lag=5)
        _publish_rows(world, pubs, tele, range(300))
        world.wait_until(lambda: detector.samples >= 300, 10.0, '300 paired samples')
        _publish_rows(world, pubs, tele, range(300, 400), with_star=False)
        world.wait_until(lambda: detector.samples >= 395, 10.0, 'gyro fed without q')

        def stale_axis():
            for msg in diags.messages[-3:]:
                for s in msg.status:
                    if s.hardware_id == 'gyro_x' and s.level == DiagnosticStatus.STALE:
                        return True
            return False
        world.wait_until(stale_axis, 10.0, 'gyro_x STALE')
        assert detector.counters['unpaired_gyro'] >= 95
        assert detector.detector.states == {'x': 0, 'y': 0, 'z': 0}
        world.spin_for(0.2)
        assert _events(events) == []


def test_reference_parameter_used_when_the_topic_is_silent_and_bad_values_rejected():
    with RosWorld() as world:
        detector = _detector(world, feature='paper', reference_rate=[0.0, 0.0, 1.0e-3])
        assert detector.reference == [0.0, 0.0, 1.0e-3]
        detector.on_gyro(messages.imu(1.0, [0.0, 0.0, 1.0e-3]))
        detector.on_star_tracker(messages.quaternion(1.0, [0.0, 0.0, 0.0, 1.0]))
        assert detector.samples == 1 and detector.counters['reference_from_parameter'] == 1
        result = detector.set_parameters([Parameter('window', value=1)])[0]
        assert not result.successful and 'window' in result.reason
        result = detector.set_parameters([Parameter('reference_rate', value=[1.0, 2.0])])[0]
        assert not result.successful and 'reference_rate' in result.reason
        assert detector.set_parameters([Parameter('margin', value=2.0)])[0].successful
        assert detector.detector.channels[0].margin == 2.0
    with RosWorld() as world:
        with pytest.raises(ConfigError, match='distance_threshold'):
            _detector(world, distance_threshold=-1.0)


def test_replay_loop_restarts_the_detector():
    with RosWorld() as world:
        detector = _detector(world)
        for t in (10.0, 10.25, 10.5, 2.0):
            detector.on_gyro(messages.imu(t, [0.0, 0.0, 0.0]))
            detector.on_star_tracker(messages.quaternion(t, [0.0, 0.0, 0.0, 1.0]))
        assert detector.counters['time_jump_reset'] == 1
        assert detector.detector.counters['rows'] == 1


def test_non_increasing_stamps_and_bad_messages_are_counted():
    with RosWorld() as world:
        detector = _detector(world)
        rows = [(1.0, [0, 0, 0, 1.0]), (1.25, [0, 0, 0, 1.0]), (0.75, [0, 0, 0, 1.0]),
                (1.5, [float('nan'), 0, 0, 1.0]), (1.75, [0, 0, 0, 3.0]), (2.0, [0, 0, 0, 1.0])]
        for t, q in rows:
            detector.on_star_tracker(messages.quaternion(t, q))
            detector.on_gyro(messages.imu(t, [0.0, 0.0, 0.0]))
        c = detector.detector.counters
        assert detector.samples == 6
        assert c['non_increasing_time'] == 1 and c['invalid_quaternions'] == 2
        assert c['accepted'] == 2          # 1.25 and 2.0 (the first has no rate yet)
        assert detector.detector.states == {'x': 0, 'y': 0, 'z': 0}


def _gyro_x_levels(diags):
    return [s.level for m in diags.messages for s in m.status if s.hardware_id == 'gyro_x']


def _node_with_publishers(world, **params):
    from geometry_msgs.msg import QuaternionStamped
    from sensor_msgs.msg import Imu
    detector = _detector(world, diagnostic_period=0.1, **params)
    src = world.node(Node, 'source')
    pubs = (src.create_publisher(Imu, 'telemetry/gyro', telemetry_qos()),
            src.create_publisher(QuaternionStamped, 'telemetry/star_tracker',
                                 telemetry_qos()))
    diags = Collector(src, DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
    events = Collector(src, DiagnosticArray, 'anomalies', EVENTS_QOS)
    for pub in pubs:
        world.wait_for_subscribers(pub)
    return detector, pubs, diags, events


def test_star_tracker_blinded_for_minutes_is_stale_then_resumes_without_a_declaration():
    # Sun in the star tracker's field of view: 4 minutes (960 rows at 4 Hz) without a
    # quaternion while the gyro goes on. The residual axes hold (STALE while the pairing
    # waits), then resume on the same nominal: examined again (OK), no event.
    tele = simulate_aocs(900.0, seed=23)
    blind = range(1200, 2160)
    with RosWorld() as world:
        detector, pubs, diags, events = _node_with_publishers(world, stale_timeout=0.5)
        _publish_rows(world, pubs, tele, range(1200))
        world.wait_until(lambda: detector.samples >= 1200, 20.0, '1200 paired samples')
        assert all(ch.ready for ch in detector.detector.channels)
        used = detector.detector.channels[0].samples
        _publish_rows(world, pubs, tele, blind, with_star=False)
        world.wait_until(lambda: detector.samples >= blind.stop - 41, 20.0, 'gyro fed without q')
        world.wait_until(lambda: DiagnosticStatus.STALE in _gyro_x_levels(diags)[-3:],
                         10.0, 'gyro_x STALE while blinded')
        assert detector.detector.channels[0].samples - used <= 5    # nothing diagnosed
        blinded_reports = len(_gyro_x_levels(diags))
        _publish_rows(world, pubs, tele, range(2160, len(tele)))
        world.wait_until(lambda: detector.samples >= len(tele) - 5, 20.0, 'every row')
        world.wait_until(lambda: DiagnosticStatus.OK in _gyro_x_levels(diags)[blinded_reports:],
                         10.0, 'gyro_x examined again (OK)')
        assert detector.detector.channels[0].samples - used > 1000  # resumed
        assert detector.detector.counters['star_tracker_gaps'] >= 1
        world.spin_for(0.2)
        assert detector.detector.states == {'x': 0, 'y': 0, 'z': 0}
        assert _events(events) == []


def test_saturated_gyro_is_reported_not_diagnosed():
    # The x rate rails at 1 rad/s (above saturation_rad_s) for 50 s of a healthy record:
    # the axis reports WARN "saturated", its samples are held, no drift or bias follows.
    tele = simulate_aocs(600.0, seed=24)
    gyro = tele.gyro.copy()
    rail = (tele.time > 400.0) & (tele.time < 450.0)
    gyro[rail, 0] = 1.0
    tele = type(tele)(time=tele.time, gyro=gyro, attitude=tele.attitude,
                      reference_rate=tele.reference_rate, truth=tele.truth)
    with RosWorld() as world:
        detector, pubs, diags, events = _node_with_publishers(world, stale_timeout=5.0)
        first = int(rail.argmax())
        _publish_rows(world, pubs, tele, range(first + 100))
        world.wait_until(lambda: detector.samples >= first + 100, 20.0, 'rows into the rail')

        def saturated_warning():
            return any(s.hardware_id == 'gyro_x' and s.level == DiagnosticStatus.WARN
                       and 'saturated' in s.message
                       for m in diags.messages[-3:] for s in m.status)
        world.wait_until(saturated_warning, 10.0, 'gyro_x WARN saturated')
        _publish_rows(world, pubs, tele, range(first + 100, len(tele)))
        world.wait_until(lambda: detector.samples >= len(tele), 20.0, 'every row')
        world.spin_for(0.3)
        assert detector.detector.counters['saturated_x'] >= 190
        assert detector.detector.states == {'x': 0, 'y': 0, 'z': 0}
        assert not saturated_warning()              # reported while it lasts only
        assert _events(events) == []
