"""Launch the telemetry replay and the LLR detector with the shipped parameters.

    ros2 launch rwa_monitor rwa_monitor.launch.py file:=/path/telemetry.csv rate:=40.0

Launch is not installable from PyPI wheels: outside a ROS 2 install, run the console
scripts (`rwa-monitor-replay`, `rwa-monitor-llr`) or `rwa-monitor demo` instead.
"""

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    params = os.path.join(get_package_share_directory('rwa_monitor'), 'config',
                          'rwa_monitor.yaml')
    file_arg = DeclareLaunchArgument('file', description='telemetry file (.csv or .mcap)')
    rate_arg = DeclareLaunchArgument('rate', default_value='1.0',
                                     description='time factor; 0.0 = as fast as possible')
    params_arg = DeclareLaunchArgument('params_file', default_value=params,
                                       description='parameter file')
    replay = Node(
        package='rwa_monitor', executable='telemetry_replay', name='telemetry_replay',
        parameters=[LaunchConfiguration('params_file'),
                    {'file': LaunchConfiguration('file'),
                     'rate': LaunchConfiguration('rate')}],
        output='screen')
    detector = Node(
        package='rwa_monitor', executable='llr_detector', name='llr_detector',
        parameters=[LaunchConfiguration('params_file')], output='screen')
    return LaunchDescription([file_arg, rate_arg, params_arg, detector, replay])
