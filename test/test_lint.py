"""Lint as ROS packages do: flake8 with the ament settings (setup.cfg) and pep257."""

import subprocess
import sys

from conftest import REPO


def test_flake8_and_pep257():
    targets = [t for t in ('rwa_monitor', 'bench', 'test', 'setup.py', 'launch')
               if (REPO / t).exists()]
    result = subprocess.run([sys.executable, '-m', 'flake8', *targets], cwd=REPO,
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
