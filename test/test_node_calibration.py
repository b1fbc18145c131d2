"""The detector nodes' ``calibration_file``: same events as ``detect --calibration``."""

import hashlib

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, RosWorld
import yaml

from rwa_monitor.core import keys
from rwa_monitor.core.wheel_runner import WheelRunner
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import EVENTS_QOS
from rwa_monitor.nodes.llr_detector import LLRDetectorNode
from rwa_monitor.nodes.replay import TelemetryReplay
from rwa_monitor.pipelines import calibrated, llr
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
from rwa_monitor.telemetry import read_telemetry, write_telemetry

pytestmark = pytest.mark.ros

CONFIG = {'window': 200, 'false_alarm_rate': 1.0e-5}


def _files(tmp_path):
    """Return (calibration file, faulted telemetry file, its telemetry)."""
    # 10 minutes of commissioning: with 5 (3000 samples) the nominal is not determined to
    # a test window's precision at the faulted record's speeds of rw2 (docs/calibration.md,
    # "Where the nominal is tested"), which would then be left untested.
    nominal, _ = simulate_friction_with_truth(wheels=['rw1', 'rw2'], n_samples=6000,
                                              rate_hz=10.0, seed=5)
    document, _, arrays = calibrated.commission([nominal])
    cal = calibrated.write(document, arrays, tmp_path / 'cal')[0]
    faulted, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=3000, rate_hz=10.0, seed=11,
        anomalies=[Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    path = tmp_path / 'faulted.csv'
    write_telemetry(path, faulted)
    return cal, path, read_telemetry(path)


def _changes(collector):
    return [s for m in collector.messages for s in m.status
            if messages.status_event(s).kind == keys.CALIBRATION_KIND]


def _key(event):
    return (event.component, event.kind, event.index, event.declared_index, event.revision)


def test_node_with_calibration_equals_detect_and_keeps_the_last_good_file(tmp_path):
    cal, path, tele = _files(tmp_path)
    expected = [e for e in llr.run(tele, {**CONFIG, 'calibration_file': str(cal)})
                if not e.details.get('final')]   # a live node has no end of record
    assert any(e.component == 'rw2' for e in expected)
    with RosWorld('calibration') as world:
        overrides = [Parameter('use_sim_time', value=True),
                     Parameter('calibration_file', value=str(cal))]
        overrides += [Parameter(k, value=v) for k, v in CONFIG.items()]
        detector = world.node(LLRDetectorNode, parameter_overrides=overrides)
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter(k, value=v) for k, v in {'file': str(path), 'rate': 0.0, 'burst': 50,
                                               'exit_when_done': False}.items()])
        world.wait_until(lambda: replay.done and sum(
            w.samples for w in detector.wheels.values()) == 2 * len(tele), 240.0,
            f'samples ({detector.input_counters})')
        world.wait_until(lambda: sum(len(m.status) for m in anomalies.messages)
                         >= len(expected), 10.0, 'events')
        got = [messages.status_event(s) for m in anomalies.messages for s in m.status]
        assert [_key(e) for e in got] == [_key(e) for e in expected]
        values = detector.calibration.values()
        assert values['calibration_file'] == str(cal)
        bad = tmp_path / 'bad.yaml'
        bad.write_text(yaml.safe_dump({'calibration': {'version': 1}}))
        for wrong, words in ((tmp_path / 'missing.yaml', 'cannot read'),
                             (bad, 'key calibration.wheels')):
            result = detector.set_parameters([Parameter('calibration_file',
                                                        value=str(wrong))])[0]
            assert not result.successful and str(wrong) in result.reason
            assert words in result.reason
        assert detector.calibration.path == str(cal) and detector.calibration.loads == 1
        assert not [s for m in anomalies.messages for s in m.status
                    if messages.status_event(s).kind == keys.CALIBRATION_KIND]
        # A new, valid file: reloaded, one calibration_changed event, shown in diagnostics.
        other = tmp_path / 'other.yaml'
        other.write_text(cal.read_text().replace('version: 1', 'version: 1\n  note: 2', 1))
        assert detector.set_parameters([Parameter('calibration_file',
                                                  value=str(other))])[0].successful
        assert detector.calibration.loads == 2
        world.wait_until(lambda: _changes(anomalies), 10.0, 'calibration event')
        status = _changes(anomalies)[-1]
        assert status.level == DiagnosticStatus.OK
        event = messages.status_event(status)
        assert (event.detector, event.component, event.index) == ('llr', 'calibration', -1)
        assert event.details[keys.CALIBRATION_FILE] == str(other)
        assert event.details[keys.PREVIOUS_CALIBRATION] == str(cal)
        digest = hashlib.sha256(other.read_bytes()).hexdigest()
        assert event.details[keys.CALIBRATION_SHA256] == digest
        health = detector.diagnostics.status(detector.diagnostics.components['calibration'])
        shown = {kv.key: kv.value for kv in health.values}
        assert shown[keys.CALIBRATION_FILE] == str(other)
        assert shown[keys.CALIBRATION_SHA256] == digest
        assert health.level == DiagnosticStatus.OK and 'sha256' in health.message
        # A malformed file at run time: refused naming file and key; the last good stays.
        result = detector.set_parameters([Parameter('calibration_file', value=str(bad))])[0]
        assert not result.successful and 'key calibration.wheels' in result.reason
        assert detector.calibration.path == str(other) and detector.calibration.sha256 == digest
        world.spin_for(0.5)
        assert len(_changes(anomalies)) == 1
        assert not any(a.event.kind == keys.CALIBRATION_KIND
                       for a in detector.alarms.store.active())


