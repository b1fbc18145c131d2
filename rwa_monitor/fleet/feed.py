"""A pass's samples into a streaming LLR detector, the per-sample loop compiled.

:meth:`rwa_monitor.core.llr.LLRDetector.update` on the paper's model (once its noise model
is fitted) is one compiled kernel call per sample (core/llr_kernel.py ``step``) and, on
the rare sample whose flags ask for it, the detector's Python follow-up (revision,
exact tail, declaration). :func:`feed` runs that same sequence over whole arrays: the
loop over samples is compiled too and returns to Python only at a flagged sample, where
the detector's own follow-up runs; every other case goes through ``update`` sample by
sample. Same calls in the same order, so the same events and state (test/test_fleet.py
checks against ``detect``); about five times less CPU than calling ``update`` from
Python for each sample.

It reads the detector's kernel state (``_fs``, ``_ints``, ``_fast``, ``_after``): the
natural home of this loop is the detector itself. A detector that has its own loop over
arrays (``process_arrays``, same contract) is fed through that instead; this module's
loop then goes.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rwa_monitor.core import llr_kernel
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.jit import njit

_step = llr_kernel.step


@njit(cache=True)
def _until_flag(fs, ints, t, w, f, start):
    """Run ``step`` from sample ``start``; return (index of the first flagged one, flags)."""
    for i in range(start, t.shape[0]):
        flags = _step(fs, ints, t[i], w[i], f[i])
        if flags:
            return i, flags
    return t.shape[0], 0


def feed(detector: Any, time: np.ndarray, speed: np.ndarray, friction: np.ndarray
         ) -> list[AnomalyEvent]:
    """Feed the samples to ``detector`` in order; return the events (as ``update``)."""
    if hasattr(detector, 'process_arrays'):     # the detector's own loop, where it has one
        return detector.process_arrays(time, speed, friction)
    t, w, f = (np.ascontiguousarray(a, dtype=float) for a in (time, speed, friction))
    events: list[AnomalyEvent] = []
    i, n = 0, t.shape[0]
    while i < n and not detector._fast:       # fitting the noise model, other models
        events.extend(detector.update(float(t[i]), float(w[i]), float(f[i])))
        i += 1
    while i < n:
        i, flags = _until_flag(detector._fs, detector._ints, t, w, f, i)
        if flags:
            events.extend(detector._after(flags))
            i += 1
    return events
