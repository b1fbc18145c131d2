"""Message codecs: conversions between ROS messages and the package's numbers and events.

Below the nodes layer: file readers and writers (telemetry) and the nodes share them.

Times: telemetry seconds (float) <-> ``builtin_interfaces/Time`` at nanosecond
resolution; back to seconds as ``sec + nanosec / 1e9`` (so 0.3 s reads back as 0.3).
Anomaly events <-> ``DiagnosticStatus``: every ``AnomalyEvent.fields()`` item becomes a
KeyValue, floats written with ``repr`` so they read back bit for bit.
"""

from __future__ import annotations

import math
import struct
from typing import Any, Mapping, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.core import keys
from rwa_monitor.core.events import AnomalyEvent

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE

# Event kinds published as ERROR; every other kind is a WARN (docs/nodes.md).
ERROR_KINDS = frozenset({'both'})


def split_seconds(seconds: float) -> tuple[int, int]:
    """Return ``(sec, nanosec)`` of ``seconds`` (nanosec in [0, 1e9))."""
    whole = math.floor(seconds)
    nanosec = int(round((seconds - whole) * 1e9))
    if nanosec >= 1_000_000_000:
        whole, nanosec = whole + 1, nanosec - 1_000_000_000
    return int(whole), nanosec


def to_stamp(seconds: float) -> Time:
    """Return the Time of ``seconds`` (nanosecond resolution)."""
    sec, nanosec = split_seconds(seconds)
    return Time(sec=sec, nanosec=nanosec)


def to_seconds(stamp: Time) -> float:
    """Return a Time as seconds."""
    return stamp.sec + stamp.nanosec / 1e9


def joint_state(seconds: float, names: Sequence[str], speeds: Sequence[float],
                frictions: Sequence[float] | None = None) -> JointState:
    """Return the ``telemetry/wheels`` message: velocity = rad/s, effort = friction N m."""
    msg = JointState()
    msg.header.stamp = to_stamp(seconds)
    msg.name = list(names)
    msg.velocity = [float(v) for v in speeds]
    if frictions is not None:
        msg.effort = [float(v) for v in frictions]
    return msg


def imu(seconds: float, rate: Sequence[float], frame_id: str = 'body') -> Imu:
    """Return the ``telemetry/gyro`` message (angular velocity only)."""
    msg = Imu()
    msg.header.stamp = to_stamp(seconds)
    msg.header.frame_id = frame_id
    msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z = map(float, rate)
    msg.orientation_covariance[0] = -1.0
    msg.linear_acceleration_covariance[0] = -1.0
    return msg


def quaternion(seconds: float, q_xyzw: Sequence[float],
               frame_id: str = 'body') -> QuaternionStamped:
    """Return the ``telemetry/star_tracker`` message (scalar last)."""
    msg = QuaternionStamped()
    msg.header.stamp = to_stamp(seconds)
    msg.header.frame_id = frame_id
    q = msg.quaternion
    q.x, q.y, q.z, q.w = map(float, q_xyzw)
    return msg


def vector3(seconds: float, xyz: Sequence[float], frame_id: str = 'body') -> Vector3Stamped:
    """Return the ``telemetry/reference_rate`` message."""
    msg = Vector3Stamped()
    msg.header.stamp = to_stamp(seconds)
    msg.header.frame_id = frame_id
    msg.vector.x, msg.vector.y, msg.vector.z = map(float, xyz)
    return msg


def clock(seconds: float) -> Clock:
    """Return the ``/clock`` message."""
    return Clock(clock=to_stamp(seconds))


# ------------------------------------------- JointState as CDR bytes (the hot path)
# sensor_msgs/JointState in the little-endian CDR that rmw uses: a 4-byte encapsulation
# header, then header.stamp (int32 sec, uint32 nanosec), header.frame_id (uint32 length
# with the NUL, bytes), name (uint32 count, strings), position, velocity, effort (uint32
# count, float64 values aligned to 8 when the count is not 0). Alignment is relative to
# the end of the encapsulation header. Encoding and decoding by hand takes a few
# microseconds where building or reading the Python message takes tens (docs/nodes.md).
_CDR_LE = b'\x00\x01\x00\x00'
_U32 = struct.Struct('<I')
_HEAD = struct.Struct('<iII')


