"""The main job (`rwa-monitor demo`) and the dashboard, in-process."""

import argparse
import io

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import pytest
from rclpy.node import Node
from ros_harness import DomainLease, RosWorld

from rwa_monitor.cli import cmd_dashboard, cmd_demo
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import DIAGNOSTICS_QOS, EVENTS_QOS

pytestmark = pytest.mark.ros


@pytest.mark.slow
def test_demo_finds_both_injected_anomalies(tmp_path):
    path = cmd_demo.demo_file(tmp_path, hours=0.5, seed=cmd_demo.DEFAULT_SEED)
    assert cmd_demo.demo_file(tmp_path, hours=0.5) == path  # cached, not regenerated
    out = io.StringIO()
    lease = DomainLease()
    try:
        result = cmd_demo.run_demo(path, domain_id=lease.domain_id, out=out, live=True)
    finally:
        lease.release()
    assert [(c.wheel, c.kind) for c in result.changes] == [('rw2', 'dry'), ('rw3', 'viscous')]
    assert all(hit is not None for _, hit in result.matches)
    assert result.false_alarms == []
    assert [(e.component, e.kind, e.index) for e in result.events] == \
        [(e.component, e.kind, e.index) for e in result.pipeline_events]
    text = out.getvalue()
    assert 'rwa_monitor demo' in text and '100.0%' in text and 'rw2' in text
    report = cmd_demo.summary(result)
    assert 'identical to `rwa-monitor detect` on the file: yes' in report
    assert 'MISSED' not in report
    # The demo's own count (seed 7, half an hour: rw3's viscous step has 10 minutes after
    # it, its final kind on those is undecided; rw2 is named dry): no wrong kind.
    counts = cmd_demo.kind_counts(result)['llr']
    assert counts['wrong'] == 0 and counts['right'] >= 1
    assert 'kinds against the truth: llr right' in report


def test_summary_counts_right_and_wrong_kinds():
    # The demo judges its own answer: kinds after the revisions against the truth (LLR)
    # and the window diagnoser's flags against the injected (wheel, kind) pairs.
    from rwa_monitor.sim.friction import Change
    changes = [Change('rw2', 'dry', 100, 10.0, 2e-4, 0.0),
               Change('rw3', 'viscous', 200, 20.0, 0.0, 1e-6),
               Change('rw4', 'dry', 300, 30.0, 2e-4, 0.0)]

    def event(wheel, kind, index, revision=0):
        return AnomalyEvent(detector='llr', component=wheel, kind=kind, time=index / 10,
                            index=index, declared_time=index / 10 + 5,
                            declared_index=index + 50, revision=revision)
    first2, first3 = event('rw2', 'undecided', 100), event('rw3', 'undecided', 200)
    events = [first2, first3, event('rw2', 'both', 100, 1), event('rw3', 'viscous', 200, 1)]
    fss = [{'component': w, 'fields': {'detector': 'fss', 'kind': k}}
           for w, k in (('rw2', 'dry'), ('rw2', 'fss2'), ('rw1', 'fss1'))]
    result = cmd_demo.DemoResult(
        rows=10, wall_s=1.0, executor='single', events=events, pipeline_events=events,
        changes=changes, matches=[(changes[0], first2), (changes[1], first3),
                                  (changes[2], None)],
        false_alarms=[], notes=[], other_detectors={'fss': 3}, other_events=fss)
    counts = cmd_demo.kind_counts(result)
    assert counts['llr'] == {'right': 1, 'wrong': 1, 'undecided': 0, 'missed': 1}
    assert counts['fss'] == {'ran': True, 'right': 1,
                             'wrong': [('rw1', 'fss1'), ('rw2', 'fss2')],
                             'missed': [('rw3', 'viscous'), ('rw4', 'dry')]}
    report = cmd_demo.summary(result)
    assert 'llr right 1/3, wrong 1, undecided 0, missed 1' in report
    assert 'fss flags against the truth: right 1/3, wrong 2 (rw1 fss1, rw2 fss2)' in report


def test_missing_detector_modules_are_skipped_with_a_note():
    classes, notes = cmd_demo.node_classes(('rwa_monitor.nodes.llr_detector',
                                            'rwa_monitor.nodes.not_written_yet'))
    assert [c.__name__ for c in classes] == ['LLRDetectorNode']
    assert notes == ['rwa_monitor.nodes.not_written_yet is not there yet: skipped']


