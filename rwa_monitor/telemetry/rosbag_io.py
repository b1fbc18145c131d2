"""Telemetry recordings: rosbag2 directories and bare ``.mcap`` / ``.db3`` files.

Read and written through the ``rosbags`` library with its ROS 2 Jazzy type store. One
topic per stream (DESIGN.md names by default, others with ``--topics``): ``wheels``
(sensor_msgs/JointState: name = wheel ids, velocity = rad/s, effort = friction N m),
``gyro`` (sensor_msgs/Imu), ``star_tracker`` (geometry_msgs/QuaternionStamped),
``reference_rate`` (geometry_msgs/Vector3Stamped). Auxiliary and truth columns, which
have no ROS message of their own, go on ``/rwa_monitor/columns`` as a JointState whose
``name`` lists the column names (truth columns with their ``truth_`` prefix) and whose
``position`` holds the values.

Each stream keeps its own stamps (``header.stamp``, the telemetry time; the bag's
receive time is not used): the record's ``time`` is the union of the stamps and
``Telemetry.present`` marks each stream's rows (docs/contracts.md, multi-rate recordings).

Payloads are written in canonical CDR (an empty sequence is its count alone, nothing
after the last field), so files are byte-identical across runs with the same input.
Reading accepts canonical CDR and what rclpy writes (up to 8 bytes of uninitialised
padding after a JointState ending in empty sequences): a JointState the type store
refuses is read by the package's decoder, which allows that padding (telemetry/codecs.py).
"""

from __future__ import annotations

import os
import pathlib
from typing import Any, Callable, Iterable, Mapping

import numpy as np

from rwa_monitor.exceptions import ConfigError, OutputError, TelemetrySchemaError
from rwa_monitor.telemetry import codecs
from rwa_monitor.telemetry.atomic import install_file, work_folder
from rwa_monitor.telemetry.recording_folder import recording_output
from rwa_monitor.telemetry.schema import name_problem, Telemetry, TRUTH_PREFIX, Wheel
from rwa_monitor.telemetry.topics import DEFAULT_TOPICS
from rwa_monitor.telemetry.yaml_file import read_yaml

# Stream -> default topic (DESIGN.md topic names, absolute as a recorder stores them).
COLUMNS_TOPIC = '/rwa_monitor/columns'
MSG_TYPES = {'wheels': 'sensor_msgs/msg/JointState', 'gyro': 'sensor_msgs/msg/Imu',
             'star_tracker': 'geometry_msgs/msg/QuaternionStamped',
             'reference_rate': 'geometry_msgs/msg/Vector3Stamped',
             'columns': 'sensor_msgs/msg/JointState'}
BAG_SUFFIXES = ('.mcap', '.db3')
_FRAME = 'body'


def typestore() -> Any:
    """Return the ROS 2 Jazzy type store of rosbags (built once)."""
    global _STORE
    if _STORE is None:
        from rosbags.typesys import get_typestore, Stores
        _STORE = get_typestore(Stores.ROS2_JAZZY)
    return _STORE


_STORE = None


def parse_topics(text: str | Mapping[str, str] | None) -> dict[str, str]:
    """Return stream -> topic from ``wheels=/a,gyro=/b,...`` (unnamed streams: defaults).

    Raise ConfigError naming an unknown stream or a malformed item.
    """
    topics = dict(DEFAULT_TOPICS)
    if not text:
        return topics
    items = text.items() if isinstance(text, Mapping) else (
        item.split('=', 1) if '=' in item else (item, '')
        for item in str(text).split(',') if item.strip())
    for stream, topic in items:
        stream, topic = stream.strip(), topic.strip()
        if stream not in DEFAULT_TOPICS:
            raise ConfigError(f'topics: unknown stream {stream!r} (expected '
                              f'{", ".join(DEFAULT_TOPICS)}, as stream=/topic)')
        if not topic:
            raise ConfigError(f'topics: {stream!r} needs a topic name (stream=/topic)')
        topics[stream] = topic if topic.startswith('/') else '/' + topic
    return topics


def is_recording(path: str | os.PathLike) -> bool:
    """Return True if ``path`` is a rosbag2 directory or a bare .mcap/.db3 file."""
    path = pathlib.Path(path)
    return path.suffix.lower() in BAG_SUFFIXES or (path / 'metadata.yaml').is_file()