def _pad(buffer: bytearray, size: int) -> None:
    buffer.extend(b'\x00' * (-(len(buffer) - 4) % size))


def encode_joint_state(seconds: float, names: Sequence[str], speeds: Sequence[float],
                       frictions: Sequence[float], frame_id: str = '') -> bytes:
    """Return the serialised ``telemetry/wheels`` JointState (``publish`` accepts bytes)."""
    return _encode_joint(seconds, names, ((), speeds, frictions), frame_id)


def encode_columns(seconds: float, names: Sequence[str], values: Sequence[float]) -> bytes:
    """Return the serialised ``/rwa_monitor/columns`` JointState (values in ``position``)."""
    return _encode_joint(seconds, names, (values, (), ()), '')


def _encode_joint(seconds: float, names: Sequence[str], arrays: Sequence[Sequence[float]],
                  frame_id: str) -> bytes:
    sec, nanosec = split_seconds(seconds)
    frame = frame_id.encode()
    out = bytearray(_CDR_LE)
    out += _HEAD.pack(sec, nanosec, len(frame) + 1) + frame + b'\x00'
    _pad(out, 4)
    out += _U32.pack(len(names))
    for name in names:
        _pad(out, 4)
        raw = name.encode()
        out += _U32.pack(len(raw) + 1) + raw + b'\x00'
    for values in arrays:
        _pad(out, 4)
        out += _U32.pack(len(values))
        if len(values):
            _pad(out, 8)
            out += struct.pack(f'<{len(values)}d', *values)
    return bytes(out)


def decode_joint_state(buffer: bytes) -> tuple[float, list[str], tuple, tuple]:
    """Return ``(time, names, velocity, effort)`` of a serialised JointState.

    Accepts both encodings of an empty float64 sequence (see :func:`parse_joint_state`).
    Raise ValueError if the bytes are not a little-endian CDR JointState (the caller
    falls back to rclpy's deserialisation).
    """
    sec, nanosec, _, names, (_, velocity, effort) = parse_joint_state(buffer)
    return sec + nanosec / 1e9, names, velocity, effort


def parse_joint_state(buffer: bytes) -> tuple[int, int, str, list[str], tuple]:
    """Return ``(sec, nanosec, frame_id, names, (position, velocity, effort))``.

    Canonical CDR ends with the last field; rclpy may append up to 8 bytes of padding of
    unspecified content after a message whose last sequences are empty (the serialisers
    then disagree on the size, and a strict reader refuses rclpy's bytes). Both are read;
    ValueError for anything else.
    """
    if buffer[:2] != b'\x00\x01':
        raise ValueError('not little-endian CDR')
    data = memoryview(buffer)[4:]
    try:
        sec, nanosec, frame_len = _HEAD.unpack_from(data, 0)
        frame = str(data[12:12 + max(frame_len - 1, 0)], 'utf-8')
        offset = (12 + frame_len + 3) & ~3
        (count,) = _U32.unpack_from(data, offset)
        offset += 4
        names = []
        for _ in range(min(count, len(data))):
            offset = (offset + 3) & ~3
            (size,) = _U32.unpack_from(data, offset)
            offset += 4
            if size < 1 or offset + size > len(data):
                raise ValueError('a name runs past the end')
            names.append(str(data[offset:offset + size - 1], 'utf-8'))
            offset += size
        arrays = []
        for _ in range(3):
            offset = (offset + 3) & ~3
            (size,) = _U32.unpack_from(data, offset)
            offset += 4
            if size:
                offset = (offset + 7) & ~7
            arrays.append(struct.unpack_from(f'<{size}d', data, offset) if size else ())
            offset += 8 * size
    except (struct.error, UnicodeDecodeError) as err:
        raise ValueError(f'not a JointState: {err}') from None
    if len(names) != count or not len(data) - 8 <= offset <= len(data):
        raise ValueError(f'not a JointState: {len(data) - offset} bytes left over')
    return sec, nanosec, frame, names, tuple(arrays)


