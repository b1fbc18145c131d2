"""rwa_monitor: reaction-wheel and attitude-sensor health monitoring for ROS 2 Jazzy."""

__version__ = '0.1.0'