# ------------------------------------------------------------------------------ reading
def read(path: str | os.PathLike, topics: str | Mapping[str, str] | None = None) -> Telemetry:
    """Read a recording; TelemetrySchemaError names the file (and topic) of any problem."""
    from rosbags.rosbag2 import Reader
    name = os.fspath(path)
    wanted = parse_topics(topics)
    by_topic = {topic: stream for stream, topic in wanted.items()}
    by_topic.setdefault(COLUMNS_TOPIC, 'columns')
    samples: dict[str, list[tuple[int, Any]]] = {s: [] for s in MSG_TYPES}
    if not os.path.exists(name):
        raise TelemetrySchemaError(name, 'no such file or folder')
    metadata = pathlib.Path(name, 'metadata.yaml')
    if metadata.is_file():   # its aliases bounded before the library reads it
        try:
            read_yaml(metadata)
        except ConfigError as err:
            raise TelemetrySchemaError(name, f'metadata.yaml: {err}') from None
    try:
        with Reader(name) as reader:
            connections = []
            for conn in reader.connections:
                stream = by_topic.get(conn.topic)
                if stream is None:
                    continue
                if conn.msgtype != MSG_TYPES[stream]:
                    raise TelemetrySchemaError(
                        name, f'topic {conn.topic} is {conn.msgtype}, expected '
                        f'{MSG_TYPES[stream]} for the {stream} stream', column=conn.topic)
                connections.append(conn)
            decode = _Decoder()
            messages = reader.messages(connections=connections) if connections else ()
            for conn, _, data in messages:
                msg = decode(data, conn.msgtype, name, conn.topic)
                stamp = msg.header.stamp
                samples[by_topic[conn.topic]].append((stamp.sec * 1_000_000_000
                                                      + stamp.nanosec, msg))
    except TelemetrySchemaError:
        raise
    except Exception as err:  # noqa: BLE001 - any failure of the reader is a bad file
        detail = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise TelemetrySchemaError(name, f'not a readable rosbag2 recording: {detail}') from None
    if not any(samples[s] for s in DEFAULT_TOPICS):
        raise TelemetrySchemaError(name, 'no telemetry topic (looked for ' + ', '.join(
            f'{s}={t}' for s, t in wanted.items()) + '; name others with --topics)')
    return _telemetry(name, samples, wanted)


class _Decoder:
    """Deserialise CDR: the type store (canonical), then JointState as rclpy writes it.

    Only sensor_msgs/JointState among the types read has sequences that may be empty at
    its end, the one place the serialisers differ: :func:`codecs.parse_joint_state`.
    """

    def __init__(self) -> None:
        self.store = typestore()

    def __call__(self, data: bytes, msgtype: str, path: str, topic: str) -> Any:
        try:
            return self.store.deserialize_cdr(data, msgtype)
        except Exception as err:  # noqa: BLE001 - try the other encoding of empty sequences
            problem = err
        if msgtype == 'sensor_msgs/msg/JointState':
            try:
                sec, nanosec, frame, names, arrays = codecs.parse_joint_state(bytes(data))
            except ValueError as err:
                problem = err
            else:
                t = self.store.types
                return t[msgtype](
                    header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
                        sec=sec, nanosec=nanosec), frame_id=frame),
                    name=names, position=np.array(arrays[0], dtype=float),
                    velocity=np.array(arrays[1], dtype=float),
                    effort=np.array(arrays[2], dtype=float))
        raise TelemetrySchemaError(path, f'undecodable {msgtype} message on {topic}: '
                                   f'{problem}', column=topic)