class JointStateCodec:
    """Encode and decode JointStates of one fixed name list with a precomputed layout.

    With the names (and frame) fixed, every field sits at a fixed offset: the bytes between
    the stamp and the velocity count are a constant, the rest is one ``struct`` format.
    :meth:`decode` returns None for a message of another layout (other names, lengths that
    differ): the caller then uses :func:`decode_joint_state`.
    """

    _STAMP = struct.Struct('<iI')

    def __init__(self, names: Sequence[str], frame_id: str = '') -> None:
        self.names = list(names)
        n = len(self.names)
        out = bytearray(_CDR_LE) + bytes(8)
        segments: list[tuple[int, int]] = []  # the bytes that are not padding

        def add(data: bytes) -> None:
            if segments and segments[-1][1] == len(out):
                segments[-1] = (segments[-1][0], len(out) + len(data))
            else:
                segments.append((len(out), len(out) + len(data)))
            out.extend(data)

        frame = frame_id.encode()
        add(_U32.pack(len(frame) + 1) + frame + b'\x00')
        _pad(out, 4)
        add(_U32.pack(n))
        for name in self.names:
            _pad(out, 4)
            raw = name.encode()
            add(_U32.pack(len(raw) + 1) + raw + b'\x00')
        _pad(out, 4)
        add(_U32.pack(0))  # position: empty
        self._middle = bytes(out[12:])
        # Padding bytes written by other serialisers are not necessarily zero: compare
        # only the meaningful ones.
        self._segments = [(a, b, bytes(out[a:b])) for a, b in segments]
        self._tail_at = len(out)
        offset, fmt = len(out) - 4, ['<']
        for _ in range(2):  # velocity, effort
            fmt.append('x' * (-offset % 4) + 'I')
            offset += -offset % 4 + 4
            if n:
                fmt.append('x' * (-offset % 8) + f'{n}d')
                offset += -offset % 8 + 8 * n
        self._tail = struct.Struct(''.join(fmt))
        self._n = n

    def encode(self, seconds: float, speeds: Sequence[float],
               frictions: Sequence[float]) -> bytes:
        """Return the serialised JointState (``speeds``/``frictions``: one per name)."""
        n = self._n
        return b''.join((_CDR_LE, self._STAMP.pack(*split_seconds(seconds)), self._middle,
                         self._tail.pack(n, *speeds, n, *frictions)))

    def decode(self, buffer: bytes) -> tuple[float, list[str], tuple, tuple] | None:
        """Return ``(time, names, velocity, effort)``, or None if the layout differs."""
        if buffer[:2] != b'\x00\x01':
            return None
        for start, end, expected in self._segments:
            if buffer[start:end] != expected:
                return None
        try:
            values = self._tail.unpack_from(buffer, self._tail_at)
        except struct.error:
            return None
        n = self._n
        if values[0] != n or values[n + 1] != n:
            return None
        sec, nanosec = self._STAMP.unpack_from(buffer, 4)
        return sec + nanosec / 1e9, self.names, values[1:n + 1], values[n + 2:]


