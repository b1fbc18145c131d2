"""Conversions between ROS messages and the package's numbers and events.

Times: telemetry seconds (float) <-> ``builtin_interfaces/Time`` at nanosecond
resolution; back to seconds as ``sec + nanosec / 1e9`` (so 0.3 s reads back as 0.3).
Anomaly events <-> ``DiagnosticStatus``: every ``AnomalyEvent.fields()`` item becomes a
KeyValue, floats written with ``repr`` so they read back bit for bit.
"""

from __future__ import annotations

import math
from typing import Any, Sequence

from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import QuaternionStamped, Vector3Stamped
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu, JointState

from rwa_monitor.core import keys
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.nodes.common import ERROR, key_values, WARN

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


class BadMessage(ValueError):
    """A message that cannot be used at all; ``reason`` is a counter name."""

    def __init__(self, reason: str, detail: str) -> None:
        super().__init__(f'{reason}: {detail}')
        self.reason = reason


def wheel_samples(msg: JointState) -> tuple[float, list[tuple[str, float, float]]]:
    """Return ``(time, [(wheel, speed, friction), ...])`` from a ``telemetry/wheels`` message.

    Raise BadMessage with reason ``length_mismatch`` when ``velocity`` or ``effort`` do not
    have one value per name (effort is required: it is the friction measurement). Entries
    with an empty or repeated name are dropped here; the caller counts them by comparing
    lengths (see :func:`wheel_name_problems`).
    """
    names, speeds, efforts = msg.name, msg.velocity, msg.effort
    if len(speeds) != len(names) or len(efforts) != len(names):
        raise BadMessage('length_mismatch', f'{len(names)} names, {len(speeds)} velocities, '
                         f'{len(efforts)} efforts')
    seconds = to_seconds(msg.header.stamp)
    seen: set[str] = set()
    out = []
    for name, speed, effort in zip(names, speeds, efforts):
        if not name or name in seen:
            continue
        seen.add(name)
        out.append((name, speed, effort))
    return seconds, out


def wheel_name_problems(msg: JointState) -> dict[str, int]:
    """Return counts of empty and repeated names in a JointState."""
    empty = sum(1 for n in msg.name if not n)
    named = [n for n in msg.name if n]
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
