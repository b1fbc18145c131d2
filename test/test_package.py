"""The package builds the way a real ROS 2 install does, and its parts import cleanly."""

import os
import pathlib
import shutil
import subprocess
import sys

from conftest import REPO
import pytest


_IGNORED = shutil.ignore_patterns(
    '.venv*', '.git', 'build', 'install', 'log', 'bench', '*.egg-info', '__pycache__',
    'node_modules')


def _ignored(folder: str, names: list[str]) -> set[str]:
    """Return what a fresh clone does not hold: the patterns, and data/generated.

    data/generated is the simulators' cache (git-ignored); in a working copy that ran the
    bus benchmarks it holds gigabytes, copied once per install test before.
    """
    skip = set(_IGNORED(folder, names))
    if pathlib.Path(folder) == REPO / 'data':
        skip.add('generated')
    return skip


def copy_sources(dest: pathlib.Path) -> None:
    """Copy the repository's sources to ``dest``, as a fresh clone holds them."""
    shutil.copytree(REPO, dest, ignore=_ignored)


def test_core_never_imports_rclpy():
    code = ('import importlib, pkgutil, sys, rwa_monitor.core as c\n'
            'for m in pkgutil.walk_packages(c.__path__, "rwa_monitor.core."):\n'
            '    importlib.import_module(m.name)\n'
            'assert "rclpy" not in sys.modules, "core imported rclpy"\n')
    subprocess.run([sys.executable, '-c', code], check=True, cwd=REPO)


def test_cli_help_lists_commands():
    out = subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', '--help'],
                         capture_output=True, text=True, check=True, cwd=REPO).stdout
    assert 'simulate' in out and 'detect' in out and 'bench' not in out


ROS_NODE_NAMES = ('telemetry_replay', 'llr_detector', 'vsadc_detector', 'fss_diagnoser',
                  'basilisk_bus', 'recorder', 'foxglove_bridge')


@pytest.mark.slow
def test_colcon_build_installs_console_scripts_where_ros2_run_looks(tmp_path):
    colcon = pathlib.Path(sys.executable).parent / 'colcon'
    if not colcon.exists():
        colcon = shutil.which('colcon')
    assert colcon, 'colcon-common-extensions is in requirements.txt'
    copy_sources(tmp_path / 'ws' / 'src' / 'rwa_monitor')
    env = dict(os.environ, PATH=f'{pathlib.Path(sys.executable).parent}:{os.environ["PATH"]}')
    result = subprocess.run([str(colcon), 'build', '--packages-select', 'rwa_monitor'],
                            cwd=tmp_path / 'ws', capture_output=True, text=True, env=env,
                            timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    install = tmp_path / 'ws' / 'install' / 'rwa_monitor'
    lib = install / 'lib' / 'rwa_monitor'
    scripts = {p.name for p in lib.iterdir()}
    assert {'rwa-monitor', 'rwa-monitor-replay', 'rwa-monitor-llr', 'rwa-monitor-vsadc',
            'rwa-monitor-fss', 'rwa-monitor-bus', 'rwa-monitor-record',
            'rwa-monitor-foxglove'} <= scripts
    # `ros2 run rwa_monitor NAME` runs lib/rwa_monitor/NAME: each node under its own name
    for node in ROS_NODE_NAMES:
        assert node in scripts, node
        assert os.access(lib / node, os.X_OK), node
    # the installed executables run from the install space, as ros2 run starts them after
    # `source install/setup.bash` (which puts the install's site-packages first)
    (site,) = install.glob('lib/python3*/site-packages')
    # rosdep brings the dependencies (package.xml): the metadata names none of pip's
    (requires,) = site.glob('rwa_monitor-*.egg-info/requires.txt')
    assert requires.read_text().split() == ['setuptools']
    sourced = dict(env, PYTHONPATH=os.pathsep.join(
        [str(site)] + [p for p in [os.environ.get('PYTHONPATH')] if p]))
    for node in ('llr_detector', 'foxglove_bridge'):
        run = subprocess.run([str(lib / node), '--help'], capture_output=True, text=True,
                             env=sourced, timeout=120, cwd=tmp_path)
        assert run.returncode == 0 and 'parameters' in run.stdout, run.stderr
    share = install / 'share' / 'rwa_monitor'
    assert (share / 'package.xml').is_file()
    assert (share / 'config' / 'rwa_monitor.yaml').is_file()
    marker = install / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'rwa_monitor'
    assert marker.is_file()


def test_benchmarks_live_outside_the_installed_package():
    out = subprocess.run([sys.executable, '-m', 'bench', '--help'], capture_output=True,
                         text=True, check=True, cwd=REPO).stdout
    assert 'llr' in out and 'identify' in out
    import rwa_monitor
    assert not (pathlib.Path(rwa_monitor.__file__).parent / 'bench').exists()