def _telemetry(path: str, samples: dict[str, list[tuple[int, Any]]],
               topics: Mapping[str, str]) -> Telemetry:
    """Map each stream's own stamps onto the union time grid (see the module docstring)."""
    for stream, items in samples.items():
        items.sort(key=lambda item: item[0])
        stamps = [s for s, _ in items]
        dup = next((s for a, s in zip(stamps, stamps[1:]) if a == s), None)
        if dup is not None:
            topic = topics.get(stream, COLUMNS_TOPIC)
            raise TelemetrySchemaError(path, f'two {topic} messages stamped {dup * 1e-9!r} s',
                                       column=topic)
    grid = np.unique(np.concatenate([np.array([s for s, _ in items], dtype=np.int64)
                                     for items in samples.values()]))
    tele = Telemetry(time=grid / 1e9, source=path)
    full = {stream: len(items) == len(grid) for stream, items in samples.items()}

    def place(stream: str, values: Iterable[Any], width: int) -> np.ndarray:
        rows = np.searchsorted(grid, [s for s, _ in samples[stream]])
        out = np.full((len(grid), width), np.nan)
        out[rows] = np.array(list(values), dtype=float).reshape(len(rows), width)
        if not full[stream]:
            mask = np.zeros(len(grid), dtype=bool)
            mask[rows] = True
            tele.present[stream] = mask
        return out

    def vectors(stream: str, get: Callable[[Any], tuple]) -> np.ndarray | None:
        if not samples[stream]:
            return None
        return place(stream, (get(m) for _, m in samples[stream]), len(get(samples[stream][0][1])))

    tele.gyro = vectors('gyro', lambda m: (m.angular_velocity.x, m.angular_velocity.y,
                                           m.angular_velocity.z))
    tele.attitude = vectors('star_tracker', lambda m: (m.quaternion.x, m.quaternion.y,
                                                       m.quaternion.z, m.quaternion.w))
    tele.reference_rate = vectors('reference_rate', lambda m: (m.vector.x, m.vector.y,
                                                               m.vector.z))
    if samples['wheels']:
        speed = _named(samples['wheels'], 'velocity')
        friction = _named(samples['wheels'], 'effort')
        for wheel_id in speed:
            problem = name_problem(wheel_id, wheel_id)
            if problem:
                topic = topics['wheels']
                raise TelemetrySchemaError(path, f'{topic} joint name: {problem}',
                                           column=topic)
        for wheel_id, values in speed.items():
            f = friction.get(wheel_id)
            tele.wheels[wheel_id] = Wheel(
                place('wheels', values, 1)[:, 0],
                None if f is None else place('wheels', f, 1)[:, 0])
    for name, values in _named(samples['columns'], 'position').items():
        problem = name_problem(name, None)
        if problem:
            raise TelemetrySchemaError(path, f'{COLUMNS_TOPIC} column name: {problem}',
                                       column=COLUMNS_TOPIC)
        column = place('columns', values, 1)[:, 0]
        if name.startswith(TRUTH_PREFIX):
            tele.truth[name[len(TRUTH_PREFIX):]] = column
        else:
            tele.aux[name] = column
    return tele


def _named(items: list[tuple[int, Any]], field: str) -> dict[str, np.ndarray]:
    """Return name -> values over JointStates whose name lists may vary (missing: NaN)."""
    order: dict[str, int] = {}
    for _, msg in items:
        for name in msg.name:
            order.setdefault(name, len(order))
    table = np.full((len(items), len(order)), np.nan)
    for row, (_, msg) in enumerate(items):
        values = getattr(msg, field)
        if len(values) == len(msg.name):
            for name, value in zip(msg.name, values):
                table[row, order[name]] = value
    return {name: table[:, col] for name, col in order.items()}


# ------------------------------------------------------------------------------ writing
def write(path: str | os.PathLike, tele: Telemetry,
          topics: str | Mapping[str, str] | None = None) -> None:
    """Write ``tele`` as a rosbag2 directory, or a bare ``.mcap``/``.db3`` file by suffix.

    ``topics``: the topic of each stream (:func:`parse_topics`; default the DESIGN.md names).

    Through telemetry/atomic.py: a folder is built beside ``path`` and swapped in whole
    (an existing folder may hold only a recording: telemetry/recording_folder.py), a bare
    file is written like every other output file.
    """
    target = pathlib.Path(path)
    bare = target.suffix.lower() in BAG_SUFFIXES
    storage = 'sqlite3' if target.suffix.lower() == '.db3' else 'mcap'
    if not bare:
        output = recording_output(target)
        try:
            _write_bag(output.open(), tele, storage, topics)
            output.commit()
        except OSError as err:
            if isinstance(err, OutputError):
                raise
            raise OutputError(f'{target}: write failed: {err.strerror or err}') from None
        finally:
            output.abort()
        return
    try:
        with work_folder(target, (target.stem,)) as work:
            bag = work / target.stem
            _write_bag(bag, tele, storage, topics)
            install_file(next(bag.glob('*' + target.suffix.lower())), target)
    except OSError as err:
        if isinstance(err, OutputError):
            raise
        raise OutputError(f'{target}: write failed: {err.strerror or err}') from None


