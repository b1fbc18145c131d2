"""The way of an accepted sample into the LLR detector: noise fit, scaling, whitening.

llr-realtime paper, Algorithm 1 (one accepted sample enters the sums, then the test); not
in the paper (docs/llr.md "Noise beyond white", "Noise growing with speed"): while the
noise model is fitted the samples wait in the state's ``SampleBuffer``; once it is fitted
(core/llr_noise.py) they are replayed, and every sample is divided by the modelled noise
level and AR-filtered before it enters the sums: in the compiled kernel for p = 2
(core/llr_kernel.py), in core/llr_general.py for larger models. Also the whole-array
acceptance of models other than the paper's (:func:`process_rows`). Every function
receives the working state (core/llr_state.py ``Live``) and the configuration.
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from rwa_monitor.core import llr_changes, llr_general, llr_kernel as kern
from rwa_monitor.core import llr_layout as layout
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.jit import kernel_array
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_noise import (fit_noise_model, speed_fit_done, speed_fit_ready,
                                        speed_scale)
from rwa_monitor.core.llr_state import Live


def as_arrays(time, speed, friction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the columns as contiguous 1-D float arrays of one length (ValueError if not)."""
    arrays = []
    for name, values in (('time', time), ('speed', speed), ('friction', friction)):
        a = kernel_array(values)
        if a.ndim != 1:
            raise ValueError(f'{name} must be a 1-D array, got shape {a.shape}')
        arrays.append(a)
    if len({a.size for a in arrays}) != 1:
        raise ValueError('time, speed and friction must have the same length, got '
                         f'{arrays[0].size}, {arrays[1].size}, {arrays[2].size}')
    return arrays[0], arrays[1], arrays[2]


def regressor_row(live: Live, config: LLRConfig, t: float, w: float,
                  aux: Mapping[str, float] | None) -> np.ndarray | None:
    """Return the regressor row of one sample, or None (missing channel, non-finite; counted)."""
    if aux is not None:
        aux = {name: np.asarray([value], dtype=float) for name, value in aux.items()}
    try:
        h = config.regressors.matrix(np.asarray([w]), np.asarray([t]), aux)[0]
    except (KeyError, TypeError):
        live.counters['missing_aux'] += 1
        return None
    if not np.all(np.isfinite(h)):
        live.counters['non_finite'] += 1
        return None
    return h


def ingest(live: Live, config: LLRConfig, row: int, t: float, f: float, h, speed: float
           ) -> list[AnomalyEvent]:
    """Process an accepted sample whose regressor row ``h`` is computed; return its events.

    While the noise model is being fitted the sample is buffered; once fitted the buffer
    is replayed (:func:`fit_and_replay`), and every sample is prewhitened (divided by the
    modelled noise level at ``|speed|``, then AR-filtered) before it enters the sums.
    """
    buffer = live.fit
    if buffer is None:
        return ingest_fitted(live, config, row, t, f, h, speed)
    buffer.append(row, t, f, h, speed)
    if config.noise_speed_model:
        aw = abs(speed)
        buffer.speed_low = min(buffer.speed_low, aw)
        buffer.speed_high = max(buffer.speed_high, aw)
        if buffer.next_fit is None:
            if not speed_fit_ready(len(buffer), config.noise_fit_samples, buffer.speed_low,
                                   buffer.speed_high):
                return []
        elif len(buffer) < buffer.next_fit:
            return []
    elif len(buffer) < config.noise_fit_samples:
        return []
    return fit_and_replay(live, config)


