"""A clean virtual environment with ``pip install CLONE[EXTRAS]``, built once per test run.

Shared by test_pip_install.py and test_docs_commands.py: the first test that needs it
builds it (a copy of the sources as a clone holds them, a new venv without system
site-packages, pip with the machine's configuration, ``pip check``); the others, in this
process or in another pytest-xdist worker of the same run, wait on a lock and reuse it.
"""

import fcntl
import os
import subprocess
import sys

import pytest
from test_package import copy_sources

# pip's words for an index it cannot reach (then the test is skipped, saying so)
UNREACHABLE = ('NewConnectionError', 'Network is unreachable', 'Temporary failure in name '
               'resolution', 'Max retries exceeded', 'ConnectTimeout', 'ProxyError')


def run(args, env, cwd, timeout=600):
    """Run ``args``; return the completed process (output captured as text)."""
    return subprocess.run(args, env=env, cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def clean_env():
    """Return the environment without this venv's traces (PYTHONPATH, VIRTUAL_ENV)."""
    return {k: v for k, v in os.environ.items()
            if k not in ('PYTHONPATH', 'VIRTUAL_ENV', 'PYTHONHOME')}


def clean_install(tmp_path_factory, extras=''):
    """Return (bin folder, env) of the clean venv holding ``CLONE[extras]``.

    It lives in this run's temporary root (shared by the xdist workers of the run, kept
    and removed by pytest's own retention of temporary folders).
    """
    base = tmp_path_factory.getbasetemp()
    if os.environ.get('PYTEST_XDIST_WORKER'):
        base = base.parent
    root = base / f'pip_{extras.replace(",", "_") or "base"}'
    root.mkdir(exist_ok=True)
    env = clean_env()
    venv = root / 'venv'
    with open(root / 'lock', 'w') as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        done = root / 'installed'
        if not done.exists():
            if (root / 'clone').exists():
                subprocess.run(['rm', '-rf', str(root / 'clone'), str(venv)], check=True)
            copy_sources(root / 'clone')
            subprocess.run([sys.executable, '-m', 'venv', str(venv)], check=True, timeout=300)
            python = str(venv / 'bin' / 'python')
            target = str(root / 'clone') + (f'[{extras}]' if extras else '')
            install = run([python, '-m', 'pip', 'install', '--quiet', target], env, root,
                          timeout=1500)
            log = install.stdout[-4000:] + install.stderr[-4000:]
            if install.returncode != 0 and any(word in log for word in UNREACHABLE):
                pytest.skip(f'the package index is unreachable from here: {log[-600:]}')
            assert install.returncode == 0, log
            check = run([python, '-m', 'pip', 'check'], env, root)
            assert check.returncode == 0, check.stdout + check.stderr
            done.write_text('ok\n')
    env['PATH'] = f'{venv / "bin"}{os.pathsep}{env["PATH"]}'
    return venv / 'bin', env