class StampedCodec:
    """Encode a message that is a Header followed only by float64 values, by hand.

    Vector3Stamped (3 values), QuaternionStamped (4) and Imu (37: orientation,
    its covariance, angular velocity, its covariance, linear acceleration, its
    covariance) have this shape: after ``frame_id`` the values start at the next multiple
    of 8 and follow each other. ``template`` holds the constant values; ``slots`` says
    which of them :meth:`encode` replaces.
    """

    def __init__(self, template: Sequence[float], slots: Sequence[int],
                 frame_id: str = '') -> None:
        frame = frame_id.encode()
        head = bytearray(_CDR_LE) + bytes(8)
        head += _U32.pack(len(frame) + 1) + frame + b'\x00'
        _pad(head, 8)
        self._middle = bytes(head[12:])
        self._template = [float(v) for v in template]
        self._slots = list(slots)
        self._values = struct.Struct(f'<{len(self._template)}d')
        self._stamp = struct.Struct('<iI')

    def encode(self, seconds: float, values: Sequence[float]) -> bytes:
        """Return the serialised message with ``values`` in the slots."""
        row = self._template.copy()
        for slot, value in zip(self._slots, values):
            row[slot] = value
        return b''.join((_CDR_LE, self._stamp.pack(*split_seconds(seconds)), self._middle,
                         self._values.pack(*row)))


# Float64 values after the header of each message that is a Header and float64s only.
STAMPED_SIZES = {'Vector3Stamped': 3, 'QuaternionStamped': 4, 'Imu': 37}
IMU_ANGULAR_VELOCITY = slice(13, 16)  # angular_velocity x, y, z among the Imu's 37 values


def decode_stamped(buffer: bytes, count: int) -> tuple[float, tuple[float, ...]]:
    """Return ``(time, values)`` of a serialised Header-then-``count``-float64 message.

    The inverse of :class:`StampedCodec` for any ``frame_id`` (so also bytes another
    serialiser wrote); up to 7 trailing padding bytes are accepted, as for the JointState.
    Raise ValueError if the bytes are not such a little-endian CDR message (the caller
    falls back to rclpy's deserialisation).
    """
    if buffer[:2] != b'\x00\x01':
        raise ValueError('not little-endian CDR')
    data = memoryview(buffer)[4:]
    try:
        sec, nanosec, frame_len = _HEAD.unpack_from(data, 0)
        offset = (12 + frame_len + 7) & ~7
        values = struct.unpack_from(f'<{count}d', data, offset)
    except struct.error as err:
        raise ValueError(f'not a stamped message of {count} values: {err}') from None
    left = len(data) - offset - 8 * count
    if frame_len < 1 or not 0 <= left < 8:
        raise ValueError(f'not a stamped message of {count} values: {left} bytes left over')
    return sec + nanosec / 1e9, values


def vector3_codec(frame_id: str = 'body') -> StampedCodec:
    """Return the codec of ``telemetry/reference_rate`` (geometry_msgs/Vector3Stamped)."""
    return StampedCodec([0.0] * 3, range(3), frame_id)


def quaternion_codec(frame_id: str = 'body') -> StampedCodec:
    """Return the codec of ``telemetry/star_tracker`` (QuaternionStamped, scalar last)."""
    return StampedCodec([0.0, 0.0, 0.0, 1.0], range(4), frame_id)


def imu_codec(frame_id: str = 'body') -> StampedCodec:
    """Return the codec of ``telemetry/gyro`` (Imu: angular velocity only, as :func:`imu`)."""
    template = [0.0, 0.0, 0.0, 1.0, -1.0, *[0.0] * 8, 0.0, 0.0, 0.0, *[0.0] * 9,
                0.0, 0.0, 0.0, -1.0, *[0.0] * 8]
    return StampedCodec(template, (13, 14, 15), frame_id)


