"""The recording topics of the telemetry streams (docs/contracts.md), without the readers.

A module of its own so that a command's options name the default topics without
importing the recording reader and its ROS message types (rosbag_io).
"""

DEFAULT_TOPICS = {'wheels': '/telemetry/wheels', 'gyro': '/telemetry/gyro',
                  'star_tracker': '/telemetry/star_tracker',
                  'reference_rate': '/telemetry/reference_rate'}
