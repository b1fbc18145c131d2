"""Node parameters come from the core schema: the shipped file, `-p`, auto, unknown names."""

import numpy as np
import pytest
from rclpy.parameter import Parameter
from ros_harness import RosWorld

from rwa_monitor.core.schema import LLR, REPLAY
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.nodes.common import descriptor
from rwa_monitor.nodes.llr_detector import LLRDetectorNode
from rwa_monitor.nodes.replay import TelemetryReplay
from rwa_monitor.nodes.vsadc_detector import VsadcDetectorNode
from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry

pytestmark = pytest.mark.ros


def test_replay_file_from_the_command_line_beats_nothing_in_the_shipped_file(
        tmp_path, repo_root):
    path = tmp_path / 'wheels.csv'
    write_telemetry(path, Telemetry(time=np.arange(5.0), wheels={
        'rw1': Wheel(np.ones(5), np.zeros(5))}))
    shipped = str(repo_root / 'config' / 'rwa_monitor.yaml')
    with RosWorld() as world:
        node = world.node(TelemetryReplay, cli_args=[
            '--ros-args', '--params-file', shipped, '-p', f'file:={path}',
            '-p', 'exit_when_done:=false'])
        assert node.params['file'] == str(path)
        with pytest.raises(ConfigError, match='file'):
            world.node(TelemetryReplay, cli_args=['--ros-args', '--params-file', shipped])


def test_auto_and_floats_without_a_dot_on_the_command_line():
    with RosWorld() as world:
        node = world.node(LLRDetectorNode, cli_args=[
            '--ros-args', '-p', 'k_verif:=auto', '-p', 'noise_std:=auto',
            '-p', 'false_alarm_rate:=1e-4', '-p', 'window:=300'])
        assert node.params['k_verif'] == 'auto' and node.params['false_alarm_rate'] == 1e-4
        assert node._values['k_verif'] == 'auto' and node._values['window'] == 300
        assert node.set_parameters([Parameter('k_verif', value=40)])[0].successful
        assert node._values['k_verif'] == 40


@pytest.mark.parametrize('node_class', [LLRDetectorNode, VsadcDetectorNode])
def test_unknown_parameter_is_refused_with_the_nearest_name(node_class):
    with RosWorld() as world:
        with pytest.raises(ConfigError, match="did you mean 'window'"):
            world.node(node_class, parameter_overrides=[Parameter('windw', value=3)])


def test_descriptor_comes_from_the_schema():
    desc = descriptor(LLR['window'])
    assert desc.integer_range[0].from_value == LLR['window'].low == 10
    assert 'auto' in descriptor(LLR['k_verif']).description
    assert descriptor(REPLAY['file']).read_only
