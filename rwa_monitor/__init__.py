"""rwa_monitor: reaction-wheel and attitude-sensor health monitoring for ROS 2 Jazzy.

The Python API, without ROS (names load on first use, so ``import rwa_monitor`` is cheap)::

    from rwa_monitor import LLRDetector, detect_batch, VsadcDetector, FssDiagnoser

Streaming detectors follow :class:`StreamingDetector` (``reset``, ``counters``,
``params``, ``last_event``) and their family's typed ``update``: :class:`WheelDetector`,
:class:`GyroDetector` or :class:`WindowDiagnoser`; their parameters are defined in
:data:`SCHEMAS` (docs/parameters.md). docs/architecture.md shows the layers.
"""

from __future__ import annotations

import importlib
from typing import Any

__version__ = '0.1.0'

_EXPORTS = {
    'AnomalyEvent': 'rwa_monitor.core.events',
    'AUTO': 'rwa_monitor.core.params',
    'SCHEMAS': 'rwa_monitor.core.schema',
    'StreamingDetector': 'rwa_monitor.core.protocol',
    'WheelDetector': 'rwa_monitor.core.protocol',
    'GyroDetector': 'rwa_monitor.core.protocol',
    'WindowDiagnoser': 'rwa_monitor.core.protocol',
    'LLRDetector': 'rwa_monitor.core.llr',
    'detect_batch': 'rwa_monitor.core.llr',
    'VsadcDetector': 'rwa_monitor.core.vsadc',
    'GyroDiagnosis': 'rwa_monitor.core.gyro_diagnosis',
    'FssDiagnoser': 'rwa_monitor.core.fss.diagnoser',
    'WindowDiagnosis': 'rwa_monitor.core.fss.diagnoser',
    'diagnose_window': 'rwa_monitor.core.fss.pipeline:diagnose',
    'identify': 'rwa_monitor.core.identify.select',
    'Telemetry': 'rwa_monitor.telemetry',
    'read_telemetry': 'rwa_monitor.telemetry',
    'write_telemetry': 'rwa_monitor.telemetry',
    'load_fss_model': 'rwa_monitor.telemetry.fss_model:load_model',
    'detect_file': 'rwa_monitor.pipelines:detect',
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    """Import an exported name from its module on first use (PEP 562)."""
    if name not in _EXPORTS:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    module, _, attribute = _EXPORTS[name].partition(':')
    value = getattr(importlib.import_module(module), attribute or name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(list(globals()) + __all__)
