"""The telemetry map: which XTCE parameter gives each schema column, and each packet's time.

One YAML file (docs/contracts.md "CCSDS space packets")::

    time:                     # per container: the time of its packets, in seconds
      WheelPacket: WHL_TIME   # a parameter in seconds, or
      GyroPacket: {seconds: GYR_SEC, subseconds: GYR_SUB, subsecond_scale: 65536}
    columns:                  # schema column -> XTCE parameter (calibrated value, SI units)
      rw1_speed: RW1_SPD
    epoch_utc: 2026-01-01T00:00:00Z   # optional: the calendar time of time 0

With ``seconds``/``subseconds`` the time is ``(seconds * scale + subseconds) / scale``
computed on exact integers (one rounding), so a stamp written as nanoseconds reads back as
the float a CSV or a ROS stamp gives. Read with the package's YAML reader (aliases
bounded); every mistake is one ConfigError naming the file. :func:`check` holds the map
against an XTCE definition, both ways.
"""

from __future__ import annotations

from dataclasses import dataclass
import datetime
import difflib
import os
from typing import Any

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry.schema import name_problem, Telemetry, wheel_id_of
from rwa_monitor.telemetry.yaml_file import read_yaml

_TIME_KEYS = {'seconds', 'subseconds', 'subsecond_scale'}
MAX_SCALE = 1 << 32


@dataclass(frozen=True)
class TimeSpec:
    """How a container's packets give their time: one parameter, or seconds + fraction."""

    seconds: str
    subseconds: str | None = None
    scale: int = 1

    def parameters(self) -> tuple[str, ...]:
        """Return the parameters this time is computed from."""
        return (self.seconds,) if self.subseconds is None else (self.seconds, self.subseconds)


@dataclass(frozen=True)
class TelemetryMap:
    """A parsed telemetry map (module docstring)."""

    path: str
    time: dict[str, TimeSpec]
    columns: dict[str, str]
    epoch_utc: datetime.datetime | None = None


def read_map(path: str | os.PathLike) -> TelemetryMap:
    """Read and check the structure of a telemetry map; ConfigError naming the file."""
    name = os.fspath(path)
    document = read_yaml(name)
    if not isinstance(document, dict):
        raise ConfigError(f'{name}: a telemetry map is a mapping with time: and columns:')
    unknown = sorted(set(map(str, document)) - {'time', 'columns', 'epoch_utc'})
    if unknown:
        raise ConfigError(f'{name}: unknown key {unknown[0]!r} (expected time, columns, '
                          'epoch_utc)')
    time, columns = document.get('time'), document.get('columns')
    if not isinstance(time, dict) or not time:
        raise ConfigError(f'{name}: time: must map each container to its time parameter')
    if not isinstance(columns, dict) or not columns:
        raise ConfigError(f'{name}: columns: must map schema columns to XTCE parameters')
    specs = {str(c): _time_spec(name, str(c), v) for c, v in time.items()}
    mapped: dict[str, str] = {}
    for column, parameter in columns.items():
        column = str(column)
        problem = name_problem(column, wheel_id_of(column))
        if problem or column == 'time':
            raise ConfigError(f'{name}: columns: {column!r}: '
                              f'{problem or "time comes from the time: section"}')
        if not isinstance(parameter, str) or not parameter:
            raise ConfigError(f'{name}: columns: {column}: expected an XTCE parameter name')
        mapped[column] = parameter
    try:
        Telemetry.from_columns({'time': [], **{c: [] for c in mapped}})
    except KeyError as err:
        raise ConfigError(f'{name}: columns: missing {err.args[0]} (a group is all or '
                          'nothing: gyro_x/y/z, q_x/y/z/w, ref_x/y/z; friction needs speed)'
                          ) from None
    return TelemetryMap(name, specs, mapped, _epoch(name, document.get('epoch_utc')))


