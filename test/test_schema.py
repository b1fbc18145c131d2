"""One parameter schema per detector: shipped YAML, docs, loader and core agree with it."""

import math

import pytest
import yaml

from rwa_monitor.core.fss.pipeline import FssConfig
from rwa_monitor.core.gyro_diagnosis import make_gyro_detector
from rwa_monitor.core.llr import LLRDetector
from rwa_monitor.core.schema import (AUTO, FLEET, FSS, LLR, parameters_document, REPLAY, SCHEMAS,
                                     VSADC)
from rwa_monitor.core.vsadc import VsadcDetector
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.parameters_file import (block_values, load_block,
                                                   read_parameters_file)

NODE_SCHEMAS = [REPLAY, LLR, FSS, VSADC]
# File-command blocks of the shipped parameters file (no node reads them).
FILE_SCHEMAS = [FLEET]


def _shipped(repo_root):
    return yaml.safe_load((repo_root / 'config' / 'rwa_monitor.yaml').read_text())


@pytest.mark.parametrize('schema', NODE_SCHEMAS + FILE_SCHEMAS, ids=lambda s: s.name)
def test_shipped_yaml_equals_schema_defaults(repo_root, schema):
    block = _shipped(repo_root)[schema.name]['ros__parameters']
    assert block == schema.defaults()


def test_shipped_yaml_has_no_other_block_and_no_required_value(repo_root):
    shipped = _shipped(repo_root)
    assert set(shipped) == {'/**', 'basilisk_bus'} | {s.name for s in NODE_SCHEMAS + FILE_SCHEMAS}
    assert shipped['/**']['ros__parameters'] == {'use_sim_time': True}
    # A `file: ""` here would beat `-p file:=PATH` on the replay's command line.
    assert 'file' not in shipped[REPLAY.name]['ros__parameters']
    assert REPLAY['file'].required


def test_bus_block_equals_the_bus_node_defaults(repo_root):
    pytest.importorskip('rclpy')
    from rwa_monitor.nodes.basilisk_bus import PARAMETERS
    block = dict(_shipped(repo_root)['basilisk_bus']['ros__parameters'])
    assert block.pop('use_sim_time') is False
    assert block == {p.name: p.default for p in PARAMETERS}


def test_docs_table_matches_the_schema(repo_root):
    text = (repo_root / 'docs' / 'parameters.md').read_text()
    assert text == parameters_document(), 'regenerate: rwa-monitor params --markdown'


def test_loader_merges_shared_block_and_refuses_unknown_names(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text('/**:\n  ros__parameters:\n    use_sim_time: true\n    window: 300\n'
                    'llr_detector:\n  ros__parameters:\n    false_alarm_rate: 1e-4\n')
    values = load_block(path, LLR)
    assert values['window'] == 300 and values['false_alarm_rate'] == 1e-4
    assert load_block(path, VSADC)['window'] == 300
    path.write_text('llr_detector:\n  ros__parameters:\n    windw: 300\n')
    with pytest.raises(ConfigError, match="unknown parameter 'windw'; did you mean 'window'"):
        load_block(path, LLR)
    path.write_text('/**:\n  ros__parameters:\n    flase_alarm_rate: 1.0e-4\n')
    with pytest.raises(ConfigError, match="did you mean 'false_alarm_rate'"):
        load_block(path, LLR)


@pytest.mark.parametrize('text', ['- a\n- b\n', '42\n', 'llr_detector: 3\n',
                                  'llr_detector:\n  ros__parameters: [1]\n'])
def test_a_file_that_is_not_a_mapping_is_one_line(tmp_path, text):
    path = tmp_path / 'p.yaml'
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        load_block(path, LLR)
    assert str(path) in str(err.value) and '\n' not in str(err.value)


def test_auto_is_one_spelling_and_numbers_without_a_dot_are_floats():
    values = block_values({'llr_detector': {'ros__parameters': {
        'k_verif': 'auto', 'noise_std': 'auto', 'false_alarm_rate': '1e-5'}}}, LLR)
    assert values['k_verif'] == AUTO and values['false_alarm_rate'] == 1e-5
    detector = LLRDetector('rw1', k_verif=AUTO, noise_std=AUTO, window=300)
    assert detector.params['k_verif'] == 150 and detector.params['noise_std'] is None
    assert LLRDetector('rw1', k_verif=0).params['k_verif'] == 0
    with pytest.raises(ConfigError, match='noise_std'):
        LLR.validate({'noise_std': 0.0})
    with pytest.raises(ConfigError, match='window'):
        VSADC.validate({'window': 'automatic'})
    axis = VsadcDetector(window=50, sigma_window=AUTO, reference_window=AUTO).channels[0]
    assert axis.sigma_window == 50 and axis.reference_window == 50


def test_relations_are_the_algorithms_own():
    with pytest.raises(ConfigError, match=r'k_verif must be an integer in \[0, 99\]'):
        LLR.validate({'window': 100, 'k_verif': 100})
    with pytest.raises(ConfigError, match='axes'):
        VSADC.validate({'axes': 'x,w'})


def _edges(param):
    """Yield (value, accepted) just inside and just outside each bound of ``param``."""
    step = 1 if param.type is int else None
    for end, sign, is_open in ((param.low, -1, param.low_open),
                               (param.high, 1, param.high_open)):
        if end is None or math.isinf(end):
            continue
        if step:
            yield int(end), True
            yield int(end) + sign, False
        else:
            outside = end + sign * 1e-9 * max(1.0, abs(end))
            yield (end, not is_open)
            if not is_open:
                yield outside, False


def _core(schema, name, value):
    """Build the algorithm with one parameter changed (its own checks run)."""
    values = {**schema.defaults(), name: value}
    if schema is LLR:
        LLRDetector('rw1', **{n: values[n] for n in LLR.names(('all',))
                              if n != 'friction_model_file'})
    elif schema is VSADC:
        make_gyro_detector(values)          # builds VsadcDetector and the residual axes
    else:
        FssConfig(**{n: values[n] for n in FSS.names(('all',)) if n != 'model'})


CORE_PARAMS = [(s, p) for s in (LLR, VSADC, FSS) for p in s
               if p.scope == 'all' and p.type in (int, float)
               and (p.low is not None or p.high is not None)]


@pytest.mark.parametrize('schema,param', CORE_PARAMS,
                         ids=[f'{s.name}.{p.name}' for s, p in CORE_PARAMS])
def test_schema_bounds_are_the_core_bounds(schema, param):
    for value, accepted in _edges(param):
        if accepted:
            schema.validate({param.name: value})
            _core(schema, param.name, value)
        else:
            with pytest.raises(ValueError):
                schema.validate({param.name: value})
            with pytest.raises(ValueError):
                _core(schema, param.name, value)


def test_every_schema_is_importable_without_ros():
    import subprocess
    import sys
    code = ('import sys, rwa_monitor.core.schema as s, rwa_monitor.telemetry.parameters_file;'
            'assert "rclpy" not in sys.modules; print(len(s.SCHEMAS))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert int(out.stdout) == len(SCHEMAS)


def test_read_installed_file():
    assert 'llr_detector' in read_parameters_file(None)
