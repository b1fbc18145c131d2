"""Install rwa_monitor: an ament_python package that also installs standalone with pip.

``install_requires`` and ``extras_require`` declare what pip needs, as compatible ranges
(docs/install.md says why they depart from the ROS habit of ``setuptools`` only, and why
colcon and rosdep users are unaffected); requirements.txt pins the tested set inside
them (test/test_dependencies.py checks that the two agree). Rule of the ranges: from the
tested minor release up to the next major one, or to the next minor one for releases
below 1.0, whose minor releases may change their API.

colcon (ament_python) installs the package with ``setup.py install`` or ``develop``; pip
and every other PEP 517 front end build a wheel. Under those two commands the metadata
keeps the ROS habit (``setuptools`` only): a ROS install takes its dependencies from
package.xml through rosdep (Debian packages of other versions, ROS packages without pip
metadata), and declared pip requirements would make any ``pkg_resources`` import in a
node fail its check of the console script's ``__requires__``.
"""
from glob import glob
import sys

from setuptools import Extension, find_packages, setup

package_name = 'rwa_monitor'

# ROS 2 Jazzy from PyPI wheels: a ROS install brings these through package.xml instead.
ROS_WHEELS = [
    'ros-jazzy-rclpy[fastrtps]>=7.1,<8',
    'ros-jazzy-std-msgs>=5.3,<6',
    'ros-jazzy-sensor-msgs>=5.3,<6',
    'ros-jazzy-geometry-msgs>=5.3,<6',
    'ros-jazzy-diagnostic-msgs>=5.3,<6',
    'ros-jazzy-std-srvs>=5.3,<6',
]
INSTALL_REQUIRES = ROS_WHEELS + [
    'numpy>=2.4,<3',
    'scipy>=1.17,<2',
    'numba>=0.68,<0.69',
    'scikit-learn>=1.9,<2',
    'threadpoolctl>=3.8,<4',
    # requirements-bsk.txt moves matplotlib to 3.10 for the simulation bus
    'matplotlib>=3.10,<4',
    'PyYAML>=6.0,<7',
    'mcap>=1.6,<2',
    'mcap-ros2-support>=0.6,<0.7',
    'rosbags>=0.11.9,<0.12',
    # CCSDS space packets in XTCE (telemetry/ccsds.py): reference decoder, safe XML
    'space-packet-parser>=6.2,<7',
    'lxml>=6.1,<7',
]
EXTRAS_REQUIRE = {
    # the spacecraft simulation bus (rwa-monitor-bus, simulate basilisk)
    'bsk': ['bsk>=2.12,<3'],
    # the live view (rwa-monitor-foxglove): the SDK's server and the WebSocket front
    'foxglove': ['foxglove-sdk>=0.30.3,<0.31', 'websockets>=17.4,<18',
                 'cryptography>=50.0,<51'],
    # the operator's view server (rwa-monitor openmct); Open MCT itself comes from npm
    'openmct': ['tornado>=6.6,<7'],
    # the fleet engine
    'fleet': ['dask>=2026.8,<2027', 'distributed>=2026.8,<2027', 'pyarrow>=26.0,<27'],
    # tests, lint and benchmarks
    'dev': ['pytest>=9.2,<10', 'pytest-timeout>=2.4,<3', 'pytest-xdist>=3.8,<4',
            'hypothesis>=6.170,<7',
            'import-linter>=2.16,<3', 'flake8>=7.5,<8', 'flake8-quotes>=3.4,<4',
            'flake8-docstrings>=1.7,<2', 'flake8-import-order>=0.19.2,<0.20',
            'pydocstyle>=6.3,<7', 'mpmath>=1.3,<2', 'ruptures>=1.1,<2',
            'river>=0.26.1,<0.27', 'colcon-common-extensions>=0.3.0,<0.4',
            'py-spy>=0.4.3,<0.5', 'playwright>=1.65,<2', 'yamcs-pymdb>=1.4,<2'],
}

ROS_BUILD = bool({'install', 'develop'} & set(sys.argv[1:]))

# Each node as ``ros2 run rwa_monitor NODE_NAME`` runs it, and as a pip user's command.
NODES = {
    'telemetry_replay': ('rwa-monitor-replay', 'replay'),
    'llr_detector': ('rwa-monitor-llr', 'llr_detector'),
    'vsadc_detector': ('rwa-monitor-vsadc', 'vsadc_detector'),
    'fss_diagnoser': ('rwa-monitor-fss', 'fss_diagnoser'),
    'basilisk_bus': ('rwa-monitor-bus', 'basilisk_bus'),
    'recorder': ('rwa-monitor-record', 'recorder'),
    'foxglove_bridge': ('rwa-monitor-foxglove', 'foxglove_bridge'),
    'monitor': ('rwa-monitor-monitor', 'monitor'),
}
CONSOLE_SCRIPTS = ['rwa-monitor = rwa_monitor.cli.main:main'] + [
    f'{name} = rwa_monitor.nodes.{module}:main'
    for node, (script, module) in NODES.items() for name in (script, node)]

# The one C call per streaming sample (docs/llr.md "Streaming call"); optional: without a C
# compiler the package installs and the detector runs its compiled step from Python.
EXT_MODULES = [Extension('rwa_monitor.core._stepcall', ['rwa_monitor/core/_stepcall.c'],
                         optional=True),
               # the packet walk (telemetry/_packetwalk.c); without it numba compiles it
               Extension('rwa_monitor.telemetry._packetwalk',
                         ['rwa_monitor/telemetry/_packetwalk.c'], optional=True)]

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'bench', 'bench.*']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.json')),
        ('share/' + package_name + '/launch', glob('launch/*.py')),
    ],
    # the operator's view: its page and plugin, and the npm lock of Open MCT (the bundle
    # itself is installed by `make openmct` or `rwa-monitor openmct --install`)
    package_data={package_name: ['config/*.yaml', 'data/*', 'openmct/web/*',
                                 'openmct/npm/package.json', 'openmct/npm/package-lock.json']},
    python_requires='>=3.11',
    install_requires=['setuptools'] if ROS_BUILD else INSTALL_REQUIRES,
    extras_require={} if ROS_BUILD else EXTRAS_REQUIRE,
    ext_modules=EXT_MODULES,
    zip_safe=True,
    maintainer='rwa_monitor maintainers',
    maintainer_email='rwa-monitor@example.org',
    description='Reaction-wheel and attitude-sensor anomaly detection for ROS 2 Jazzy.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={'console_scripts': CONSOLE_SCRIPTS},
)
