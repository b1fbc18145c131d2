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

    ``config`` holds the node blocks of a parameters file; ``where`` names it in errors.
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
