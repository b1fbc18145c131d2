"""Bus parameters, fault specifications and the CLI's behaviour without the simulator.

These run everywhere (no Basilisk import); the simulator's own tests are in
test_basilisk.py and skip where the optional extra is absent.
"""

import math

import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.exceptions import ConfigError, RwaMonitorError
from rwa_monitor.sim import basilisk_config
from rwa_monitor.sim.basilisk_config import (BIAS, BusConfig, describe, DRIFT, FrictionFault,
                                             GyroFault, HEALTHY, parse_fault)


def test_parse_friction_step_and_ramp():
    assert parse_fault('friction:rw2:600:dry=3e-4') == FrictionFault('rw2', 600.0, 3e-4)
    ramp = parse_fault('friction:rw4:10.5:dry=-1e-4,viscous=2e-6,ramp=300')
    assert ramp == FrictionFault('rw4', 10.5, -1e-4, 2e-6, 300.0)
    assert ramp.fraction(10.0) == 0.0
    assert ramp.fraction(160.5) == pytest.approx(0.5)
    assert ramp.fraction(1e6) == 1.0
    assert parse_fault('friction:rw1:0:viscous=1e-6').fraction(0.0) == 1.0


def test_parse_gyro_bias_and_drift():
    assert parse_fault('gyro:y:900:bias=2e-4') == GyroFault(1, 900.0, 2e-4, 0.0)
    drift = parse_fault('gyro:z:100:drift=1e-6,level=-2e-4')
    assert drift == GyroFault(2, 100.0, -2e-4, 1e-6)
    assert drift.error(50.0) == (0.0, HEALTHY)
    assert drift.error(200.0) == (pytest.approx(-1e-4), DRIFT)
    assert drift.error(400.0) == (-2e-4, BIAS)
    endless = parse_fault('gyro:x:0:drift=1e-6')
    assert math.isnan(endless.level)
    assert endless.error(1e5) == (pytest.approx(0.1), DRIFT)


def test_now_means_the_given_time():
    assert parse_fault('friction:rw3:now:dry=1e-4', now=42.0).time_s == 42.0


@pytest.mark.parametrize('spec, words', [
    ('friction:rw9:1:dry=1e-4', 'WHEEL must be one of'),
    ('friction:rw1:1', 'expected'),
    ('friction:rw1:-1:dry=1e-4', '>= 0'),
    ('friction:rw1:x:dry=1e-4', 'TIME_S must be'),
    ('friction:rw1:1:ramp=10', 'dry=NM and/or viscous'),
    ('friction:rw1:1:dry=1e-4,ramp=-1', 'ramp must be'),
    ('friction:rw1:1:dry=abc', 'must be a number'),
    ('friction:rw1:1:dry=nan', 'finite'),
    ('friction:rw1:1:dry=1,dry=2', 'given twice'),
    ('friction:rw1:1:cold=1', 'KEY one of'),
    ('gyro:w:1:bias=1e-4', 'AXIS must be one of'),
    ('gyro:x:1:bias=1e-4,drift=1e-6', 'exactly one'),
    ('gyro:x:1:level=1e-4', 'exactly one'),
    ('gyro:x:1:bias=1e-4,level=1e-4', 'level goes with drift'),
    ('gyro:x:1:drift=-1e-6', 'slope must be > 0'),
    ('thermal:rw1:1:dry=1', 'kind must be friction or gyro'),
])
def test_bad_fault_specs_say_what_is_wrong(spec, words):
    with pytest.raises(ConfigError, match=words):
        parse_fault(spec)


def test_describe_names_component_and_size():
    assert 'rw2' in describe(parse_fault('friction:rw2:600:dry=3e-4'))
    assert 'drift' in describe(parse_fault('gyro:x:1:drift=1e-6'))
    assert 'bias' in describe(parse_fault('gyro:x:1:bias=1e-6'))


@pytest.mark.parametrize('change, name', [
    ({'rate_hz': 0.0}, 'rate_hz'), ({'coulomb': -1.0}, 'coulomb'),
    ({'static': 1e-5}, 'static'), ({'elevation_deg': 90.0}, 'elevation_deg'),
    ({'ref_period': (1.0, 2.0)}, 'ref_period'), ({'ref_amplitude': (0.0, -1.0, 0.0)},
                                                 'ref_amplitude'),
    ({'omega_limit_cycle': 0.0}, 'omega_limit_cycle'),
    ({'stribeck_speed': -1.0}, 'stribeck_speed'),
])
def test_config_validation_names_the_parameter(change, name):
    with pytest.raises(ValueError, match=name):
        BusConfig(**change).validated()


def test_default_config_is_valid():
    assert BusConfig().validated() == BusConfig()


def test_cli_without_the_simulator_says_how_to_install(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(basilisk_config, 'available', lambda: False)
    with pytest.raises(RwaMonitorError, match=r'\[bsk\]'):
        basilisk_config.require()
    out = tmp_path / 'bus.csv'
    assert main(['simulate', 'basilisk', '--seconds', '10', '-o', str(out)]) == 2
    assert 'optional extra' in capsys.readouterr().err
    assert not out.exists()


def test_cli_rejects_bad_arguments_before_simulating(tmp_path, capsys):
    out = str(tmp_path / 'bus.csv')
    assert main(['simulate', 'basilisk', '--seconds', '10', '--fault', 'gyro:q:1:bias=1',
                 '-o', out]) == 2
    assert 'AXIS must be one of' in capsys.readouterr().err
    assert main(['simulate', 'basilisk', '--seconds', '0.1', '-o', out]) == 2
    assert 'at least one sample' in capsys.readouterr().err
    assert main(['simulate', 'basilisk', '--rate', '-4', '-o', out]) == 2
    assert 'rate_hz' in capsys.readouterr().err


def test_bus_node_without_the_simulator_is_a_config_error(monkeypatch):
    from ros_harness import RosWorld

    from rwa_monitor.nodes import basilisk_bus
    monkeypatch.setattr(basilisk_bus, 'available', lambda: False)
    with RosWorld() as world:
        with pytest.raises(ConfigError, match='optional extra'):
            world.node(basilisk_bus.BasiliskBusNode)


def test_cli_guidance_scale_must_be_non_negative(tmp_path, capsys):
    out = str(tmp_path / 'bus.csv')
    assert main(['simulate', 'basilisk', '--guidance-scale', '-1', '-o', out]) == 2
    assert 'ref_amplitude' in capsys.readouterr().err
