"""Reading ``telemetry/wheels`` from serialised bytes (the raw subscriptions' hot path).

llr_detector and fss_diagnoser subscribe raw: building the generated JointState costs
tens of microseconds per message where :class:`WheelsDecoder` reads the bytes in a few
(docs/nodes.md "Where the time goes"). The fields it returns are those of the message,
so a node gives the same samples, and the same events, either way.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState

from rwa_monitor.nodes import messages
from rwa_monitor.telemetry.schema import NAME_RULE, valid_name

# (time s, names, velocities, efforts) of one JointState.
WheelFields = tuple[float, Sequence[str], Sequence[float], Sequence[float]]


class WheelsDecoder:
    """Decode serialised JointStates, fastest first, and learn the layout of the stream.

    First the fixed-layout :class:`messages.JointStateCodec` of the last well-formed
    name list; then the general CDR reader :func:`messages.decode_joint_state` (a
    well-formed message of a new layout becomes the fixed one); then rclpy's
    deserialisation, for bytes another serialiser wrote differently. None when nothing
    reads them (the caller counts an ``undecodable`` message).
    """

    def __init__(self) -> None:
        self._codec: messages.JointStateCodec | None = None

    def decode(self, buffer: bytes) -> WheelFields | None:
        """Return the fields of one serialised JointState, or None if unreadable."""
        fields = self._codec.decode(buffer) if self._codec is not None else None
        if fields is not None:
            return fields
        try:
            fields = messages.decode_joint_state(buffer)
        except ValueError:
            try:
                msg = deserialize_message(buffer, JointState)
            except Exception:  # noqa: BLE001 - anything undecodable is counted, not fatal
                return None
            return fields_of(msg)
        names = fields[1]
        if (len(fields[2]) == len(fields[3]) == len(names) and all(names)
                and len(set(names)) == len(names)):
            self._codec = messages.JointStateCodec(names)
        return fields


def fields_of(msg: JointState) -> WheelFields:
    """Return the fields of a JointState message (the in-process, non-raw path)."""
    return messages.to_seconds(msg.header.stamp), msg.name, msg.velocity, msg.effort


def wheel_names(text: str) -> set[str] | None:
    """Return the wheel ids of a comma-separated ``wheels`` parameter (None = any wheel)."""
    names = {n.strip() for n in text.split(',') if n.strip()}
    return names or None


class Refusal(NamedTuple):
    """Why a wheel is ignored: the input counter to increment and the log message."""

    counter: str
    message: str


def name_refusal(wheel_id: str) -> Refusal | None:
    """Return the refusal of a wheel id that is not a valid name (the file readers' rule).

    A wheel id from a message becomes a diagnostics key and the component of journalled
    events, so it is checked as a column name is (telemetry/schema.py ``valid_name``).
    """
    if valid_name(wheel_id):
        return None
    return Refusal('invalid_name', f'ignoring wheel {str(wheel_id)[:80]!r}: not a valid '
                   f'name ({NAME_RULE})')


def wheel_refusal(wheel_id: str, allowed: set[str] | None, known: int,
                  max_wheels: int) -> Refusal | None:
    """Return the refusal if a new wheel must be ignored, else None."""
    if allowed is not None and wheel_id not in allowed:
        return Refusal('unknown_wheel', f'ignoring wheel {wheel_id!r}: not in parameter wheels')
    if known >= max_wheels:
        return Refusal('too_many_wheels', f'ignoring wheel {wheel_id!r}: max_wheels reached')
    return None


MAX_LOGGED = 1000   # (reason, subject) pairs a node remembers having logged


def first_time(logged: set[tuple[str, str]], reason: str, subject: str) -> bool:
    """Return True (and remember it) the first time ``(reason, subject)`` is seen.

    Subjects come from messages (wheel ids), so their number is unbounded: past
    :data:`MAX_LOGGED` remembered pairs every new subject counts as one, per reason.
    """
    key = (reason, subject) if len(logged) < MAX_LOGGED else (reason, '')
    if key in logged:
        return False
    logged.add(key)
    return True
