"""The LLR detector over whole arrays (llr-realtime paper, Algorithm 1).

Gives exactly the events and counters of :class:`rwa_monitor.core.llr_detector.LLRDetector`
fed the same samples, because it is that detector: ``LLRDetector.process_arrays`` (for
the paper's model, eq. (1), the per-sample kernel with the loop compiled; for other
regressor sets the rows computed once), then ``finish``.
:func:`rwa_monitor.core.llr.detect_batch` is the public entry point.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.llr_detector import LLRDetector
from rwa_monitor.core.llr_samples import accepted_mask, as_arrays

__all__ = ['accepted_mask', 'as_arrays', 'detect_batch', 'detect_batch_with_counters']


def detect_batch(time, speed, friction, *, component: str = 'rw1',
                 aux: Mapping[str, np.ndarray] | None = None, **params: Any
                 ) -> list[AnomalyEvent]:
    """Run Algorithm 1 over whole arrays and return the events of the streaming detector.

    Parameters
    ----------
    time, speed, friction : array_like
        1-D arrays of the same length, one row per sample (event indices are row indices).
    component : str
        Wheel id of the events.
    aux : mapping of str to array_like, optional
        Auxiliary channels of a regressor set that needs them.
    **params
        Keyword parameters of :class:`LLRDetector`.

    Returns
    -------
    list of AnomalyEvent
        The events :meth:`LLRDetector.update` gives on the same rows, then those of
        :meth:`LLRDetector.finish` (the file has ended: the open declaration's final kind).

    Examples
    --------
    A dry-friction step of 4e-4 N m at 450 s on a wheel swinging between 50 and 350 rad/s:

    >>> import numpy as np
    >>> t = np.arange(0.0, 900.0, 0.1)
    >>> speed = 200.0 + 150.0 * np.sin(t / 40.0)
    >>> noise = np.random.default_rng(1).normal(0.0, 5e-5, t.size)
    >>> friction = -(2e-4 + 4e-4 * (t >= 450.0)) - 5e-7 * speed + noise
    >>> [(e.kind, round(e.time, 1)) for e in detect_batch(t, speed, friction, window=300)]
    [('dry', 450.0)]
    """
    events, _ = detect_batch_with_counters(time, speed, friction, component=component,
                                           aux=aux, **params)
    return events


def detect_batch_with_counters(time, speed, friction, *, component: str = 'rw1',
                               aux: Mapping[str, np.ndarray] | None = None, **params: Any
                               ) -> tuple[list[AnomalyEvent], dict[str, int]]:
    """Return ``(events, counters)`` of :func:`detect_batch` (counters as the detector's)."""
    det = LLRDetector(component, **params)
    events = det.process_arrays(time, speed, friction, aux)
    return events + det.finish(), det.counters
