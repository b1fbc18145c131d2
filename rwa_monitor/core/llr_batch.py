"""The LLR detector over whole arrays (llr-realtime paper, Algorithm 1).

Gives exactly the events and counters of :class:`rwa_monitor.core.llr_detector.LLRDetector`
fed the same samples, because it runs the same code: for the paper's model (eq. (1)) the
detector's per-sample kernel over the arrays with the loop compiled
(``LLRDetector.process_arrays``); for other regressor sets (p > 2, auxiliary channels) the
regressor rows are computed once for the file and fed to the detector's per-row path.
:func:`rwa_monitor.core.llr.detect_batch` is the public entry point.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.llr_common import validate_parameters
from rwa_monitor.core.llr_detector import LLRDetector


def as_arrays(time, speed, friction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the three columns as 1-D float arrays of one length (ValueError if not)."""
    arrays = []
    for name, values in (('time', time), ('speed', speed), ('friction', friction)):
        a = np.asarray(values, dtype=float)
        if a.ndim != 1:
            raise ValueError(f'{name} must be a 1-D array, got shape {a.shape}')
        arrays.append(a)
    n = {a.size for a in arrays}
    if len(n) != 1:
        raise ValueError('time, speed and friction must have the same length, got '
                         f'{arrays[0].size}, {arrays[1].size}, {arrays[2].size}')
    return arrays[0], arrays[1], arrays[2]


def accepted_mask(t: np.ndarray, w: np.ndarray, f: np.ndarray, max_speed: float,
                  max_friction: float, row_ok: np.ndarray | None = None
                  ) -> tuple[np.ndarray, dict[str, int]]:
    """Return the samples the streaming detector accepts, and the rejection counts.

    Checks in the streaming order (core/llr_kernel.py ``accept``): finite time, speed and
    friction (else ``non_finite``); speed and friction within the bounds (else
    ``out_of_range``); time after the last accepted time (else ``non_increasing_time``);
    finite regressor row ``row_ok`` (else ``non_finite``). The last accepted time before a
    sample equals the running maximum of the times of the earlier samples that pass all
    checks but the time check.
    """
    finite = np.isfinite(t) & np.isfinite(w) & np.isfinite(f)
    with np.errstate(invalid='ignore'):
        inrange = finite & (np.abs(w) < max_speed) & (np.abs(f) < max_friction)
    cand = inrange if row_ok is None else inrange & row_ok
    tf = np.where(cand, t, -np.inf)
    prev = np.empty_like(tf)
    prev[:1] = -np.inf
    np.maximum.accumulate(tf[:-1], out=prev[1:])
    timely = t > prev
    accepted = cand & timely
    bad_row = 0 if row_ok is None else int(np.count_nonzero(inrange & timely & ~row_ok))
    counts = {'non_finite': int(np.count_nonzero(~finite)) + bad_row,
              'out_of_range': int(np.count_nonzero(finite & ~inrange)),
              'non_increasing_time': int(np.count_nonzero(inrange & ~timely))}
    return accepted, counts


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
    cfg = validate_parameters(component, **params)
    t, w, f = as_arrays(time, speed, friction)
    if cfg['regressors'].is_coulomb_viscous:
        det = LLRDetector(component, **params)
        events = det.process_arrays(t, w, f) + det.finish()
        return events, det.counters
    return _streamed(t, w, f, aux, component, params)


def _streamed(t: np.ndarray, w: np.ndarray, f: np.ndarray,
              aux: Mapping[str, np.ndarray] | None, component: str,
              params: Mapping[str, Any]) -> tuple[list[AnomalyEvent], dict[str, int]]:
    """Run the streaming detector on precomputed rows (models other than eq. (1)).

    The regressor matrix is computed once for the whole file; acceptance follows the
    streaming order of checks (finite time, speed and friction; increasing time; finite
    row). If the model cannot be evaluated on the file (missing auxiliary channel), the
    rows are fed one by one through ``update`` instead.
    """
    det = LLRDetector(component, **params)
    aux_arrays = None
    if aux:
        aux_arrays = {}
        for name, values in aux.items():
            col = np.asarray(values, dtype=float)
            if col.shape != t.shape:
                raise ValueError(f'aux[{name!r}] must have the length of time ({t.size}), '
                                 f'got {col.size}')
            aux_arrays[name] = col
    cfg = det.params
    try:
        with np.errstate(all='ignore'):
            h = cfg['regressors'].matrix(w, t, aux_arrays)
    except (KeyError, TypeError):
        return _row_by_row(det, t, w, f, aux_arrays)
    accepted, counts = accepted_mask(t, w, f, cfg['max_abs_speed'], cfg['max_abs_friction'],
                                     np.all(np.isfinite(h), axis=1))
    events: list[AnomalyEvent] = []
    for i in np.flatnonzero(accepted):
        events.extend(det.ingest_row(int(i), float(t[i]), float(f[i]), h[i], float(w[i])))
    events.extend(det.finish())
    counters = det.counters
    for name, value in counts.items():
        counters[name] += value
    return events, counters


def _row_by_row(det: LLRDetector, t: np.ndarray, w: np.ndarray, f: np.ndarray,
                aux: Mapping[str, np.ndarray] | None
                ) -> tuple[list[AnomalyEvent], dict[str, int]]:
    names = list(aux) if aux else []
    events: list[AnomalyEvent] = []
    for i in range(t.size):
        row_aux = {name: float(aux[name][i]) for name in names} if aux else None
        events.extend(det.update(float(t[i]), float(w[i]), float(f[i]), row_aux))
    return events + det.finish(), det.counters
