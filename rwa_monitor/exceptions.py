"""The package's own errors, in one place."""

from __future__ import annotations


class RwaMonitorError(Exception):
    """Base class of every error this package raises on purpose."""


class TelemetrySchemaError(RwaMonitorError, ValueError):
    """A telemetry file that breaks the schema: names the file, the line and the column."""

    def __init__(self, path: str, message: str, line: int | None = None,
                 column: str | None = None) -> None:
        self.path = str(path)
        self.line = line
        self.column = column
        where = self.path
        if line is not None:
            where += f', line {line}'
        if column is not None:
            where += f', column {column!r}'
        super().__init__(f'{where}: {message}')


class ConfigError(RwaMonitorError, ValueError):
    """A configuration file or value that cannot be used."""


class JournalError(ConfigError):
    """An ``events_file`` that is not an alarm journal (foreign file, folder, device)."""


class NotIdentifiableError(RwaMonitorError, ValueError):
    """Data that cannot determine the parameters asked for (the message says which)."""


class OutputError(RwaMonitorError, OSError):
    """An output that cannot be written safely (names the path and the reason)."""


class NotExaminedError(RwaMonitorError):
    """Too few usable samples for any verdict (core/coverage.py): a command exits 3."""


class TooFewSamplesError(NotIdentifiableError, NotExaminedError):
    """Too few valid samples to identify a model: not identifiable, and not examined."""