def test_node_refuses_to_start_on_a_bad_calibration(tmp_path):
    with RosWorld('calibration_bad') as world:
        with pytest.raises(ConfigError, match='missing.yaml: cannot read'):
            world.node(LLRDetectorNode, parameter_overrides=[
                Parameter('calibration_file', value=str(tmp_path / 'missing.yaml'))])


def _wheel_and_gyro_calibration(tmp_path):
    """Return a calibration file with wheels (simulated friction) and a gyro block."""
    from rwa_monitor.core import gyro_calibration as gc
    nominal, _ = simulate_friction_with_truth(wheels=['rw1'], n_samples=2000, rate_hz=10.0,
                                              seed=7)
    document, _, arrays = calibrated.commission([nominal])
    cal = calibrated.write(document, arrays, tmp_path / 'cal')[0]
    rng = np.random.default_rng(3)
    t = 0.25 * np.arange(1, 4801)
    gyro = rng.normal(0.0, 1e-5, (len(t), 3))
    q = np.tile([0.0, 0.0, 0.0, 1.0], (len(t), 1))
    data = yaml.safe_load(cal.read_text())
    data['calibration']['gyro'] = gc.calibrate_gyro(t, gyro, q)
    cal.write_text(yaml.safe_dump(data))
    return cal


@pytest.mark.parametrize('name', ['fss', 'vsadc'])
def test_fss_and_vsadc_nodes_announce_a_calibration_change(tmp_path, name):
    from rwa_monitor.nodes.fss_diagnoser import FssDiagnoserNode
    from rwa_monitor.nodes.vsadc_detector import VsadcDetectorNode
    node_class = {'fss': FssDiagnoserNode, 'vsadc': VsadcDetectorNode}[name]
    cal = _wheel_and_gyro_calibration(tmp_path)
    other = tmp_path / 'other.yaml'
    other.write_text(cal.read_text() + '\n# second copy\n')
    with RosWorld(f'calibration_{name}') as world:
        node = world.node(node_class, parameter_overrides=[
            Parameter('calibration_file', value=str(cal))])
        sink = world.node(Node, 'sink')
        anomalies = Collector(sink, DiagnosticArray, 'anomalies', EVENTS_QOS)
        world.spin_for(0.3)
        bad = tmp_path / 'bad.yaml'
        bad.write_text('calibration: {version: 1}\n')
        result = node.set_parameters([Parameter('calibration_file', value=str(bad))])[0]
        assert not result.successful and str(bad) in result.reason
        assert node.calibration.path == str(cal)
        assert node.set_parameters([Parameter('calibration_file',
                                              value=str(other))])[0].successful
        world.wait_until(lambda: _changes(anomalies), 10.0, 'calibration event')
        world.spin_for(0.3)
        assert len(_changes(anomalies)) == 1
        event = messages.status_event(_changes(anomalies)[0])
        assert (event.detector, event.component) == (name, 'calibration')
        assert event.details[keys.CALIBRATION_FILE] == str(other)
        assert event.details[keys.PREVIOUS_CALIBRATION] == str(cal)
        assert node.calibration.path == str(other)


def test_samples_not_tested_are_counted_across_calibration_reloads(tmp_path):
    from rwa_monitor.core.schema import LLR
    from rwa_monitor.nodes.calibration import CalibrationInForce
    from rwa_monitor.nodes.llr_detector import _Wheel
    cal, _, _ = _files(tmp_path)
    holder = CalibrationInForce(str(cal))
    low, high = holder.block('rw1')['speed_range_rad_s']
    inside = 0.5 * (low + high)
    values = {**LLR.defaults(), 'window': 200}

    def runner():
        return WheelRunner('rw1', values, nominal=holder.nominal('rw1'))

    wheel = _Wheel(runner(), 1.0)

    def feed(start, speeds):
        for k, w in enumerate(speeds):
            wheel.runner.update(start + 0.1 * k, w, 1e-3)

    feed(0.0, [inside] * 5 + [high + 50.0] * 3 + [low - 50.0] * 4)
    assert wheel.totals()[1] == {'low_speed_band': 0, 'outside_calibrated_range': 7}
    holder.set(str(cal))    # a reload: a new runner; the wheel's counts go on
    wheel.restart(runner())
    feed(10.0, [high + 50.0] * 2)
    rejected, untested = wheel.totals()
    assert untested == {'low_speed_band': 0, 'outside_calibrated_range': 9}
    assert rejected['non_finite'] == 0   # not tested is not counted again as non-finite
    holder.set('')          # no calibration: the friction itself is tested
    wheel.restart(runner())
    feed(20.0, [high + 50.0] * 2)
    assert wheel.totals()[1]['outside_calibrated_range'] == 9
    assert wheel.totals()[0]['non_finite'] == 0
