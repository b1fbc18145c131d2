"""The message codecs, re-exported for the nodes (they live in rwa_monitor.telemetry.codecs).

The file readers and writers of the telemetry layer use the same codecs, so they sit
below the nodes layer; this module keeps the nodes' import path.
"""

from rwa_monitor.telemetry.codecs import (  # noqa: F401
    BadMessage, clock, decode_joint_state, decode_stamped, encode_joint_state, ERROR_KINDS,
    event_level, event_status, format_value, imu, IMU_ANGULAR_VELOCITY, imu_codec,
    joint_state, JointStateCodec, key_values, parse_value, quaternion, quaternion_codec,
    samples_of, split_seconds, STAMPED_SIZES, StampedCodec, status_event, status_fields,
    to_seconds, to_stamp, vector3, vector3_codec, wheel_name_problems, wheel_samples)
