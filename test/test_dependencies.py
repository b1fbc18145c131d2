"""setup.py's ranges, requirements.txt's pins and package.xml's rosdep keys agree."""

import os
import re
import runpy
import sys
from unittest import mock
import xml.etree.ElementTree as ET

from conftest import REPO
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name
from packaging.version import Version
import pytest

# A dependency pip installs -> its rosdep key (ROS message wheels -> the ROS package).
ROSDEP_KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'numba': 'python3-numba',
    'scikit-learn': 'python3-sklearn', 'matplotlib': 'python3-matplotlib',
    'pyyaml': 'python3-yaml', 'rosbags': 'python3-rosbags-pip',
    'mcap-ros2-support': 'mcap-ros2-support', 'websockets': 'python3-websockets',
    'cryptography': 'python3-cryptography',
    'lxml': 'python3-lxml',
}
# Without a rosdep key: package.xml's comments name each (and what brings it in).
NO_ROSDEP_KEY = {'threadpoolctl', 'mcap', 'foxglove-sdk', 'space-packet-parser'}


def setup_kwargs(*argv):
    """Return the keyword arguments setup.py gives to setup() when run with ``argv``."""
    here = os.getcwd()
    os.chdir(REPO)  # setup.py globs its data files relative to the repository
    try:
        with mock.patch('setuptools.setup') as setup, \
                mock.patch.object(sys, 'argv', ['setup.py', *argv]):
            runpy.run_path('setup.py', run_name='__main__')
    finally:
        os.chdir(here)
    return setup.call_args.kwargs


@pytest.fixture(scope='module')
def declared():
    """Return setup()'s arguments as pip's build of a wheel sees them."""
    return setup_kwargs('bdist_wheel', '--dist-dir', 'dist')


def _pins(name):
    pins = {}
    for line in (REPO / name).read_text().splitlines():
        line = line.split('#', 1)[0].strip()
        if line:
            req = Requirement(line)
            (spec,) = req.specifier
            assert spec.operator == '==', f'{name}: {line} is not a pin'
            pins[canonicalize_name(req.name)] = (req, Version(spec.version))
    return pins


def _groups(declared):
    yield 'install_requires', [Requirement(r) for r in declared['install_requires']]
    for extra, reqs in declared['extras_require'].items():
        yield extra, [Requirement(r) for r in reqs]


def test_every_declared_dependency_is_pinned_inside_its_range(declared):
    locks = {'requirements.txt': _pins('requirements.txt'),
             'requirements-bsk.txt': _pins('requirements-bsk.txt')}
    for group, reqs in _groups(declared):
        lock = locks['requirements-bsk.txt' if group == 'bsk' else 'requirements.txt']
        for req in reqs:
            name = canonicalize_name(req.name)
            assert name in lock, f'{group}: {req} is not pinned'
            pinned, version = lock[name]
            assert req.specifier.contains(version), f'{group}: pin {pinned} outside {req}'
            assert req.extras == pinned.extras, f'{group}: {req} vs {pinned}'
    # the simulation bus's lock moves matplotlib: still inside the package's range
    core = {canonicalize_name(r.name): r for r in dict(_groups(declared))['install_requires']}
    for name, (pinned, version) in locks['requirements-bsk.txt'].items():
        if name in core:
            assert core[name].specifier.contains(version), f'{pinned} outside {core[name]}'


def test_every_pin_belongs_to_a_declared_group(declared):
    names = {canonicalize_name(r.name) for _, reqs in _groups(declared) for r in reqs}
    undeclared = set(_pins('requirements.txt')) - names
    assert not undeclared, f'pinned in requirements.txt but in no group of setup.py: {undeclared}'


def test_ranges_run_from_the_tested_minor_to_the_next_breaking_release(declared):
    tested = {}  # name -> the versions pinned in either lock
    for lock in ('requirements.txt', 'requirements-bsk.txt'):
        for name, (_, version) in _pins(lock).items():
            tested.setdefault(name, []).append(version)
    for group, reqs in _groups(declared):
        for req in reqs:
            lower = [Version(s.version) for s in req.specifier if s.operator == '>=']
            upper = [Version(s.version) for s in req.specifier if s.operator == '<']
            assert len(lower) == len(upper) == 1 == len(req.specifier) - 1, f'{group}: {req}'
            oldest, newest = min(tested[canonicalize_name(req.name)]), max(
                tested[canonicalize_name(req.name)])
            assert lower[0].release[:2] == oldest.release[:2] and lower[0] <= oldest, req
            major, minor = newest.release[:2]
            expected = Version(f'{major + 1}') if major else Version(f'0.{minor + 1}')
            assert upper[0] == expected, f'{group}: {req} should end below {expected}'


def test_extras_name_the_optional_parts(declared):
    assert set(declared['extras_require']) == {'bsk', 'foxglove', 'fleet', 'dev', 'openmct'}
    core = {canonicalize_name(Requirement(r).name) for r in declared['install_requires']}
    assert {'foxglove-sdk', 'bsk', 'dask', 'pytest', 'tornado', 'playwright'}.isdisjoint(core)


def test_package_xml_lists_each_runtime_dependency_with_its_rosdep_key(declared):
    text = (REPO / 'package.xml').read_text()
    root = ET.fromstring(text)
    exec_keys = {e.text for e in root.iter('exec_depend')}
    comments = ' '.join(re.findall(r'<!--(.*?)-->', text, re.S))
    runtime = declared['install_requires'] + declared['extras_require']['foxglove']
    for req in map(Requirement, runtime):
        name = canonicalize_name(req.name)
        if name.startswith('ros-jazzy-'):
            key = name.removeprefix('ros-jazzy-').replace('-', '_')
        elif name in NO_ROSDEP_KEY:
            assert re.search(rf'\b{re.escape(name)}\b', comments), f'{name}: say why no key'
            continue
        else:
            assert name in ROSDEP_KEYS, f'{name}: which rosdep key? (or list it without one)'
            key = ROSDEP_KEYS[name]
        assert key in exec_keys, f'package.xml has no <exec_depend>{key}</exec_depend>'


def test_every_node_is_installed_under_its_node_name_and_its_command(declared):
    scripts = dict(s.replace(' ', '').split('=') for s in
                   declared['entry_points']['console_scripts'])
    for module in (REPO / 'rwa_monitor' / 'nodes').glob('*.py'):
        found = re.search(r"^NODE_NAME = '(\w+)'$", module.read_text(), re.M)
        if found is None:
            continue
        target = f'rwa_monitor.nodes.{module.stem}:main'
        assert scripts.get(found.group(1)) == target, found.group(1)
        commands = [s for s, t in scripts.items() if t == target and s.startswith('rwa-monitor-')]
        assert len(commands) == 1, (module.stem, commands)
    # rwa-monitor, and each node and the one-process monitor under two names
    assert len(scripts) == 1 + 2 * 8
    assert scripts['monitor'] == scripts['rwa-monitor-monitor'] == 'rwa_monitor.nodes.monitor:main'


@pytest.mark.parametrize('argv', [
    ('egg_info', '--egg-base', 'b', 'build', '--build-base', 'b', 'install', '--prefix', 'p',
     '--single-version-externally-managed'),                     # colcon build
    ('develop', '--editable', '--build-directory', 'b', '--no-deps'),  # --symlink-install
])
def test_a_colcon_build_keeps_the_ros_style_metadata(argv, declared):
    ros = setup_kwargs(*argv)
    assert ros['install_requires'] == ['setuptools'] and ros['extras_require'] == {}
    assert ros['entry_points'] == declared['entry_points']
    assert setup_kwargs('egg_info')['install_requires'] == declared['install_requires']
