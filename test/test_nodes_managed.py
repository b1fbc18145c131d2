"""The managed (lifecycle) llr_detector in process: states, events, latched alarms kept."""

import pytest
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.parameter import Parameter
from ros_harness import RosWorld

from rwa_monitor.nodes import messages
from rwa_monitor.nodes.common import RCLError
from rwa_monitor.nodes.managed import ManagedLLRDetectorNode
from rwa_monitor.pipelines import llr
from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth

pytestmark = pytest.mark.ros

CONFIG = {'window': 200, 'k_verif': 'auto', 'false_alarm_rate': 1.0e-5, 'noise_std': 'auto'}


def _rows(tele):
    names = list(tele.wheels)
    for k, t in enumerate(tele.time):
        yield messages.encode_joint_state(
            float(t), names, [float(tele.wheels[w].speed[k]) for w in names],
            [float(tele.wheels[w].friction[k]) for w in names])


def _key(events):
    return [(e.component, e.kind, e.index, e.declared_index) for e in events]


def test_only_an_active_node_detects_and_deactivation_keeps_the_latched_alarms():
    tele, _ = simulate_friction_with_truth(
        wheels=['rw1', 'rw2'], n_samples=3000, rate_hz=10.0, seed=11,
        anomalies=[Anomaly('rw2', 'dry', 150.0, delta_dry=3e-4)])
    expected = [e for e in llr.run(tele, CONFIG)
                if not e.details.get('final')]     # a live node has no end of record
    assert expected
    rows = list(_rows(tele))
    with RosWorld() as world:
        node = world.node(ManagedLLRDetectorNode, parameter_overrides=[
            Parameter(k, value=v) for k, v in CONFIG.items()])
        for raw in rows[:100]:                 # unconfigured: received, not detected
            node.on_raw_wheels(raw)
        assert node.input_counters['inactive'] == 100 and not node.wheels
        loads = node.calibration.loads
        assert node.trigger_configure() == TransitionCallbackReturn.SUCCESS
        assert node.calibration.loads == loads + 1     # configure loaded the calibration
        assert node.trigger_activate() == TransitionCallbackReturn.SUCCESS
        for raw in rows:
            node.on_raw_wheels(raw)
        assert _key(node.events) == _key(expected)
        latched = [a.event for a in node.alarms.store.active()]
        assert latched
        assert node.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
        samples = node.wheels['rw2'].samples
        for raw in rows[:50]:
            node.on_raw_wheels(raw)
        assert node.wheels['rw2'].samples == samples
        assert node.input_counters['inactive'] == 150
        assert [a.event for a in node.alarms.store.active()] == latched
        level, message, _ = node.alarms._health()
        assert 'latched' in message and level != b'\x00'
        assert node.trigger_cleanup() == TransitionCallbackReturn.SUCCESS
        assert not node.wheels and [a.event for a in node.alarms.store.active()] == latched


def test_a_calibration_refused_at_configure_fails_the_transition(monkeypatch):
    with RosWorld() as world:
        node = world.node(ManagedLLRDetectorNode)

        def refuse(path):
            raise ValueError('calibration.yaml: wheels.rw1.noise_std: must be > 0')
        monkeypatch.setattr(node.calibration, 'set', refuse)
        assert node.trigger_configure() == TransitionCallbackReturn.FAILURE
        with pytest.raises(RCLError, match='not registered'):   # still unconfigured
            node.trigger_activate()
        assert not node.active
