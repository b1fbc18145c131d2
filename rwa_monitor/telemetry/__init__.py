"""Telemetry files: CSV (the schema of DESIGN.md), recordings and space packets, by path.

A rosbag2 folder (``metadata.yaml`` with ``.mcap`` or ``.db3`` storage) or a bare ``.mcap``
or ``.db3`` file is a recording (rosbag_io); a ``.parquet`` file is read by parquet_io; a
``.bin`` file, or any file given with an XTCE definition or a telemetry map, is a file of
CCSDS space packets (ccsds: its XTCE and map from the arguments, else ``FILE.xml`` and
``FILE_map.yaml``, else ``telemetry.xml`` and ``telemetry_map.yaml`` beside it; what the
packet reader counted and skipped is logged as warnings); anything else is read as CSV.
Writing: a ``.mcap`` or ``.db3`` path writes a bare file, a path without a suffix (or an
existing recording folder) a rosbag2 folder, a ``.bin`` path packets with their XTCE and
map beside them (ccsds_write), a ``.parquet`` path Parquet (parquet_io), any other path
CSV; a FIFO or a device (``-o /dev/null``) gets CSV written straight into it
(telemetry/atomic.py).
"""

from __future__ import annotations

import logging
import os
import pathlib
from typing import Mapping

from rwa_monitor.exceptions import ConfigError, TelemetrySchemaError
from rwa_monitor.telemetry.atomic import is_stream
from rwa_monitor.telemetry.csv_io import read_csv, write_csv
from rwa_monitor.telemetry.schema import STREAMS, Telemetry, Wheel

__all__ = ['STREAMS', 'Telemetry', 'Wheel', 'read_telemetry', 'write_telemetry']

PACKET_SUFFIX = '.bin'
ARCHIVE_XTCE, ARCHIVE_MAP = 'telemetry.xml', 'telemetry_map.yaml'
_LOG = logging.getLogger(__name__)


def is_packets(path: str | os.PathLike) -> bool:
    """Return True for a path read as CCSDS space packets without being told (``.bin``)."""
    name = os.path.basename(os.fspath(path))       # a string: called for every archive file
    return os.path.splitext(name)[1].lower() == PACKET_SUFFIX


def packet_definitions(path: str | os.PathLike, xtce: str | os.PathLike | None = None,
                       telemetry_map: str | os.PathLike | None = None
                       ) -> tuple[pathlib.Path, pathlib.Path]:
    """Return the XTCE and map of a packet file: given, else found beside it (module doc)."""
    from rwa_monitor.telemetry.ccsds_write import sibling_paths
    target = pathlib.Path(path)
    for xml, yml in (sibling_paths(target), (target.parent / ARCHIVE_XTCE,
                                             target.parent / ARCHIVE_MAP)):
        found_xml = pathlib.Path(xtce) if xtce else xml
        found_yml = pathlib.Path(telemetry_map) if telemetry_map else yml
        if found_xml.is_file() and found_yml.is_file():
            return found_xml, found_yml
    for given, what in ((xtce, 'XTCE definition'), (telemetry_map, 'telemetry map')):
        if given and not pathlib.Path(given).is_file():
            raise TelemetrySchemaError(os.fspath(given), f'no such {what}')
    raise TelemetrySchemaError(
        os.fspath(target), 'space packets need an XTCE definition and a telemetry map: give '
        f'--xtce DEF.xml --telemetry-map MAP.yaml, or put {target.stem}.xml and '
        f'{target.stem}_map.yaml (or {ARCHIVE_XTCE} and {ARCHIVE_MAP}) beside it')


def read_telemetry(path: str | os.PathLike,
                   topics: str | Mapping[str, str] | None = None,
                   xtce: str | os.PathLike | None = None,
                   telemetry_map: str | os.PathLike | None = None) -> Telemetry:
    """Read a telemetry file or recording (the format from the path, module doc).

    Parameters
    ----------
    path : str or path
        A CSV or Parquet file, a rosbag2 folder, a bare ``.mcap`` or ``.db3`` file, or a
        file of CCSDS space packets.
    topics : str or mapping, optional
        Stream -> topic of a recording (``wheels=/a,gyro=/b``); None: the default topics.
    xtce, telemetry_map : str or path, optional
        The XTCE definition and telemetry map of a packet file (docs/contracts.md); either
        one makes ``path`` a packet file whatever its suffix.

    Returns
    -------
    Telemetry
        The record; a TelemetrySchemaError names the file and what is wrong with it.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> path = pathlib.Path(tempfile.mkdtemp()) / 'record.csv'
    >>> write_telemetry(path, Telemetry(np.arange(3) * 0.25,
    ...                                 {'rw1': Wheel(np.array([1.0, 2.0, 3.0]))}))
    >>> tele = read_telemetry(path)
    >>> len(tele), tele.wheels['rw1'].speed.tolist()
    (3, [1.0, 2.0, 3.0])
    """
    tele, notes = read_with_notes(path, topics, xtce, telemetry_map)
    for note in notes:
        _LOG.warning('%s', note)
    return tele