class BadMessage(ValueError):
    """A message that cannot be used at all; ``reason`` is a counter name."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f'{reason}: {detail}')
        self.reason = reason


def wheel_samples(msg: JointState) -> tuple[float, list[tuple[str, float, float]]]:
    """Return ``(time, [(wheel, speed, friction), ...])`` from a ``telemetry/wheels`` message.

    See :func:`samples_of` for the rules.
    """
    return samples_of(to_seconds(msg.header.stamp), msg.name, msg.velocity, msg.effort)


def samples_of(seconds: float, names: Sequence[str], speeds: Sequence[float],
               efforts: Sequence[float]) -> tuple[float, list[tuple[str, float, float]]]:
    """Return ``(time, [(wheel, speed, friction), ...])`` from JointState fields.

    Raise BadMessage with reason ``length_mismatch`` when ``velocity`` or ``effort`` do not
    have one value per name (effort is required: it is the friction measurement). Entries
    with an empty or repeated name are dropped here; the caller counts them by comparing
    lengths (see :func:`wheel_name_problems`).
    """
    if len(speeds) != len(names) or len(efforts) != len(names):
        raise BadMessage('length_mismatch', f'{len(names)} names, {len(speeds)} velocities, '
                         f'{len(efforts)} efforts')
    seen: set[str] = set()
    out = []
    for name, speed, effort in zip(names, speeds, efforts):
        if not name or name in seen:
            continue
        seen.add(name)
        out.append((name, speed, effort))
    return seconds, out


def wheel_name_problems(msg: JointState | Sequence[str]) -> dict[str, int]:
    """Return counts of empty and repeated names in a JointState (or its ``name`` list)."""
    names = getattr(msg, 'name', msg)
    empty = sum(1 for n in names if not n)
    named = [n for n in names if n]
    return {'empty_name': empty, 'duplicate_name': len(named) - len(set(named))}


def event_level(kind: str) -> bytes:
    """Return the DiagnosticStatus level of an event kind: ERROR for ``both``, else WARN."""
    return ERROR if kind in ERROR_KINDS else WARN


def event_status(event: AnomalyEvent, node_name: str) -> DiagnosticStatus:
    """Return the DiagnosticStatus of one anomaly event (KeyValues = ``event.fields()``)."""
    return DiagnosticStatus(
        level=event_level(event.kind), name=f'{node_name}: {event.component} anomaly',
        hardware_id=event.component,
        message=f'{event.kind} anomaly, change at t={event.time:.3f} s',
        values=key_values(event.fields()))


def key_values(values: Mapping[str, Any]) -> list[KeyValue]:
    """Return KeyValues; floats keep every digit (``repr``), so they read back exactly."""
    return [KeyValue(key=str(k), value=format_value(v)) for k, v in values.items()]


def format_value(value: Any) -> str:
    """Return a KeyValue value string: ``repr`` of floats (exact), ``str`` otherwise."""
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, bool):
        return 'true' if value else 'false'
    return str(value)


def parse_value(text: str) -> Any:
    """Return a KeyValue value as int, float, bool or str (the inverse of format_value)."""
    if text in ('true', 'false'):
        return text == 'true'
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def status_fields(status: DiagnosticStatus) -> dict[str, Any]:
    """Return a status's KeyValues as key -> parsed value."""
    return {kv.key: parse_value(kv.value) for kv in status.values}


def status_event(status: DiagnosticStatus) -> AnomalyEvent:
    """Return the AnomalyEvent carried by an ``anomalies`` status (inverse of event_status)."""
    fields = status_fields(status)
    core = {keys.DETECTOR, keys.COMPONENT, keys.KIND, keys.CHANGE_TIME, keys.CHANGE_INDEX,
            keys.DECLARATION_TIME, keys.DECLARATION_INDEX, keys.P_VALUE, keys.REVISION}
    return AnomalyEvent(
        detector=str(fields[keys.DETECTOR]), component=str(fields[keys.COMPONENT]),
        kind=str(fields[keys.KIND]), time=float(fields[keys.CHANGE_TIME]),
        index=int(fields[keys.CHANGE_INDEX]),
        declared_time=float(fields[keys.DECLARATION_TIME]),
        declared_index=int(fields[keys.DECLARATION_INDEX]),
        p_value=float(fields.get(keys.P_VALUE, math.nan)),
        revision=int(fields.get(keys.REVISION, 0)),
        details={k: v for k, v in fields.items() if k not in core})