def _event_array(node_name='llr_detector'):
    event = AnomalyEvent('llr', 'rw2', 'dry', 120.5, 1205, 150.0, 1500, 1e-9)
    msg = DiagnosticArray()
    msg.status = [messages.event_status(event, node_name)]
    return msg


def _health_array():
    msg = DiagnosticArray()
    msg.status = [DiagnosticStatus(level=DiagnosticStatus.WARN, name='llr_detector: rw2 friction',
                                   hardware_id='rw2', message='dry anomaly since t=120.5 s',
                                   values=[KeyValue(key='kind', value='dry'),
                                           KeyValue(key='change_time_s', value='120.5')]),
                  DiagnosticStatus(level=DiagnosticStatus.OK, name='llr_detector: rw1 friction',
                                   hardware_id='rw1', message='no anomaly')]
    return msg


def test_dashboard_shows_health_and_late_joined_anomalies():
    with RosWorld() as world:
        source = world.node(Node, 'llr_detector')
        events = source.create_publisher(DiagnosticArray, 'anomalies', EVENTS_QOS)
        health = source.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        events.publish(_event_array())  # before the dashboard exists: TRANSIENT_LOCAL
        board = cmd_dashboard.Board()
        world.add(cmd_dashboard.make_node(board, context=world.context))
        world.wait_until(lambda: board.n_events == 1, 10.0, 'the late-joined event')
        world.wait_for_subscribers(health)
        health.publish(_health_array())
        world.wait_until(lambda: len(board.health) == 2, 10.0, 'two health statuses')
        events.publish(_event_array())  # the same event again is shown once
        world.spin_for(0.2)
    assert board.n_events == 1
    text = cmd_dashboard.render(board)
    lines = text.splitlines()
    rw2 = next(line for line in lines if line.startswith('rw2'))
    assert 'WARN' in rw2 and 'dry' in rw2 and '120.5' in rw2 and 'llr_detector' in rw2
    assert any(line.startswith('rw1') and 'OK' in line for line in lines)
    assert 'anomalies: 1' in text
    assert any('change t=120.5 s' in line and 'declared t=150.0 s' in line for line in lines)


def test_dashboard_command_runs_for_a_duration(capsys):
    lease = DomainLease()
    try:
        code = cmd_dashboard.run(argparse.Namespace(domain_id=lease.domain_id, duration=0.3,
                                                    interval=0.1))
    finally:
        lease.release()
    assert code == 0
    assert 'rwa_monitor dashboard' in capsys.readouterr().out


def test_demo_command_on_a_given_file_with_the_fallback_executor(tmp_path, capsys):
    from rwa_monitor.cli.main import main
    from rwa_monitor.sim.friction import simulate_friction
    from rwa_monitor.telemetry import write_telemetry
    path = tmp_path / 'small.csv'
    write_telemetry(path, simulate_friction(wheels=['rw1', 'rw2'], n_samples=600,
                                            rate_hz=10.0, seed=1))
    lease = DomainLease()
    try:
        code = main(['demo', '--file', str(path), '--quiet', '--executor', 'single',
                     '--domain-id', str(lease.domain_id)])
    finally:
        lease.release()
    out = capsys.readouterr().out
    assert code == 0
    assert 'false alarms (first declarations away from every injected change): 0' in out
    assert '600 rows' in out and 'single executor' in out


def test_events_executor_failure_falls_back(monkeypatch):
    import rclpy.experimental

    def broken(**kwargs):
        raise RuntimeError('not here')
    monkeypatch.setattr(rclpy.experimental, 'EventsExecutor', broken)
    notes = []
    with RosWorld() as world:
        executor, kind = cmd_demo._make_executor('events', world.context, notes)
        executor.shutdown()
    assert kind == 'single' and 'SingleThreadedExecutor' in notes[0]


@pytest.mark.slow
def test_demo_with_gyro_channels_feeds_every_detector(tmp_path):
    path = cmd_demo.demo_file(tmp_path, hours=0.1, gyro=True)
    assert path.name.endswith('-gyro.csv')
    lease = DomainLease()
    try:
        result = cmd_demo.run_demo(path, domain_id=lease.domain_id, live=False,
                                   out=io.StringIO())
    finally:
        lease.release()
    assert result.gyro_faults[0][:2] == ('gyro_y', 'drift')
    assert result.gyro_faults[0][2] == pytest.approx(180.0, abs=0.1)
    assert 'injected gyro fault: gyro_y drift from t=180.0 s' in cmd_demo.summary(result)


