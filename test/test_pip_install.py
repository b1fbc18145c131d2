"""`pip install CLONE` into a clean virtual environment gives a working rwa-monitor.

The environment is new (no system site-packages, no PYTHONPATH) and pip uses the
machine's own configuration (its index and wheel folders), so setup.py's dependencies
alone must bring everything the command line and the nodes need.
"""

import json
import pathlib

import pip_venv
import pytest
from ros_harness import DomainLease

_run = pip_venv.run


@pytest.fixture(scope='module')
def clean_install(tmp_path_factory):
    """Return (bin folder, env, scratch folder) of a clean venv with the package installed."""
    bin_dir, env = pip_venv.clean_install(tmp_path_factory)
    return bin_dir, env, tmp_path_factory.mktemp('pip')


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_the_command_line_simulates_and_detects(clean_install):
    bin_dir, env, root = clean_install
    where = _run([str(bin_dir / 'python'), '-c',
                  'import rwa_monitor; print(rwa_monitor.__file__)'], env, root)
    assert pathlib.Path(where.stdout.strip()).is_relative_to(bin_dir.parent), where.stdout
    cli = str(bin_dir / 'rwa-monitor')
    usage = _run([cli, '--help'], env, root)
    assert usage.returncode == 0 and 'simulate' in usage.stdout, usage.stderr
    sim = _run([cli, 'simulate', 'friction', '--wheels', '2', '--hours', '0.2', '--anomaly',
                'rw2:dry:300:+3e-4', '--seed', '3', '-o', 'run.csv'], env, root)
    assert sim.returncode == 0, sim.stderr
    detect = _run([cli, 'detect', 'run.csv', '-o', 'events.json'], env, root)
    assert detect.returncode == 1, detect.stderr      # 1: an anomaly was found (--help)
    events = json.loads((root / 'events.json').read_text())['events']
    assert {e['component'] for e in events} == {'rw2'}
    assert all(e['time'] >= 300.0 for e in events)   # nothing before the injected fault


@pytest.mark.slow
@pytest.mark.timeout(1800)
@pytest.mark.parametrize('command', ['llr_detector', 'rwa-monitor-llr', 'telemetry_replay',
                                     'foxglove_bridge'])
def test_the_nodes_are_installed_under_both_names(clean_install, command):
    bin_dir, env, root = clean_install
    usage = _run([str(bin_dir / command), '--help'], env, root, timeout=120)
    assert usage.returncode == 0 and 'parameters' in usage.stdout, usage.stderr


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_the_live_view_without_its_extra_says_what_to_install(clean_install):
    bin_dir, env, root = clean_install
    lease = DomainLease()
    try:
        run = _run([str(bin_dir / 'foxglove_bridge'), '--ros-args', '-p', 'port:=0'],
                   {**env, 'ROS_DOMAIN_ID': str(lease.domain_id),
                    'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'}, root, timeout=120)
    finally:
        lease.release()
    assert run.returncode == 2, run.stdout + run.stderr
    assert 'rwa_monitor[foxglove]' in run.stdout + run.stderr
    assert 'Traceback' not in run.stderr
