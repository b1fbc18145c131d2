"""Tests of the shared node helpers: parameters, diagnostics, QoS."""

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_harness import Collector, RosWorld

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes import common

pytestmark = pytest.mark.ros

SPECS = (
    common.ParamSpec('rate', 1.0, 'Time factor.', low=0.0),
    common.ParamSpec('alpha', 1.0e-5, 'False-alarm rate.', low=0.0, high=1.0,
                     low_open=True, high_open=True),
    common.ParamSpec('window', 500, 'Samples.', low=10, high=100000, read_only=True),
    common.ParamSpec('mode', 'a', 'Mode.', choices=('a', 'b')),
    common.ParamSpec('loop', False, 'Loop.'),
    common.ParamSpec('wheels', [''], 'Wheel ids.'),
)


def _node(world, overrides=None):
    args = []
    for name, value in (overrides or {}).items():
        args += ['-p', f'{name}:={value}']
    cli = ['--ros-args', *args] if args else None
    return world.node(Node, 'params_under_test', cli_args=cli)


def test_defaults_and_descriptors():
    with RosWorld() as world:
        node = _node(world)
        params = common.declare_parameters(node, SPECS)
        assert dict(params)['rate'] == 1.0 and params['window'] == 500
        desc = node.describe_parameter('alpha')
        assert desc.description == 'False-alarm rate.'
        assert desc.floating_point_range[0].to_value == 1.0
        assert node.describe_parameter('window').read_only
        assert node.describe_parameter('window').integer_range[0].from_value == 10


@pytest.mark.parametrize('name,value,fragment', [
    ('rate', '-1.0', 'rate'),
    ('alpha', '0.0', 'alpha'),
    ('window', '3', 'window'),
    ('mode', 'c', 'mode'),
    ('rate', 'fast', 'rate'),
])
def test_bad_start_up_value_names_the_parameter(name, value, fragment):
    with RosWorld() as world:
        node = _node(world, {name: value})
        with pytest.raises(ConfigError, match=fragment):
            common.declare_parameters(node, SPECS)


def test_run_time_change_validated_and_applied():
    changes = []
    with RosWorld() as world:
        node = _node(world)
        params = common.declare_parameters(node, SPECS, lambda n, v: changes.append((n, v)))
        result = node.set_parameters([Parameter('alpha', value=2.0)])[0]
        assert not result.successful and 'alpha' in result.reason
        assert params['alpha'] == 1.0e-5
        result = node.set_parameters([Parameter('mode', value='z')])[0]
        assert not result.successful and 'mode' in result.reason
        result = node.set_parameters([Parameter('window', value=20)])[0]
        assert not result.successful
        assert node.set_parameters([Parameter('alpha', value=1.0e-3)])[0].successful
        assert params['alpha'] == 1.0e-3 and changes == [('alpha', 1.0e-3)]


def test_diagnostics_levels_names_and_stale():
    with RosWorld() as world:
        node = world.node(Node, 'health_node')
        listener = world.node(Node, 'listener')
        got = Collector(listener, DiagnosticArray, '/diagnostics', common.DIAGNOSTICS_QOS)
        diag = common.DiagnosticsPublisher(node, period=0.2, stale_timeout=0.6)
        diag.mark_input('rw1', 'rw1 friction')
        diag.set('rw1', 'rw1 friction', common.WARN, 'dry anomaly', change_time_s=12.5)

        def last_status():
            return got.messages[-1].status[0] if got.messages else None

        world.wait_until(lambda: last_status() is not None, 5.0, 'a diagnostics message')
        status = last_status()
        assert status.name == 'health_node: rw1 friction' and status.hardware_id == 'rw1'
        assert status.level == DiagnosticStatus.WARN
        values = {kv.key: kv.value for kv in status.values}
        assert values['change_time_s'] == '12.5'
        world.wait_until(lambda: last_status().level == DiagnosticStatus.STALE, 5.0, 'STALE')
        values = {kv.key: kv.value for kv in last_status().values}
        assert values['last_level'] == 'WARN'
        diag.mark_input('rw1', 'rw1 friction')
        world.wait_until(lambda: last_status().level == DiagnosticStatus.WARN, 5.0,
                         'back to WARN after input resumed')


def test_a_failing_health_provider_reports_error_not_a_crash():
    with RosWorld() as world:
        node = world.node(Node, 'health_node')
        diag = common.DiagnosticsPublisher(node, period=0.2, stale_timeout=5.0)

        def broken():
            raise ZeroDivisionError('bug')
        diag.provide('rw1', 'rw1 friction', broken)
        diag.mark_input('rw1', 'rw1 friction')
        status = diag.status(diag.components['rw1'])
        assert status.level == DiagnosticStatus.ERROR and 'bug' in status.message
        diag.publish()


_INTERRUPTED_INSIDE_RCLPY = '''
import os, signal, sys, time
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rwa_monitor.nodes.common import run_node


class Interrupted(Node):
    def __init__(self):
        super().__init__('interrupted')
        self.create_timer(0.1, self.tick, clock=Clock(clock_type=ClockType.STEADY_TIME))

    def tick(self):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)
        except KeyboardInterrupt:
            # What rclpy's C++ layer makes of Ctrl-C arriving inside take_message.
            raise RuntimeError('Unable to convert call argument 0 to Python object')


sys.exit(run_node(Interrupted, [sys.argv[0]]))
'''


def test_ctrl_c_inside_an_rclpy_call_is_a_clean_stop(tmp_path):
    import subprocess
    import sys
    script = tmp_path / 'interrupted.py'
    script.write_text(_INTERRUPTED_INSIDE_RCLPY)
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 0, done.stderr
    assert 'Traceback' not in done.stderr + done.stdout
