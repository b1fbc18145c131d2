"""Vectorised LLR detector over whole arrays (llr-realtime paper, Algorithm 1).

Gives exactly the events of :class:`rwa_monitor.core.llr.LLRDetector` fed the same samples:
the prefix sums are accumulated in the same order (``numpy.cumsum`` adds sequentially,
continuing from the carried last row), the test statistic of every candidate ``k`` uses
the same float operations, and p_k, the skip rule, the declaration details and the
revisions use the same scalar functions. Vectorisation: the statistic, its trace and a
bound of p_k for all ``k`` of a chunk at once; a sample is evaluated exactly (in a Python
loop) only if its lower bound of p_k can beat the running minimum of the upper bounds, a
superset of the samples the streaming path evaluates. The only other Python loops run
over candidates, declarations and revision checkpoints.

Only the paper's two-column model is vectorised; other regressor sets (p > 2, auxiliary
channels) run the streaming detector sample by sample.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from rwa_monitor.core import llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gchi2 import log_lower_bound_array, skip_threshold
from rwa_monitor.core.llr import (candidate_log_p2, checkpoints, declaration, LLRDetector,
                                  make_event, validate_parameters)

CHUNK = 1 << 13
_PI_4 = math.pi / 4.0


def _arrays(time, speed, friction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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

    Checks in the streaming order: finite time, speed and friction (else ``nonfinite``);
    speed and friction within the bounds (else ``out_of_range``); time after the last
    accepted time (else ``non_increasing_time``); finite regressor row ``row_ok`` (else
    ``nonfinite``). The last accepted time before a sample equals the running maximum of
    the times of the earlier samples that pass all checks but the time check.
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
    counts = {'nonfinite': int(np.count_nonzero(~finite)) + bad_row,
              'out_of_range': int(np.count_nonzero(finite & ~inrange)),
              'non_increasing_time': int(np.count_nonzero(inrange & ~timely))}
    return accepted, counts


def _stats(pp: np.ndarray, pt: np.ndarray, n_p: np.ndarray, cfg: Mapping[str, Any]):
    """Vectorised statistic of the streaming path (same operations, same order).

    ``pp``, ``pt``: prefix rows at ``k`` and ``k + w``, shape ``(6, n)``.
    """
    A, B, C, U, V, E = pp[0], pp[1], pp[2], pp[3], pp[4], pp[5]
    At, Bt, Ct, Ut, Vt = pt[0], pt[1], pt[2], pt[3], pt[4]
    ac = A * C
    det = ac - B * B
    dett = At * Ct - Bt * Bt
    ok = (det > cfg['min_excitation'] * ac) & (dett > 0.0)
    with np.errstate(all='ignore'):
        x1 = (C * U - B * V) / det
        x2 = (A * V - B * U) / det
        if cfg['noise_std'] is None:
            s2 = (E - (x1 * U + x2 * V)) / (n_p - 2.0)
            floor = llr_stats.NOISE_FLOOR_REL * E / n_p + llr_stats.NOISE_FLOOR_ABS
            s2 = np.fmax(s2, floor)
        else:
            s2 = cfg['noise_std'] ** 2
        Aw = At - A
        Bw = Bt - B
        Cw = Ct - C
        g1 = (Ut - U) - (Aw * x1 + Bw * x2)
        g2 = (Vt - V) - (Bw * x1 + Cw * x2)
        d1 = (Ct * g1 - Bt * g2) / dett
        d2 = (At * g2 - Bt * g1) / dett
        y = (A * d1 * d1 + 2.0 * B * d1 * d2 + C * d2 * d2) / s2
        tr = (Ct * Aw - 2.0 * Bt * Bw + At * Cw) / dett
        dm = (Aw * Cw - Bw * Bw) / dett
        half = 0.5 * tr
        lam1 = half + np.sqrt(np.maximum(half * half - dm, 0.0))
        testable = ok & (tr > 0.0) & (y > 0.0)
        b = y / (2.0 * lam1)
        rho = np.maximum(dm / lam1, 0.0) / lam1
        a = np.maximum(b - b * rho, 0.0)
        # Bounds of log p_k: candidate_log_p2 (lower); upper: J <= i0e(a/2) (gchi2) and
        # i0e(z) = (1/pi) int_0^pi exp(-2 z sin^2(t/2)) dt <= int_0^1 exp(-2 z u^2) du
        # <= sqrt(pi / (8 z)) (sin s >= 2 s / pi), i.e. log J <= log(pi / (4 a)) / 2.
        if cfg['noise_std'] is None:
            # Studentised tail (log_sf2_t): at most its value at psi = 0.
            dof = n_p - 2.0
            upper = np.where(testable, -0.5 * dof * np.log1p(2.0 * b / dof), 0.0)
        else:
            upper = np.where(testable, np.minimum(0.5 * np.log(_PI_4 / a), 0.0) - b, 0.0)
        lower = log_lower_bound_array(a) - b * rho
    return ok, testable, y, tr, dm, upper, lower


class _Terms:
    """Per-sample terms ``(h1 h1, h1 h2, h2 h2, h1 f, h2 f, f f)``, built per block."""

    def __init__(self, h1: np.ndarray, h2: np.ndarray, f: np.ndarray):
        self.h1, self.h2, self.f = h1, h2, f

    def block(self, first: int, last: int) -> np.ndarray:
        """Return the terms of positions ``first..last - 1``, shape ``(6, n)``."""
        h1, h2, f = self.h1[first:last], self.h2[first:last], self.f[first:last]
        out = np.empty((6, h1.size))
        np.multiply(h1, h1, out=out[0])
        np.multiply(h1, h2, out=out[1])
        np.multiply(h2, h2, out=out[2])
        np.multiply(h1, f, out=out[3])
        np.multiply(h2, f, out=out[4])
        np.multiply(f, f, out=out[5])
        return out


class _Reference:
    """Prefix sums (shape ``(6, m)``) of one reference segment, extended chunk by chunk."""

    def __init__(self, terms: _Terms, c: int):
        self.terms = terms
        self.c = c
        self.pos0 = c
        self.rows = np.zeros((6, 1))

    @property
    def end(self) -> int:
        """Last position whose prefix is held."""
        return self.pos0 + self.rows.shape[1] - 1

    def extend(self, last: int) -> None:
        """Hold prefixes up to position ``last`` (sequential continuation of the sums)."""
        if last <= self.end:
            return
        block = np.concatenate([self.rows[:, -1:], self.terms.block(self.end, last)], axis=1)
        self.rows = np.concatenate([self.rows, np.cumsum(block, axis=1)[:, 1:]], axis=1)

    def trim(self, first: int) -> None:
        """Drop prefixes of positions before ``first``."""
        cut = first - self.pos0
        if cut > 0:
            self.rows = self.rows[:, cut:]
            self.pos0 = first

    def span(self, first: int, last: int) -> np.ndarray:
        """Return the prefixes of positions ``first..last`` as a ``(6, n)`` view."""
        return self.rows[:, first - self.pos0:last + 1 - self.pos0]

    def at(self, positions) -> np.ndarray:
        """Return the prefix rows at ``positions`` (shape ``(..., 6)``)."""
        return self.rows[:, np.asarray(positions) - self.pos0].T


def _scan(ref: _Reference, k0: int, k1: int, state: dict, cfg: Mapping[str, Any],
          logr: float) -> int | None:
    """Run the tests k0..k1 of Algorithm 1; return the declaration k or None."""
    w, kverif = cfg['window'], cfg['k_verif']
    c = ref.c
    ks = np.arange(k0, k1 + 1)
    ref.extend(k1 + w)
    ok, testable, y, tr, dm, upper, lower = _stats(ref.span(k0, k1), ref.span(k0 + w, k1 + w),
                                                   (ks - c).astype(float), cfg)
    bound = np.minimum.accumulate(np.concatenate([[state['bound']], upper]))
    state['bound'] = float(bound[-1])
    prev = bound[:-1]
    margin = 1e-6 * (1.0 + np.abs(prev))
    cand = np.flatnonzero(testable & (lower <= prev + margin))
    dof = None if cfg['noise_std'] is not None else (ks - c - 2).astype(float)
    declared = _candidates(ks, cand, y, tr, dm, dof, state, kverif, logr)
    last = k1 if declared is None else declared
    state['ill'] += int(np.count_nonzero(~ok[:last - k0 + 1]))
    return declared


def _candidates(ks, cand, y, tr, dm, dof, state: dict, kverif: int, logr: float
                ) -> int | None:
    """Algorithm 1 lines 11-18 over the candidate tests of a chunk (exact p_k)."""
    k1 = int(ks[-1])
    for i in cand:
        k = int(ks[i])
        if state['logp'] <= logr and state['kmin'] + kverif + 1 < k:
            return state['kmin'] + kverif + 1
        yv, trv = float(y[i]), float(tr[i])
        if not yv / trv < state['ystar']:
            logp = candidate_log_p2(yv, trv, float(dm[i]), state['logp'],
                                    None if dof is None else float(dof[i]))
            if logp is not None and logp < state['logp']:
                state.update(logp=logp, kmin=k, ystar=skip_threshold(logp))
        if state['logp'] <= logr and k > state['kmin'] + kverif:
            return k
    kd = state['kmin'] + kverif + 1
    if state['logp'] <= logr and kd <= k1:
        return kd
    return None


def detect_batch(time, speed, friction, *, component: str = 'rw1',
                 aux: Mapping[str, np.ndarray] | None = None, **params: Any
                 ) -> list[AnomalyEvent]:
    """Run Algorithm 1 over whole arrays and return the events of the streaming detector.

    ``time``, ``speed``, ``friction``: 1-D arrays of the same length (one row per sample;
    event indices are row indices). Keyword parameters as :class:`LLRDetector`.
    """
    events, _ = detect_batch_with_counters(time, speed, friction, component=component,
                                           aux=aux, **params)
    return events


def detect_batch_with_counters(time, speed, friction, *, component: str = 'rw1',
                               aux: Mapping[str, np.ndarray] | None = None, **params: Any
                               ) -> tuple[list[AnomalyEvent], dict[str, int]]:
    """Return ``(events, counters)`` of :func:`detect_batch` (counters as the detector's)."""
    cfg = validate_parameters(component, **params)
    t, w, f = _arrays(time, speed, friction)
    if not cfg['regressors'].is_coulomb_viscous:
        return _streamed(t, w, f, aux, component, params)
    accepted, counts = accepted_mask(t, w, f, cfg['max_abs_speed'], cfg['max_abs_friction'])
    if accepted.all():
        rows = np.arange(t.size)
        tv, wv, fv = t, w, f
    else:
        rows = np.flatnonzero(accepted)
        tv, wv, fv = t[rows], w[rows], f[rows]
    terms = _Terms(-np.sign(wv), -wv, fv)
    n_total = rows.size
    win, kverif = cfg['window'], cfg['k_verif']
    logr = math.log(cfg['false_alarm_rate'])
    z_thr = llr_stats.z_threshold(cfg['category_level'])
    keep = 2 * win + kverif + 2
    events: list[AnomalyEvent] = []
    counters = dict(counts, missing_aux=0, ill_conditioned=0)
    state = {'ill': 0}
    cat: dict[str, Any] | None = None
    checks: list[int] = []

    def revise(ref: _Reference, upto: int) -> None:
        while checks and checks[0] <= upto:
            j = checks.pop(0)
            ref.extend(j + 1)
            after = cat['gap'] + ref.at(j + 1)
            kind, dx, z, s2, confirmed = llr_stats.categorise(
                cat['before'], cat['n_before'], after, 2,
                None if cfg['noise_std'] is None else cfg['noise_std'] ** 2, z_thr)
            if kind != cat['kind'] or (confirmed and not cat['confirmed']):
                cat['kind'] = kind
                cat['confirmed'] = confirmed
                cat['revision'] += 1
                ev_rows = cat['rows'][:2] + (int(rows[j]),)
                events.append(make_event(component, kind, ev_rows, (cat['time'], float(tv[j])),
                                         cat['log_p'], dx, z, s2, cat['revision'], confirmed))

    c = 0
    while True:
        ref = _Reference(terms, c)
        state.update(logp=0.0, kmin=c, ystar=0.0, bound=0.0)
        k0 = c + win + 1
        declared = None
        while k0 + win - 1 <= n_total - 1:
            k1 = min(k0 + CHUNK - 1, n_total - win)
            declared = _scan(ref, k0, k1, state, cfg, logr)
            revise(ref, (declared if declared is not None else k1) + win - 1)
            if declared is not None:
                break
            ref.trim(k1 + 1 - keep)
            k0 = k1 + 1
        if declared is None:
            revise(ref, n_total - 1)
            break
        n = declared + win - 1
        k_min = state['kmin']
        first = max(c, k_min - win)
        ref.extend(n + 1)
        prefix = ref.at(np.arange(first, n + 2))
        tau, start, kind, dx, z, s2, confirmed = declaration(prefix, first, c, k_min, n, cfg,
                                                             z_thr)
        ev_rows = (int(rows[tau]), int(rows[k_min]), int(rows[n]))
        times = (float(tv[tau]), float(tv[n]))
        events.append(make_event(component, kind, ev_rows, times, state['logp'], dx, z, s2,
                                 0, confirmed))
        cat = dict(before=prefix[tau - first].copy(), n_before=tau - c, kind=kind,
                   confirmed=confirmed, revision=0, rows=ev_rows, time=times[0],
                   log_p=state['logp'], start=tau,
                   gap=prefix[start - first] - prefix[tau - first])
        checks = checkpoints(tau, n, cfg['category_revisions'], win)
        c = start
    counters['ill_conditioned'] = state['ill']
    return events, counters


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
    try:
        with np.errstate(all='ignore'):
            h = det.parameters['regressors'].matrix(w, t, aux_arrays)
    except (KeyError, TypeError):
        return _row_by_row(det, t, w, f, aux_arrays)
    cfg = det.parameters
    accepted, counts = accepted_mask(t, w, f, cfg['max_abs_speed'], cfg['max_abs_friction'],
                                     np.all(np.isfinite(h), axis=1))
    events: list[AnomalyEvent] = []
    for i in np.flatnonzero(accepted):
        events.extend(det.ingest_row(int(i), float(t[i]), float(f[i]), h[i]))
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
    return events, det.counters
