"""Anomaly events: one record type for every detector, the node and the CLI."""

from __future__ import annotations

from dataclasses import dataclass, field
import math
from typing import Any, Mapping

from rwa_monitor.core import keys
from rwa_monitor.core.records import Scalar


@dataclass(frozen=True)
class AnomalyEvent:
    """A declared anomaly.

    ``time``/``index`` are the *estimated change* time (s) and sample index; the
    declaration time and index say when the detector had enough evidence. ``revision``
    is 0 for a first declaration and n > 0 for the n-th explicit revision of the same
    change (e.g. its kind confirmed or corrected as more data arrived). ``details`` holds
    further fields, named from :mod:`rwa_monitor.core.keys`, units in the key.

    Parameters
    ----------
    detector : str
        The detector that declared it: ``llr``, ``vsadc`` or ``fss``.
    component : str
        What it concerns: a wheel id (``rw1``) or a gyro axis (``gyro_y``).
    kind : str
        The anomaly's kind (core/keys.py: ``dry``, ``viscous``, ``drift``, ``bias``, ...).
    time : float
        Estimated change time (s).
    index : int
        Row index of the estimated change.
    declared_time : float
        Time (s) at which the detector had enough evidence.
    declared_index : int
        Row index of the declaration.
    p_value : float
        Nominal p-value of the declaration; NaN when the detector gives none.
    revision : int
        0 for a first declaration, n > 0 for the n-th revision of the same change.
    details : mapping of str to value
        Further fields named from :mod:`rwa_monitor.core.keys`.

    Examples
    --------
    >>> event = AnomalyEvent('llr', 'rw1', 'dry', time=120.0, index=1200,
    ...                      declared_time=131.5, declared_index=1315)
    >>> event.declared_time - event.time, event.revision
    (11.5, 0)
    >>> event.to_json()['declared_index']
    1315
    """

    detector: str
    component: str
    kind: str
    time: float
    index: int
    declared_time: float
    declared_index: int
    p_value: float = math.nan
    revision: int = 0
    details: Mapping[str, Scalar] = field(default_factory=dict)

    def fields(self) -> dict[str, Any]:
        """Return the event as KeyValue key -> value (units in the key names)."""
        out: dict[str, Any] = {
            keys.DETECTOR: self.detector, keys.COMPONENT: self.component,
            keys.KIND: self.kind, keys.CHANGE_TIME: self.time,
            keys.CHANGE_INDEX: self.index, keys.DECLARATION_TIME: self.declared_time,
            keys.DECLARATION_INDEX: self.declared_index, keys.P_VALUE: self.p_value,
            keys.REVISION: self.revision,
        }
        out.update(self.details)
        return out

    def to_json(self) -> dict[str, Any]:
        """Return the event as the events-file JSON object (DESIGN.md contract)."""
        out = {}
        for key, value in self.fields().items():
            if isinstance(value, float) and not math.isfinite(value):
                value = None
            out[keys.JSON_NAME.get(key, key)] = value
        return out