def _write_bag(bag: pathlib.Path, tele: Telemetry, storage: str,
               topics: str | Mapping[str, str] | None = None) -> None:
    from rosbags.rosbag2 import StoragePlugin, Writer
    store = typestore()
    plugin = StoragePlugin.SQLITE3 if storage == 'sqlite3' else StoragePlugin.MCAP
    streams = dict(_message_streams(tele))
    names = parse_topics(topics)
    stamps = (np.round(tele.time * 1e9)).astype(np.int64)
    with Writer(bag, version=9, storage_plugin=plugin) as writer:
        conns = {stream: writer.add_connection(
            names.get(stream, COLUMNS_TOPIC), MSG_TYPES[stream], typestore=store)
            for stream in streams}
        order = sorted(((int(stamps[row]), k, row, stream)
                        for k, (stream, rows) in enumerate(
                            (s, tele.rows(s)) for s in streams)
                        for row in rows.tolist()))
        for stamp, _, row, stream in order:
            writer.write(conns[stream], stamp, streams[stream](row))


def _message_streams(tele: Telemetry) -> Iterable[tuple[str, Callable[[int], bytes]]]:
    """Yield (stream, row -> canonical CDR bytes) for every stream the record has.

    The package's own encoders (telemetry/codecs.py) write canonical CDR; a test checks
    their bytes against the type store's serialiser.
    """
    time = tele.time.tolist()
    if tele.wheels:
        codec = codecs.JointStateCodec(list(tele.wheels))
        speed = np.column_stack([w.speed for w in tele.wheels.values()]).tolist()
        friction = np.column_stack([np.full(len(tele), np.nan) if w.friction is None
                                    else w.friction for w in tele.wheels.values()]).tolist()
        yield 'wheels', lambda row: codec.encode(time[row], speed[row], friction[row])
    for stream, values, make in (('gyro', tele.gyro, codecs.imu_codec),
                                 ('star_tracker', tele.attitude, codecs.quaternion_codec),
                                 ('reference_rate', tele.reference_rate, codecs.vector3_codec)):
        if values is not None:
            yield stream, _stamped(make(_FRAME), time, values.tolist())
    extra = {**tele.aux, **{TRUTH_PREFIX + k: v for k, v in tele.truth.items()}}
    if extra:
        names = list(extra)
        table = np.column_stack([np.asarray(c, dtype=float) for c in extra.values()]).tolist()
        yield 'columns', lambda row: codecs.encode_columns(time[row], names, table[row])


def _stamped(codec: codecs.StampedCodec, time: list[float],
             values: list[list[float]]) -> Callable[[int], bytes]:
    return lambda row: codec.encode(time[row], values[row])


class RecordingWriter:
    """Write messages of any Jazzy type into a rosbag2 folder (MCAP storage), atomically.

    Messages are built in a temporary folder beside ``path`` and renamed onto it by
    :meth:`close`; :meth:`abort` removes them. Payloads are re-serialised in canonical CDR
    (padding zeroed), so what is recorded does not depend on the sender's serialiser.
    """

    def __init__(self, path: str | os.PathLike) -> None:
        """Open the temporary recording beside ``path`` (OutputError if impossible)."""
        from rosbags.rosbag2 import StoragePlugin, Writer
        self.path = pathlib.Path(path)
        if self.path.suffix:
            raise OutputError(f'{self.path}: a recording folder needs a name without suffix')
        self._output = recording_output(self.path)
        self._writer = Writer(self._output.open(), version=9,
                              storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        self._store = typestore()
        self._decode = _Decoder()
        self._connections: dict[tuple[str, str], Any] = {}
        self.counts: dict[str, int] = {}

    def write(self, topic: str, msgtype: str, stamp_ns: int | None, data: bytes) -> None:
        """Record one serialised message (either encoding of empty sequences).

        ``stamp_ns`` None: the message's ``header.stamp`` (0 for a message without one).
        """
        key = (topic, msgtype)
        if key not in self._connections:
            self._connections[key] = self._writer.add_connection(topic, msgtype,
                                                                 typestore=self._store)
        msg = self._decode(data, msgtype, os.fspath(self.path), topic)
        if stamp_ns is None:
            stamp = getattr(getattr(msg, 'header', None), 'stamp', None)
            stamp_ns = 0 if stamp is None else stamp.sec * 1_000_000_000 + stamp.nanosec
        self._writer.write(self._connections[key], stamp_ns,
                           bytes(self._store.serialize_cdr(msg, msgtype)))
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def close(self) -> None:
        """Finish the recording and swap it onto ``path``."""
        try:
            self._writer.close()
            self._output.commit()
        finally:
            self._output.abort()

    def abort(self) -> None:
        """Drop the recording (``path`` is left as it was)."""
        self._output.abort()