def read_with_notes(path: str | os.PathLike,
                    topics: str | Mapping[str, str] | None = None,
                    xtce: str | os.PathLike | None = None,
                    telemetry_map: str | os.PathLike | None = None
                    ) -> tuple[Telemetry, list[str]]:
    """Return :func:`read_telemetry`'s record and what the reader counted, one line each.

    The lines (``FILE: what``) say what a packet file held that is not in the record
    (ccsds.PacketReport); other formats have none. The command line prints them as
    warnings, :func:`read_telemetry` logs them.
    """
    from rwa_monitor.telemetry import rosbag_io
    if xtce or telemetry_map or is_packets(path):
        return read_packet_file(path, xtce, telemetry_map)
    if rosbag_io.is_recording(path):
        return rosbag_io.read(path, topics), []
    return _read_file(path), []


def _read_file(path: str | os.PathLike) -> Telemetry:
    """Read a CSV or Parquet file."""
    if not os.path.exists(path):
        from rwa_monitor.telemetry.atomic import path_problem
        raise TelemetrySchemaError(os.fspath(path), path_problem(path))
    if os.path.isdir(path):
        raise TelemetrySchemaError(os.fspath(path), 'a folder without metadata.yaml is not '
                                   'a rosbag2 recording')
    from rwa_monitor.telemetry import parquet_io
    if parquet_io.is_parquet(path):
        return parquet_io.read_parquet(path)
    return read_csv(path)


def read_packet_file(path: str | os.PathLike, xtce: str | os.PathLike | None = None,
                     telemetry_map: str | os.PathLike | None = None
                     ) -> tuple[Telemetry, list[str]]:
    """Read a packet file (definitions as :func:`packet_definitions`) and its report lines."""
    from rwa_monitor.telemetry.ccsds import read_packets
    if not os.path.isfile(path):
        raise TelemetrySchemaError(os.fspath(path), 'no such packet file')
    xml, yml = packet_definitions(path, xtce, telemetry_map)
    tele, report = read_packets(path, xml, yml)
    return tele, [f'{os.fspath(path)}: {line}' for line in report.lines()]


def write_telemetry(path: str | os.PathLike, telemetry: Telemetry,
                    topics: str | None = None) -> None:
    """Write a telemetry file or recording, the format chosen by the path (module doc).

    Parameters
    ----------
    path : str or path
        ``.mcap`` or ``.db3``: a bare recording file; no suffix (or an existing recording
        folder): a rosbag2 folder; ``.bin``: space packets with ``FILE.xml`` and
        ``FILE_map.yaml`` beside them; ``.parquet``: Parquet (parquet_io); anything else:
        CSV.
    telemetry : Telemetry
        The record to write (atomically: a reader never sees half a file).
    topics : str, optional
        A recording's topic per stream, ``wheels=/a,gyro=/b`` (others keep the DESIGN.md
        names), as another system would name them; ConfigError for a CSV file.

    Returns
    -------
    None

    Examples
    --------
    >>> import pathlib, tempfile
    >>> import numpy as np
    >>> path = pathlib.Path(tempfile.mkdtemp()) / 'record.csv'
    >>> write_telemetry(path, Telemetry(np.arange(2) * 0.5, {'rw1': Wheel(np.ones(2))}))
    >>> path.read_text().splitlines()[0]
    'time,rw1_speed'
    """
    from rwa_monitor.telemetry import parquet_io, rosbag_io
    target = pathlib.Path(path)
    recording = not is_stream(target) and not is_packets(target) and (
        rosbag_io.is_recording(target) or not target.suffix)
    if topics and not recording:
        raise ConfigError(f'{target}: --topics names the topics of a recording (a folder '
                          'name without suffix, .mcap or .db3), not of another file')
    if is_stream(target):
        write_csv(target, telemetry)   # a FIFO or device (-o /dev/null): CSV, streamed
    elif is_packets(target):
        from rwa_monitor.telemetry.ccsds_write import write_packets
        write_packets(target, telemetry)
    elif recording:
        rosbag_io.write(target, telemetry, topics)
    elif parquet_io.is_parquet(target):
        parquet_io.write_parquet(target, telemetry)
    else:
        write_csv(target, telemetry)
