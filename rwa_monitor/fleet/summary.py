"""The fleet's summary.json: per spacecraft and component, what was examined and found.

Per spacecraft: its calibration, the passes run in time order, the passes already in the
state (skipped), the unreadable ones with their reason, entries ignored, rows dropped
(stamped at or before the last one processed) and ``not_examined`` (component or pass
-> why). Per component: passes, samples, rows dropped, events by kind (every event,
revisions included), the detector's counters (``rejected``; ``not_tested`` when
calibrated; per axis for the gyro) and ``not_examined`` (detect's coverage rules).
"""

from __future__ import annotations

from collections import Counter
from typing import Any, Mapping

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.fleet.components import not_examined


def spacecraft_summary(entry: Mapping[str, Any], chains: Mapping[str, Mapping[str, Any]],
                       events: list[AnomalyEvent]) -> dict[str, Any]:
    """Return one spacecraft's summary (see the module docstring)."""
    craft = entry['craft']
    missing: dict[str, str] = {}
    if entry['error']:
        missing['spacecraft'] = entry['error']
    elif not entry['specs']:
        missing['spacecraft'] = 'no readable pass with a wheel friction or gyro column'
    missing.update({f'pass {name}': why for name, why in entry['unreadable'].items()})
    components = {}
    dropped = 0
    for spec in entry['specs']:
        chain = chains[spec.component]
        passes = chain['passes']
        failed = {p['pass']: p['error'] for p in passes if 'error' in p}
        for name, why in failed.items():
            if why and not any(k.startswith(f'pass {name}') for k in missing):
                missing[f'pass {name}' if _read_error(chains, name) else
                        f'{spec.component} in pass {name}'] = why
        mine = [e for e in events if _owner(e) == spec.component]
        reason = not_examined(spec, chain['facts']) if entry['passes'] or not entry['done'] \
            else None
        if reason:
            missing[spec.component] = reason
        rows = sum(p.get('rows_dropped', 0) for p in passes)
        dropped = max(dropped, rows)
        components[spec.component] = {
            'detector': spec.detector, 'passes': sum('error' not in p for p in passes),
            'samples': sum(p.get('samples', 0) for p in passes), 'rows_dropped': rows,
            'events': len(mine), 'by_kind': dict(Counter(e.kind for e in mine)),
            'not_examined': reason, **chain['facts']}
    return {'calibration': craft.calibration, 'passes': [p.name for p in entry['passes']],
            'already_processed': entry['skipped'], 'unreadable': dict(entry['unreadable']),
            'ignored': dict(craft.ignored), 'rows_dropped': dropped, 'events': len(events),
            'components': components, 'not_examined': missing}


def _owner(event: AnomalyEvent) -> str:
    """Return the fleet component of an event (gyro axes belong to the gyro)."""
    return 'gyro' if event.component.startswith('gyro_') else event.component


def _read_error(chains: Mapping[str, Mapping[str, Any]], name: str) -> bool:
    """Return True if every component failed on pass ``name`` (it could not be read)."""
    return all(any(p['pass'] == name and 'error' in p for p in c['passes'])
               for c in chains.values())
