"""Detectors run on a whole telemetry file: one module per detector.

Each module has ``applies(tele) -> bool`` (the file has the detector's input columns) and
``run(tele, config) -> list[AnomalyEvent]``; ``config`` is the detector's block of
parameters (``SCHEMA``, core/schema.py: the node's block in config/rwa_monitor.yaml, same
names). :func:`detect` runs every applicable one: ``rwa-monitor detect``, the demo summary
and the benchmarks call these, so a file gives the same events everywhere.
"""

from __future__ import annotations

import importlib
import pkgutil
import time
from types import ModuleType
from typing import Any, NamedTuple

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry import Telemetry
from rwa_monitor.telemetry.parameters_file import block_values


class Detection(NamedTuple):
    """Events of a run (sorted by change time) and its summary (JSON-ready facts)."""

    events: list[AnomalyEvent]
    summary: dict[str, Any]


def available() -> dict[str, ModuleType]:
    """Return pipeline name -> module, for every detector module of this package.

    A detector module has ``applies`` and ``run``; helper modules (identify_report) are
    not detectors.
    """
    modules = {m.name: importlib.import_module(f'{__name__}.{m.name}')
               for m in pkgutil.iter_modules(__path__)}
    return {k: v for k, v in modules.items() if hasattr(v, 'applies') and hasattr(v, 'run')}


def detect(tele: Telemetry, config: dict[str, Any], where: Any = 'parameters'
           ) -> Detection:
    """Run every applicable pipeline; return (events sorted by time, summary).

    Parameters
    ----------
    tele : Telemetry
        The record; each pipeline whose input columns it has runs on it.
    config : dict
        The node blocks of a parameters file (``{}``: every default).
    where : str or path
        The parameters file's name, used in error messages.

    Returns
    -------
    Detection
        ``events`` (AnomalyEvents sorted by change time) and ``summary`` (JSON-ready
        facts per pipeline: events, components, counters, runtime).

    Examples
    --------
    >>> import numpy as np
    >>> from rwa_monitor.telemetry import Telemetry, Wheel
    >>> t = np.arange(3000) * 0.1
    >>> speed = 200.0 + 150.0 * np.sin(t / 20.0)
    >>> noise = np.random.default_rng(0).normal(0.0, 5e-5, t.size)
    >>> friction = -(2e-4 + 4e-4 * (t >= 150.0)) - 5e-7 * speed + noise
    >>> events, summary = detect(Telemetry(t, {'rw1': Wheel(speed, friction)}), {})
    >>> [(e.component, e.kind, round(e.time, 1), e.revision) for e in events]
    [('rw1', 'dry', 150.0, 0), ('rw1', 'dry', 150.0, 1)]

    The file ends before the declaration's last re-check: its final categorisation on every
    sample after the change is the last revision (docs/llr.md "End of record").

    >>> events[-1].details['final'], list(summary['pipelines'])
    (True, ['llr'])
    """
    events: list[AnomalyEvent] = []
    summary: dict[str, Any] = {'samples': len(tele), 'source': tele.source, 'pipelines': {}}
    for name, module in sorted(available().items()):
        if not module.applies(tele):
            continue
        params = block_values(config, module.SCHEMA, where)
        start = time.perf_counter()
        try:
            if hasattr(module, 'run_with_summary'):
                found, components = module.run_with_summary(tele, params)
            else:
                found, components = module.run(tele, params), {}
        except ValueError as err:
            raise ConfigError(f'{name}: {err}') from None
        _count_kinds(found, components)
        summary['pipelines'][name] = {'events': len(found), 'components': components,
                                      'runtime_s': time.perf_counter() - start}
        events.extend(found)
    events.sort(key=lambda e: (e.time, e.component, e.revision))
    summary['events'] = len(events)
    return Detection(events, summary)


def _count_kinds(events: list[AnomalyEvent], components: dict[str, Any]) -> None:
    """Add per component the number of changes and their kinds (latest revision)."""
    latest: dict[tuple[str, int], AnomalyEvent] = {}
    for e in events:
        key = (e.component, e.index)
        if key not in latest or e.revision >= latest[key].revision:
            latest[key] = e
    for (component, _), e in sorted(latest.items()):
        entry = components.setdefault(component, {})
        entry['changes'] = entry.get('changes', 0) + 1
        kinds = entry.setdefault('by_kind', {})
        kinds[e.kind] = kinds.get(e.kind, 0) + 1
