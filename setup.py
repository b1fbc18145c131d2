"""Install rwa_monitor: an ament_python package that also installs standalone with pip."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'rwa_monitor'

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
    package_data={package_name: ['config/*.yaml', 'data/*']},
    install_requires=['setuptools'],
    extras_require={'bsk': ['bsk']},
    zip_safe=True,
    maintainer='rwa_monitor maintainers',
    maintainer_email='rwa-monitor@example.org',
    description='Reaction-wheel and attitude-sensor anomaly detection for ROS 2 Jazzy.',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'rwa-monitor = rwa_monitor.cli.main:main',
            'rwa-monitor-replay = rwa_monitor.nodes.replay:main',
            'rwa-monitor-llr = rwa_monitor.nodes.llr_detector:main',
            'rwa-monitor-vsadc = rwa_monitor.nodes.vsadc_detector:main',
            'rwa-monitor-fss = rwa_monitor.nodes.fss_diagnoser:main',
            'rwa-monitor-bus = rwa_monitor.nodes.basilisk_bus:main',
            'rwa-monitor-record = rwa_monitor.nodes.recorder:main',
            'rwa-monitor-foxglove = rwa_monitor.nodes.foxglove_bridge:main',
            'rwa-monitor-monitor = rwa_monitor.nodes.monitor:main',
        ],
    },
)
