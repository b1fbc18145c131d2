"""Anomaly events of a window diagnosis: one builder for ``rwa-monitor diagnose`` and the node.

:func:`window_events` turns one wheel's window diagnosis
(:func:`rwa_monitor.core.fss.pipeline.diagnose`) into :class:`AnomalyEvent` records: the
CLI calls it once per wheel on its window, the ``fss_diagnoser`` node on every window it
diagnoses (with the previous window's flags), so both say the same change time, kind and
fields for the same window.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from rwa_monitor.core import keys
from rwa_monitor.core.events import AnomalyEvent

DETECTOR = 'fss'


def window_events(component: str, result: Mapping[str, Any], time_s: np.ndarray,
                  first_index: int = 0, previous: Mapping[str, bool] | None = None
                  ) -> list[AnomalyEvent]:
    """Return an event per anomaly the window flags and ``previous`` did not.

    The change time and index are those of the first sample of the part of the window
    that was diagnosed (``estimates['diagnosed_from_index']``): the window's last onset
    (docs/fss.md, "Onsets": a persistent dry or viscous step found inside the window,
    after which the wheel was diagnosed), or the window's first sample when it holds
    none (the change began at or before it: a window cannot date it more closely). The
    declaration is the window's last sample. Details: the window's bounds and the
    extracted base dry friction, viscous coefficient and noise std of the diagnosed part.

    Parameters
    ----------
    component : str
        The wheel id.
    result : mapping
        The window's diagnosis (``anomalies``, ``estimates``).
    time_s : ndarray, shape (n,)
        The window's stamps (s).
    first_index : int
        Row (stream) index of the window's first sample.
    previous : mapping of str to bool, optional
        The flags of the wheel's previous window: a kind flagged there too is not new.

    Examples
    --------
    >>> import numpy as np
    >>> result = {'anomalies': {'dry': True, 'viscous': False},
    ...           'estimates': {'base_dry_nm': 4e-4, 'viscous_nms': 5e-7,
    ...                         'noise_std_nm': 5e-5, 'diagnosed_from_index': 300}}
    >>> (event,) = window_events('rw2', result, np.arange(1000) * 0.1, first_index=5000)
    >>> event.kind, event.time, event.index, event.declared_index
    ('dry', 30.0, 5300, 5999)
    >>> window_events('rw2', result, np.arange(1000) * 0.1, previous={'dry': True})
    []
    """
    previous = previous or {}
    new = [kind for kind, flagged in result.get('anomalies', {}).items()
           if flagged and not previous.get(kind)]
    if not new:
        return []
    est = result['estimates']
    start = int(est.get('diagnosed_from_index') or 0)
    last = len(time_s) - 1
    details = {keys.WINDOW_START: float(time_s[0]), keys.WINDOW_END: float(time_s[last]),
               keys.BASE_DRY: est['base_dry_nm'], keys.VISCOUS: est['viscous_nms'],
               keys.NOISE_STD: est['noise_std_nm']}
    return [AnomalyEvent(detector=DETECTOR, component=component, kind=kind,
                         time=float(time_s[start]), index=int(first_index) + start,
                         declared_time=float(time_s[last]),
                         declared_index=int(first_index) + last, details=dict(details))
            for kind in new]