def test_dashboard_keeps_spacecraft_apart_and_shows_a_silent_node_as_lost():
    from rwa_monitor.nodes.llr_detector import LLRDetectorNode
    from rclpy.parameter import Parameter
    with RosWorld() as world:
        sat1 = world.node(LLRDetectorNode, namespace='/sat1', parameter_overrides=[
            Parameter('diagnostic_period', value=0.2)])
        sat2 = world.node(LLRDetectorNode, namespace='/sat2', parameter_overrides=[
            Parameter('diagnostic_period', value=0.2)])
        event = AnomalyEvent('llr', 'rw2', 'dry', 120.5, 1205, 150.0, 1500, 1e-9)
        sat1._publish_events(sat1._wheel('rw2'), [event])
        sat2._wheel('rw2')
        board = cmd_dashboard.Board(stale_timeout=1.0)
        view = world.add(cmd_dashboard.make_node(board, 0.2, context=world.context))
        world.wait_until(lambda: board.by_namespace.get('/sat1') == 1, 10.0, 'sat1 anomaly')
        world.wait_until(lambda: {'/sat1', '/sat2'} <= set(board.namespaces()), 10.0,
                         'both namespaces')
        text = cmd_dashboard.render(board)
        sections = text.split('== ')
        one = next(s for s in sections if s.startswith('/sat1 =='))
        two = next(s for s in sections if s.startswith('/sat2 =='))
        assert 'anomalies: 1' in one and 'anomalies: 0' in two
        assert any(line.startswith('rw2') and 'WARN' in line for line in one.splitlines())
        assert not any(line.startswith('rw2') and 'WARN' in line for line in two.splitlines())
        world.remove(sat2)                      # a killed node: its statuses stop
        world.spin_for(1.5)
        two = next(s for s in cmd_dashboard.render(board).split('== ')
                   if s.startswith('/sat2 =='))
        assert all('LOST' in line for line in two.splitlines()
                   if line.startswith(('rw2', 'telemetry/wheels', 'alarms')))
        assert 'LOST' not in next(s for s in cmd_dashboard.render(board).split('== ')
                                  if s.startswith('/sat1 =='))
        del view


def test_the_view_prints_readable_p_values_waiting_diagnosers_and_the_levels():
    """Issue 36: the demo showed p=0, p=nan and a diagnoser filling its window as STALE."""
    board = cmd_dashboard.Board()
    events = DiagnosticArray()
    events.status = [messages.event_status(AnomalyEvent('llr', 'rw2', 'dry', 120.5, 1205,
                                                        150.0, 1500, 0.0), 'llr_detector'),
                     messages.event_status(AnomalyEvent('fss', 'rw3', 'viscous', 10.0, 100,
                                                        20.0, 200), 'fss_diagnoser')]
    board.on_anomalies(events)
    health = DiagnosticArray()
    health.status = [DiagnosticStatus(
        level=DiagnosticStatus.STALE, name='fss_diagnoser: rw1 window diagnosis',
        hardware_id='rw1', message='unknown: not examined yet, waiting for a full window '
        '(100/80000 samples)', values=[KeyValue(key='waiting_samples', value='79900')])]
    board.on_diagnostics(health)
    text = cmd_dashboard.render(board)
    assert 'p=< 1e-300' in text and 'p=n/a' in text
    assert 'p=0 ' not in text and 'nan' not in text
    row = next(line for line in text.splitlines() if line.startswith('rw1'))
    assert ' WAIT ' in row and 'STALE' not in row
    assert 'levels: OK' in text and 'WAIT not examined yet' in text and 'ERROR a larger' in text


def test_the_summary_lists_the_gyro_faults_against_their_detections():
    result = cmd_demo.DemoResult(
        rows=10, wall_s=1.0, executor='events', events=[], pipeline_events=[], changes=[],
        matches=[], false_alarms=[], notes=[], other_detectors={'vsadc': 1},
        other_events=[{'component': 'gyro_y', 'level': 2, 'fields': {
            'detector': 'vsadc', 'kind': 'drift', 'change_time_s': 185.0,
            'declaration_time_s': 230.0}}],
        gyro_faults=[('gyro_y', 'drift', 180.0), ('gyro_x', 'bias', 300.0)])
    report = cmd_demo.summary(result)
    rows = report.splitlines()
    assert any(line.startswith('gyro_y drift') and '|' in line and '185.0' in line
               and '230.0' in line and '50.0' in line for line in rows), report
    assert any(line.startswith('gyro_x bias') and 'MISSED' in line for line in rows)
    assert 'gyro_y drift change t=185.0 s declared t=230.0 s (ERROR)' in report
    assert 'levels: OK examined' in report
