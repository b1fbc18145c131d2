"""Telemetry as MCAP files in the rosbag2 layout (profile ``ros2``, CDR payloads).

One channel per topic of the replay node (DESIGN.md): ``/telemetry/wheels``
(sensor_msgs/JointState), ``/telemetry/gyro`` (sensor_msgs/Imu),
``/telemetry/star_tracker`` (geometry_msgs/QuaternionStamped),
``/telemetry/reference_rate`` (geometry_msgs/Vector3Stamped), each message stamped with
the telemetry time (also the MCAP log time). Auxiliary and truth columns, which have no
ROS message of their own, go on ``/rwa_monitor/columns`` as a JointState whose ``name``
lists the column names (truth columns with their ``truth_`` prefix) and ``position``
holds the values. Payloads are serialised by ``rclpy.serialization``; each schema carries
the ``ros2msg`` definition text when the message definitions are installed.

Reading takes the sample times from the first channel present in the order above; every
other channel must carry the same stamps (a bag recorded from this package's replay
does), otherwise a TelemetrySchemaError names the file and the topic.
"""

from __future__ import annotations

import os
import pathlib
import sys
from typing import Any

from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.nodes import messages
from rwa_monitor.telemetry.schema import Telemetry, TRUTH_PREFIX, Wheel

WHEELS = '/telemetry/wheels'
GYRO = '/telemetry/gyro'
STAR_TRACKER = '/telemetry/star_tracker'
REFERENCE = '/telemetry/reference_rate'
COLUMNS = '/rwa_monitor/columns'
TYPES = {WHEELS: ('sensor_msgs/msg/JointState', JointState),
         GYRO: ('sensor_msgs/msg/Imu', Imu),
         STAR_TRACKER: ('geometry_msgs/msg/QuaternionStamped', QuaternionStamped),
         REFERENCE: ('geometry_msgs/msg/Vector3Stamped', Vector3Stamped),
         COLUMNS: ('sensor_msgs/msg/JointState', JointState)}
_SEPARATOR = '=' * 80


def write(path: str | os.PathLike, tele: Telemetry) -> None:
    """Write ``tele`` as an MCAP file (one message per row and channel present)."""
    from mcap.writer import Writer
    extra = {**tele.aux, **{TRUTH_PREFIX + k: v for k, v in tele.truth.items()}}
    rows = {
        WHEELS: _wheel_messages(tele) if tele.wheels else None,
        GYRO: None if tele.gyro is None else
        (messages.imu(t, v) for t, v in zip(tele.time.tolist(), tele.gyro.tolist())),
        STAR_TRACKER: None if tele.attitude is None else
        (messages.quaternion(t, v) for t, v in zip(tele.time.tolist(), tele.attitude.tolist())),
        REFERENCE: None if tele.reference_rate is None else
        (messages.vector3(t, v) for t, v in
         zip(tele.time.tolist(), tele.reference_rate.tolist())),
        COLUMNS: _column_messages(tele.time, extra) if extra else None,
    }
    with open(path, 'wb') as handle:
        writer = Writer(handle)
        writer.start(profile='ros2', library='rwa_monitor')
        channels = {}
        for topic, source in rows.items():
            if source is None:
                continue
            type_name = TYPES[topic][0]
            schema = writer.register_schema(type_name, 'ros2msg',
                                            _definition(type_name).encode())
            channels[topic] = (writer.register_channel(topic, 'cdr', schema), source)
        stamps = [int(round(t * 1e9)) for t in tele.time.tolist()]
        iterators = {topic: iter(source) for topic, (_, source) in channels.items()}
        for row, stamp in enumerate(stamps):
            for topic, (channel_id, _) in channels.items():
                writer.add_message(channel_id, log_time=stamp, publish_time=stamp,
                                   sequence=row,
                                   data=serialize_message(next(iterators[topic])))
        writer.finish()


def _wheel_messages(tele: Telemetry) -> Any:
    names = list(tele.wheels)
    speed = np.column_stack([w.speed for w in tele.wheels.values()]).tolist()
    nan = np.full(len(tele), np.nan)
    friction = np.column_stack([nan if w.friction is None else w.friction
                                for w in tele.wheels.values()]).tolist()
    for i, t in enumerate(tele.time.tolist()):
        yield messages.joint_state(t, names, speed[i], friction[i])


def _column_messages(time: np.ndarray, columns: dict[str, np.ndarray]) -> Any:
    names = list(columns)
    table = np.column_stack([np.asarray(c, dtype=float) for c in columns.values()]).tolist()
    for t, values in zip(time.tolist(), table):
        msg = JointState(name=names, position=values)
        msg.header.stamp = messages.to_stamp(t)
        yield msg