def buffer_arrays(live: Live, config: LLRConfig, t: np.ndarray, w: np.ndarray, f: np.ndarray,
                  start: int) -> int:
    """Buffer the samples from ``start`` on (paper's model) up to the fit; return the next.

    The acceptance loop compiled (core/llr_kernel.py ``accept_run``); the buffer holds
    what the streaming path would have put in it, sample by sample (the regressors
    ``(-sign w, -w)`` formed with numpy: the same floats).
    """
    buffer = live.fit
    rows = np.full(config.noise_fit_samples - len(buffer), -1, dtype=np.int64)
    row0 = int(live.ints[layout.I_ROWS])
    end = kern.accept_run(live.floats, live.ints, t, w, f, start, rows)
    rows = rows[rows >= 0]
    at = start + rows - row0
    speed = w[at]
    h = np.column_stack([np.where(speed > 0.0, -1.0, np.where(speed < 0.0, 1.0, 0.0)),
                         -speed])
    buffer.extend(rows, t[at], f[at], speed, h)
    return end


def fit_and_replay(live: Live, config: LLRConfig) -> list[AnomalyEvent]:
    """Fit the noise model on the buffered samples, then process them; return the events.

    With the speed noise model a fit that is not final (core/llr_noise.py
    ``speed_fit_done``) is tried again ``noise_fit_samples`` later.
    """
    buffer = live.fit
    rows, times, friction, speed, h = buffer.columns()
    speeds = np.abs(speed) if config.noise_speed_model else None
    model = fit_noise_model(h, friction, config.noise_ar_max_order, speeds)
    if config.noise_speed_model and not speed_fit_done(len(buffer), config.noise_fit_samples,
                                                       model):
        buffer.next_fit = len(buffer) + config.noise_fit_samples
        return []
    live.fit = None
    live.noise = model
    if config.p != 2:
        events: list[AnomalyEvent] = []
        for i in range(rows.size):
            events.extend(ingest_fitted(live, config, int(rows[i]), float(times[i]),
                                        float(friction[i]), h[i], float(speed[i])))
        return events
    fs, ints = live.floats, live.ints
    ints[layout.I_AR_ORDER] = len(model.ar)
    fs[ints[layout.I_O_AR]:ints[layout.I_O_AR] + len(model.ar)] = model.ar
    if model.speed_std is not None:
        ints[layout.I_SPEED_MODEL] = 1
        fs[layout.F_SPEED_A:layout.F_SPEED_FLOOR + 1] = model.speed_std
        level = speed_scale(np.abs(speed), model.speed_std)
        friction = friction / level
        h = h / level[:, None]
    return replay(live, config, np.ascontiguousarray(rows, dtype=np.int64),
                  np.ascontiguousarray(times, dtype=float),
                  np.ascontiguousarray(friction, dtype=float),
                  np.ascontiguousarray(h[:, 0]), np.ascontiguousarray(h[:, 1]))


def replay(live: Live, config: LLRConfig, rows: np.ndarray, t: np.ndarray, f: np.ndarray,
           h1: np.ndarray, h2: np.ndarray) -> list[AnomalyEvent]:
    """Feed buffered samples of a two-column model, already scaled, to the kernel.

    The loop compiled (core/llr_kernel.py ``ingest_run``: the AR filter, the sums and
    the test of each sample in turn), Python at the samples whose flags need it: the
    per-sample path of :func:`ingest_fitted`, over arrays.
    """
    events: list[AnomalyEvent] = []
    i, n = 0, rows.size
    while i < n:
        i = kern.ingest_run(live.floats, live.ints, rows, t, f, h1, h2, i)
        if i < n:
            events.extend(llr_changes.after(live, config, layout.take_flags(live.ints)))
        i += 1
    return events


def ingest_fitted(live: Live, config: LLRConfig, row: int, t: float, f: float, h,
                  speed: float) -> list[AnomalyEvent]:
    """Scale and whiten one accepted sample by the noise model, add it and test it."""
    noise = live.noise
    if noise is not None and noise.speed_std is not None:
        level = speed_scale(abs(speed), noise.speed_std)
        f = f / level
        if config.p == 2:
            h = (float(h[0]) / level, float(h[1]) / level)
        else:
            h = np.asarray(h, dtype=float) / level
    if config.p == 2:
        flags = kern.ingest(live.floats, live.ints, row, t, f, float(h[0]), float(h[1]))
    else:
        if noise is not None and noise.ar:
            if kern.sequence_breaks(live.floats, live.ints, int(live.ints[layout.I_POS]),
                                    row, t):
                llr_general.forget_lags(live)
            f, h = llr_general.whiten(live, noise.ar, f, h)
        flags = llr_general.ingest(live, config, row, t, f, np.asarray(h, dtype=float))
    return llr_changes.after(live, config, flags) if flags else []


