"""Telemetry files: CSV (the schema of DESIGN.md) and rosbag2 recordings, by path.

A rosbag2 folder (``metadata.yaml`` with ``.mcap`` or ``.db3`` storage) or a bare ``.mcap``
or ``.db3`` file is a recording (rosbag_io); a ``.parquet`` file is read by parquet_io;
anything else is read as CSV. Writing: a
``.mcap`` or ``.db3`` path writes a bare file, a path without a suffix (or an existing
recording folder) a rosbag2 folder, any other path CSV; a FIFO or a device (``-o
/dev/null``) gets CSV written straight into it (telemetry/atomic.py).
"""

from __future__ import annotations

import os
import pathlib
from typing import Mapping

from rwa_monitor.exceptions import ConfigError, TelemetrySchemaError
from rwa_monitor.telemetry.atomic import is_stream
from rwa_monitor.telemetry.csv_io import read_csv, write_csv
from rwa_monitor.telemetry.schema import STREAMS, Telemetry, Wheel

__all__ = ['STREAMS', 'Telemetry', 'Wheel', 'read_telemetry', 'write_telemetry']


def read_telemetry(path: str | os.PathLike,
                   topics: str | Mapping[str, str] | None = None) -> Telemetry:
    """Read a telemetry file or recording (the format from the path, module doc).

    Parameters
    ----------
    path : str or path
        A CSV file, a rosbag2 folder, or a bare ``.mcap`` or ``.db3`` file.
    topics : str or mapping, optional
        Stream -> topic of a recording (``wheels=/a,gyro=/b``); None: the default topics.

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
    from rwa_monitor.telemetry import rosbag_io
    if rosbag_io.is_recording(path):
        return rosbag_io.read(path, topics)
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


def write_telemetry(path: str | os.PathLike, telemetry: Telemetry,
                    topics: str | None = None) -> None:
    """Write a telemetry file or recording, the format chosen by the path (module doc).

    Parameters
    ----------
    path : str or path
        ``.mcap`` or ``.db3``: a bare recording file; no suffix (or an existing recording
        folder): a rosbag2 folder; anything else: CSV.
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
    from rwa_monitor.telemetry import rosbag_io
    target = pathlib.Path(path)
    recording = not is_stream(target) and (rosbag_io.is_recording(target) or not target.suffix)
    if topics and not recording:
        raise ConfigError(f'{target}: --topics names the topics of a recording (a folder '
                          'name without suffix, .mcap or .db3), not of a CSV file')
    if recording:
        rosbag_io.write(target, telemetry, topics)
    else:
        write_csv(target, telemetry)   # a FIFO or device (-o /dev/null) included: streamed