def _time_spec(path: str, container: str, value: Any) -> TimeSpec:
    where = f'{path}: time: {container}'
    if isinstance(value, str) and value:
        return TimeSpec(value)
    if not isinstance(value, dict) or set(map(str, value)) != _TIME_KEYS:
        raise ConfigError(f'{where}: expected a parameter name or {{seconds: P, subseconds: '
                          'P2, subsecond_scale: N}')
    scale = value['subsecond_scale']
    if isinstance(scale, bool) or not isinstance(scale, int) or not 1 <= scale <= MAX_SCALE:
        raise ConfigError(f'{where}: subsecond_scale must be an integer in [1, 2**32]')
    seconds, subseconds = value['seconds'], value['subseconds']
    if not all(isinstance(p, str) and p for p in (seconds, subseconds)):
        raise ConfigError(f'{where}: seconds and subseconds must be parameter names')
    return TimeSpec(seconds, subseconds, scale)


def _epoch(path: str, value: Any) -> datetime.datetime | None:
    if value is None:
        return None
    if isinstance(value, str):
        try:
            value = datetime.datetime.fromisoformat(value.replace('Z', '+00:00'))
        except ValueError:
            value = None
    if not isinstance(value, datetime.datetime):
        raise ConfigError(f'{path}: epoch_utc: expected a UTC date and time such as '
                          '2026-01-01T00:00:00Z')
    if value.tzinfo is None:
        value = value.replace(tzinfo=datetime.timezone.utc)
    return value.astimezone(datetime.timezone.utc)


def check(tmap: TelemetryMap, definition: Any) -> dict[str, list[str]]:
    """Hold the map against the XTCE definition; return container -> its mapped columns.

    ConfigError (naming the map) when the map names a parameter or container the XTCE
    lacks, a container lacks its time parameter, a mapped parameter is in no container
    of ``time:`` or in two of them, or a ``time:`` container carries no mapped column.
    """
    params, containers = definition.parameters, definition.containers
    for container, spec in tmap.time.items():
        if container not in containers:
            raise ConfigError(f'{tmap.path}: time: container {container!r} is not in '
                              f'{definition.path}{_close(container, containers)}')
        for parameter in spec.parameters():
            if parameter not in params:
                raise ConfigError(f'{tmap.path}: time: {container}: parameter {parameter!r} '
                                  f'is not in {definition.path}{_close(parameter, params)}')
    holds = {c: {p.name for p in definition.entries(c)} for c in tmap.time}
    for container, spec in tmap.time.items():
        missing = [p for p in spec.parameters() if p not in holds[container]]
        if missing:
            raise ConfigError(f'{tmap.path}: time: {container}: the XTCE container has no '
                              f'parameter {missing[0]!r}')
    by_container: dict[str, list[str]] = {c: [] for c in tmap.time}
    for column, parameter in tmap.columns.items():
        if parameter not in params:
            raise ConfigError(f'{tmap.path}: columns: {column}: parameter {parameter!r} is '
                              f'not in {definition.path}{_close(parameter, params)}')
        found = [c for c in tmap.time if parameter in holds[c]]
        if len(found) != 1:
            elsewhere = sorted(c for c in containers if c not in tmap.time
                               and parameter in {p.name for p in definition.entries(c)})
            raise ConfigError(
                f'{tmap.path}: columns: {column}: parameter {parameter!r} is in '
                + (f'containers {", ".join(found)} of time: (one expected)' if found else
                   f'no container of time: (the XTCE has it in '
                   f'{", ".join(elsewhere) or "no container"})'))
        by_container[found[0]].append(column)
    empty = [c for c, cols in by_container.items() if not cols]
    if empty:
        raise ConfigError(f'{tmap.path}: time: container {empty[0]!r} carries none of the '
                          'columns: parameters (remove it, or map its parameters)')
    return by_container


def _close(name: str, known: Any) -> str:
    close = difflib.get_close_matches(name, list(known), n=1)
    return f"; did you mean '{close[0]}'?" if close else ''
