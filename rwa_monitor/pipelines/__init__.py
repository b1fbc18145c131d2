"""Detectors run on a whole telemetry file: one module per detector.

Each module has ``applies(tele) -> bool`` (the file has the detector's input columns) and
``run(tele, config) -> list[AnomalyEvent]``; ``config`` is the detector's block of
parameters (the node's block in config/rwa_monitor.yaml, same names). ``rwa-monitor
detect``, the demo summary and the benchmarks call these, so a file gives the same events
everywhere.
"""

from __future__ import annotations

import importlib
import pkgutil
from types import ModuleType


def available() -> dict[str, ModuleType]:
    """Return pipeline name -> module, for every detector module of this package.

    A detector module has ``applies`` and ``run``; helper modules (identify_report) are
    not detectors.
    """
    modules = {m.name: importlib.import_module(f'{__name__}.{m.name}')
               for m in pkgutil.iter_modules(__path__)}
    return {k: v for k, v in modules.items() if hasattr(v, 'applies') and hasattr(v, 'run')}
