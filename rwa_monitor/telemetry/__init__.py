"""Telemetry files: CSV (the schema of DESIGN.md) and MCAP, by file extension."""

from __future__ import annotations

import importlib
import os

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.telemetry.csv_io import read_csv, write_csv
from rwa_monitor.telemetry.schema import Telemetry, Wheel

__all__ = ['Telemetry', 'Wheel', 'read_telemetry', 'write_telemetry']

# Extension -> module with read(path) -> Telemetry and write(path, Telemetry).
_FORMATS = {'.mcap': 'rwa_monitor.telemetry.mcap_io'}


def read_telemetry(path: str | os.PathLike) -> Telemetry:
    """Read a telemetry file, choosing the format by its extension (default CSV)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext in _FORMATS:
        return importlib.import_module(_FORMATS[ext]).read(path)
    if not os.path.exists(path):
        raise TelemetrySchemaError(os.fspath(path), 'no such file')
    return read_csv(path)


def write_telemetry(path: str | os.PathLike, telemetry: Telemetry) -> None:
    """Write a telemetry file, choosing the format by its extension (default CSV)."""
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext in _FORMATS:
        importlib.import_module(_FORMATS[ext]).write(path, telemetry)
    else:
        write_csv(path, telemetry)