def read(path: str | os.PathLike) -> Telemetry:
    """Read an MCAP telemetry file; TelemetrySchemaError names the file and topic."""
    from mcap.reader import make_reader
    path = os.fspath(path)
    if not os.path.exists(path):
        raise TelemetrySchemaError(path, 'no such file')
    by_topic: dict[str, list[Any]] = {topic: [] for topic in TYPES}
    try:
        with open(path, 'rb') as handle:
            for _, channel, message in make_reader(handle).iter_messages():
                if channel.topic in TYPES:
                    by_topic[channel.topic].append(
                        deserialize_message(message.data, TYPES[channel.topic][1]))
    except TelemetrySchemaError:
        raise
    except Exception as err:  # noqa: BLE001 - any decoding failure is a bad file
        raise TelemetrySchemaError(path, f'not a readable MCAP file: {err}') from None
    base = next((t for t in (WHEELS, GYRO, STAR_TRACKER, REFERENCE) if by_topic[t]), None)
    if base is None:
        raise TelemetrySchemaError(path, 'no telemetry topic (expected one of '
                                   f'{WHEELS}, {GYRO}, {STAR_TRACKER}, {REFERENCE})')
    stamps = [(m.header.stamp.sec, m.header.stamp.nanosec) for m in by_topic[base]]
    time = np.array([messages.to_seconds(m.header.stamp) for m in by_topic[base]])
    for topic, msgs in by_topic.items():
        if msgs and [(m.header.stamp.sec, m.header.stamp.nanosec) for m in msgs] != stamps:
            raise TelemetrySchemaError(path, f'stamps of {topic} differ from those of {base}',
                                       column=topic)
    if np.any(np.diff(time) <= 0):
        raise TelemetrySchemaError(path, f'stamps of {base} are not strictly increasing',
                                   column=base)
    tele = Telemetry(time=time, source=path)
    if by_topic[WHEELS]:
        tele.wheels = _wheels(by_topic[WHEELS])
    if by_topic[GYRO]:
        tele.gyro = np.array([[m.angular_velocity.x, m.angular_velocity.y,
                               m.angular_velocity.z] for m in by_topic[GYRO]])
    if by_topic[STAR_TRACKER]:
        tele.attitude = np.array([[m.quaternion.x, m.quaternion.y, m.quaternion.z,
                                   m.quaternion.w] for m in by_topic[STAR_TRACKER]])
    if by_topic[REFERENCE]:
        tele.reference_rate = np.array([[m.vector.x, m.vector.y, m.vector.z]
                                        for m in by_topic[REFERENCE]])
    for name, values in _named_columns(by_topic[COLUMNS], 'position').items():
        if name.startswith(TRUTH_PREFIX):
            tele.truth[name[len(TRUTH_PREFIX):]] = values
        else:
            tele.aux[name] = values
    return tele


def _named_columns(msgs: list[Any], field: str) -> dict[str, np.ndarray]:
    """Return name -> values over messages whose name lists may vary (missing -> NaN)."""
    order: dict[str, int] = {}
    for msg in msgs:
        for name in msg.name:
            order.setdefault(name, len(order))
    table = np.full((len(msgs), len(order)), np.nan)
    for row, msg in enumerate(msgs):
        values = getattr(msg, field)
        for name, value in zip(msg.name, values):
            table[row, order[name]] = value
    return {name: table[:, col] for name, col in order.items()}


def _wheels(msgs: list[Any]) -> dict[str, Wheel]:
    speeds = _named_columns(msgs, 'velocity')
    frictions = _named_columns(msgs, 'effort')
    return {name: Wheel(speeds[name], frictions.get(name)) for name in speeds}


def _share_dirs() -> list[pathlib.Path]:
    dirs = [pathlib.Path(p) / 'share' for p in
            os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    return dirs + [pathlib.Path(sys.prefix) / 'share']


def _definition(type_name: str) -> str:
    """Return the ros2msg definition text of ``pkg/msg/Type`` with its dependencies.

    Empty when the ``.msg`` files are not installed (readers of this package do not need
    it; other tools then show raw CDR).
    """
    done: set[str] = set()
    parts: list[str] = []

    def add(full: str, top: bool) -> bool:
        pkg, _, name = full.split('/')
        for share in _share_dirs():
            msg_file = share / pkg / 'msg' / f'{name}.msg'
            if msg_file.is_file():
                break
        else:
            return False
        text = msg_file.read_text()
        parts.append(text if top else f'{_SEPARATOR}\nMSG: {pkg}/{name}\n{text}')
        done.add(full)
        for dep in _dependencies(text, pkg):
            if dep not in done and not add(dep, False):
                return False
        return True

    return '\n'.join(parts) if add(type_name, True) else ''


_PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16',
               'uint16', 'int32', 'uint32', 'int64', 'uint64', 'string', 'wstring'}


def _dependencies(text: str, pkg: str) -> list[str]:
    deps = []
    for line in text.splitlines():
        line = line.split('#', 1)[0].strip()
        if not line:
            continue
        declared = line.split()[0]
        field_type = declared.split('[')[0].split('<=')[0]
        if field_type in _PRIMITIVES or '=' in line[len(declared):]:
            continue
        if field_type == 'Header':
            field_type = 'std_msgs/Header'
        dep_pkg, _, name = field_type.rpartition('/')
        deps.append(f'{dep_pkg or pkg}/msg/{name}')
    return deps
