"""Shared test fixtures."""

import os
import pathlib

import pytest

REPO = pathlib.Path(__file__).resolve().parents[1]
SHARED = REPO.parent / 'shared'

# Every ROS test stays on this machine (CONVENTIONS.md).
os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')


def pytest_configure(config):
    """Under ``-n N`` compile the kernels once, here, before the workers start.

    Importing the kernel modules compiles their kernels or loads them from numba's cache
    (``cache=True``: rwa_monitor/core/__pycache__, writes atomic per file), and so does
    the streaming call's cfunc. On a fresh clone the workers would otherwise each compile
    the same kernels at the same time.
    """
    if getattr(config.option, 'numprocesses', None) and not hasattr(config, 'workerinput'):
        import rwa_monitor.core.llr_calibrated_step  # noqa: F401
        import rwa_monitor.core.llr_kernel  # noqa: F401
        from rwa_monitor.core import llr_cstep
        llr_cstep.step_address()     # the streaming call's cfunc (cache=True) too


@pytest.fixture
def repo_root() -> pathlib.Path:
    return REPO
