"""The package builds the way a real ROS 2 install does, and its parts import cleanly."""

import os
import pathlib
import shutil
import subprocess
import sys

from conftest import REPO
import pytest


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


@pytest.mark.slow
def test_colcon_build_installs_console_scripts_where_ros2_run_looks(tmp_path):
    colcon = pathlib.Path(sys.executable).parent / 'colcon'
    if not colcon.exists():
        colcon = shutil.which('colcon')
    assert colcon, 'colcon-common-extensions is in requirements.txt'
    src = tmp_path / 'ws' / 'src' / 'rwa_monitor'
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(
        '.venv*', '.git', 'build', 'install', 'log', 'bench', '*.egg-info', '__pycache__'))
    env = dict(os.environ, PATH=f'{pathlib.Path(sys.executable).parent}:{os.environ["PATH"]}')
    result = subprocess.run([str(colcon), 'build', '--packages-select', 'rwa_monitor'],
                            cwd=tmp_path / 'ws', capture_output=True, text=True, env=env,
                            timeout=600)
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-3000:]
    install = tmp_path / 'ws' / 'install' / 'rwa_monitor'
    scripts = {p.name for p in (install / 'lib' / 'rwa_monitor').iterdir()}
    assert {'rwa-monitor', 'rwa-monitor-replay', 'rwa-monitor-llr', 'rwa-monitor-vsadc',
            'rwa-monitor-fss', 'rwa-monitor-bus'} <= scripts
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