def process_rows(live: Live, config: LLRConfig, t: np.ndarray, w: np.ndarray,
                 f: np.ndarray, aux: Mapping[str, np.ndarray] | None
                 ) -> list[AnomalyEvent] | None:
    """Process whole arrays for a model other than the paper's; None if it cannot be evaluated.

    The regressor rows are computed once for the arrays; acceptance follows the
    streaming order of checks (:func:`accepted_mask`), and the counters, rows and last
    accepted time end as the streaming path leaves them. None when the model cannot be
    evaluated on the arrays (a missing auxiliary channel): the caller then goes row by
    row.
    """
    try:
        with np.errstate(all='ignore'):
            h = config.regressors.matrix(w, t, aux)
    except (KeyError, TypeError):
        return None
    fs, ints = live.floats, live.ints
    accepted, counts = accepted_mask(t, w, f, config.max_abs_speed, config.max_abs_friction,
                                     np.all(np.isfinite(h), axis=1), float(fs[layout.F_LAST_T]))
    row0 = int(ints[layout.I_ROWS])
    events: list[AnomalyEvent] = []
    for i in np.flatnonzero(accepted):
        ints[layout.I_ROWS] = row0 + i + 1
        fs[layout.F_LAST_T] = t[i]
        events.extend(ingest(live, config, row0 + int(i), float(t[i]), float(f[i]), h[i],
                             float(w[i])))
    ints[layout.I_ROWS] = row0 + t.size
    ints[layout.I_NON_FINITE] += counts['non_finite']
    ints[layout.I_OUT_OF_RANGE] += counts['out_of_range']
    ints[layout.I_NON_INCREASING] += counts['non_increasing_time']
    live.counters['non_finite'] += counts['bad_row']
    return events


def accepted_mask(t: np.ndarray, w: np.ndarray, f: np.ndarray, max_speed: float,
                  max_friction: float, row_ok: np.ndarray | None = None,
                  last_time: float = -np.inf) -> tuple[np.ndarray, dict[str, int]]:
    """Return the samples the streaming detector accepts, and the rejection counts.

    Checks in the streaming order (core/llr_kernel.py ``accept``): finite time, speed and
    friction (else ``non_finite``); speed and friction within the bounds (else
    ``out_of_range``); time after the last accepted time (else ``non_increasing_time``,
    ``last_time`` before the first sample); finite regressor row ``row_ok`` (else
    ``bad_row``, a non-finite row). The last accepted time before a sample equals the
    running maximum of the times of the earlier samples that pass all checks but the
    time check.
    """
    finite = np.isfinite(t) & np.isfinite(w) & np.isfinite(f)
    with np.errstate(invalid='ignore'):
        inrange = finite & (np.abs(w) < max_speed) & (np.abs(f) < max_friction)
    cand = inrange if row_ok is None else inrange & row_ok
    tf = np.where(cand, t, -np.inf)
    prev = np.maximum.accumulate(np.concatenate([[last_time], tf[:-1]]))[:tf.size]
    timely = t > prev
    accepted = cand & timely
    bad_row = 0 if row_ok is None else int(np.count_nonzero(inrange & timely & ~row_ok))
    counts = {'non_finite': int(np.count_nonzero(~finite)),
              'out_of_range': int(np.count_nonzero(finite & ~inrange)),
              'non_increasing_time': int(np.count_nonzero(inrange & ~timely)),
              'bad_row': bad_row}
    return accepted, counts
