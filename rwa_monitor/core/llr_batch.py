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
channels) run the streaming detector (:func:`rwa_monitor.core.llr.detect_batch`, the
public entry point, dispatches). This module does not import the streaming one.
"""

from __future__ import annotations

import math
from typing import Any, Mapping

import numpy as np

from rwa_monitor.core import llr_kernel, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gchi2 import skip_threshold
from rwa_monitor.core.llr_common import (candidate_log_p2, checkpoints, declaration,
                                         fit_noise_model, make_event, ramp_points,
                                         reference_base, revision_due, speed_fit_done,
                                         speed_fit_length, speed_scale, whiten,
                                         window_statistics)

CHUNK = 1 << 13
# A candidate's exact p_k is computed only if its lower bound is within this relative
# margin above the running minimum (the streaming path's rule, core/llr_kernel.py).
_SKIP_REL = llr_kernel.SKIP_REL
_LOWER_AT_0 = math.log(2.0 / math.sqrt(math.pi)) - math.log(2.0)


def as_arrays(time, speed, friction) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


class _Terms:
    """Per-sample terms ``(h1 h1, h1 h2, h2 h2, h1 f, h2 f, f f)``, built per block."""

    def __init__(self, h1: np.ndarray, h2: np.ndarray, f: np.ndarray):
        self.h1, self.h2, self.f = h1, h2, f

    def block(self, first: int, last: int, out: np.ndarray | None = None) -> np.ndarray:
        """Return the terms of positions ``first..last - 1``, shape ``(6, n)`` (into ``out``)."""
        h1, h2, f = self.h1[first:last], self.h2[first:last], self.f[first:last]
        if out is None:
            out = np.empty((6, h1.size))
        np.multiply(h1, h1, out=out[0])
        np.multiply(h1, h2, out=out[1])
        np.multiply(h2, h2, out=out[2])
        np.multiply(h1, f, out=out[3])
        np.multiply(h2, f, out=out[4])
        np.multiply(f, f, out=out[5])
        return out


class _Reference:
    """Prefix sums (shape ``(6, m)``) of one reference segment, extended chunk by chunk.

    The prefixes live in a buffer that grows by doubling: a chunk's terms are written in
    place after the last held prefix and summed there (``numpy.cumsum`` in place, the same
    sequential additions as a sum of the concatenation); trimming moves the start only, and
    the held part is moved to the front when the buffer is full.
    """

    def __init__(self, terms: _Terms, c: int):
        self.terms = terms
        self.c = c
        self.pos0 = c
        self._buf = np.zeros((6, 2 * CHUNK))
        self._lo = 0     # buffer column of position pos0
        self._n = 1      # prefixes held: positions pos0 .. pos0 + _n - 1

    @property
    def rows(self) -> np.ndarray:
        """Held prefixes, a ``(6, m)`` view valid until the next :meth:`extend`."""
        return self._buf[:, self._lo:self._lo + self._n]

    @property
    def end(self) -> int:
        """Last position whose prefix is held."""
        return self.pos0 + self._n - 1

    def extend(self, last: int) -> None:
        """Hold prefixes up to position ``last`` (sequential continuation of the sums)."""
        m = last - self.end
        if m <= 0:
            return
        n = self._n
        if self._lo + n + m > self._buf.shape[1]:
            buf = self._buf
            if n + m > buf.shape[1]:
                buf = np.empty((6, max(2 * buf.shape[1], n + m)))
            buf[:, :n] = self._buf[:, self._lo:self._lo + n]
            self._buf, self._lo = buf, 0
        lo = self._lo
        self.terms.block(self.end, last, out=self._buf[:, lo + n:lo + n + m])
        run = self._buf[:, lo + n - 1:lo + n + m]
        np.cumsum(run, axis=1, out=run)
        self._n = n + m

    def trim(self, first: int) -> None:
        """Drop prefixes of positions before ``first``."""
        cut = first - self.pos0
        if cut > 0:
            self._lo += cut
            self._n -= cut
            self.pos0 = first

    def span(self, first: int, last: int) -> np.ndarray:
        """Return the prefixes of positions ``first..last`` as a ``(6, n)`` view."""
        return self.rows[:, first - self.pos0:last + 1 - self.pos0]

    def at(self, positions) -> np.ndarray:
        """Return the prefix rows at ``positions`` (shape ``(..., 6)``)."""
        return self.rows[:, np.asarray(positions) - self.pos0].T

    def bases(self, ks: np.ndarray, reference_max: int | None) -> tuple[Any, np.ndarray]:
        """Return the prefix rows where P_k starts (``(6, n)`` or 0.0) and the lengths of P_k.

        Sliding reference (``reference_max``): ``P_k = [max(c, k - R), k - 1]``.
        """
        if reference_max is None:
            return 0.0, (ks - self.c).astype(float)
        start = np.maximum(ks - reference_max, self.c)
        return self.rows[:, start - self.pos0], (ks - start).astype(float)


def _scan(ref: _Reference, k0: int, k1: int, state: dict, cfg: Mapping[str, Any],
          logr: float) -> int | None:
    """Run the tests k0..k1 of Algorithm 1; return the declaration k or None."""
    w, kverif = cfg['window'], cfg['k_verif']
    ks = np.arange(k0, k1 + 1)
    ref.extend(k1 + w)
    base, n_p = ref.bases(ks, cfg['reference_max'])
    pp, pt = ref.span(k0, k1), ref.span(k0 + w, k1 + w)
    if cfg['reference_max'] is not None:
        pp, pt = pp - base, pt - base
    ok, testable, y, tr, dm, _, _ = window_statistics(pp, pt, n_p, cfg, bounds=False)
    dof = None if cfg['noise_std'] is not None else n_p - 2.0
    upper, lower = _rough_bounds(y, tr, dm, dof)
    upper[~testable] = 0.0
    bound = np.minimum.accumulate(np.concatenate([[state['bound']], upper]))
    state['bound'] = float(bound[-1])
    limit = bound[:-1]
    limit += 1e-6 * (1.0 + np.abs(limit))
    cand = np.flatnonzero(testable & (lower <= limit))
    declared = _candidates(ks, cand, y, tr, dm, dof, state, kverif, logr, limit)
    last = k1 if declared is None else declared
    state['ill'] += int(np.count_nonzero(~ok[:last - k0 + 1]))
    return declared


def _rough_bounds(y: np.ndarray, tr: np.ndarray, dm: np.ndarray, dof: np.ndarray | None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Return cheap upper and lower bounds of log p_k (no logarithm), for the scan.

    With ``b``, ``rho``, ``a`` as in :func:`candidate_log_p2`: upper ``-b`` (the tail of
    ``l1 chi2_2``), studentised ``-b dof / (dof + 2 b)`` (``log1p(x) >= x / (1 + x)`` in the
    tail at ``psi = 0``, :func:`gchi2.log_sf2_t`); lower ``-1.5 a + log(2 / sqrt(pi)) -
    log 2 - b rho``, below the Gaussian bound of :func:`gchi2.log_lower_bound` (``log(sqrt
    a + sqrt(a + 2)) <= log(a + 2) <= log 2 + a / 2``), which holds for both tails. Only
    their use matters: the running minimum of the upper bounds stays at or above p_min, and
    a test whose lower bound is above it cannot be a new minimum.
    """
    with np.errstate(all='ignore'):
        half = 0.5 * tr
        lam1 = half + np.sqrt(np.maximum(half * half - dm, 0.0))
        b = y / (2.0 * lam1)
        b_rho = b * (np.maximum(dm / lam1, 0.0) / lam1)
        a = np.maximum(b - b_rho, 0.0)
        upper = -b if dof is None else -b * dof / (dof + 2.0 * b)
        lower = _LOWER_AT_0 - 1.5 * a - b_rho
    return upper, lower


def _candidates(ks, cand, y, tr, dm, dof, state: dict, kverif: int, logr: float,
                limit: np.ndarray) -> int | None:
    """Algorithm 1 lines 11-18 over the candidate tests of a chunk (exact p_k).

    :func:`_lower_bounds` (the bound of :func:`candidate_log_p2`, vectorised) drops the
    candidates whose bound is above ``limit`` (the running minimum of the upper bounds,
    plus a margin), and skips the call for one that cannot beat the running minimum by
    more than rounding: that call would return None or a p_k above the minimum, so the
    records, hence the events, are those of the streaming path (the declaration position
    depends on the records only). The loop runs on Python floats.
    """
    k1 = int(ks[-1])
    logp, kmin, ystar = state['logp'], state['kmin'], state['ystar']
    declared = None
    if cand.size:
        yc, trc, dmc = y[cand], tr[cand], dm[cand]
        dofc = None if dof is None else dof[cand]
        lows = _lower_bounds(yc, trc, dmc, dofc)
        keep = lows <= limit[cand]
        if not keep.all():
            cand, yc, trc, dmc, lows = cand[keep], yc[keep], trc[keep], dmc[keep], lows[keep]
            dofc = None if dofc is None else dofc[keep]
        lows = lows.tolist()
        dofs = [None] * cand.size if dofc is None else dofc.tolist()
        for k, yv, trv, dmv, dfv, low in zip(ks[cand].tolist(), yc.tolist(), trc.tolist(),
                                             dmc.tolist(), dofs, lows):
            if logp <= logr and kmin + kverif + 1 < k:
                declared = kmin + kverif + 1
                break
            if not yv / trv < ystar and not low > logp + _SKIP_REL * (1.0 - logp):
                new = candidate_log_p2(yv, trv, dmv, logp, dfv)
                if new is not None and new < logp:
                    logp, kmin, ystar = new, k, skip_threshold(new)
            if logp <= logr and k > kmin + kverif:
                declared = k
                break
    state.update(logp=logp, kmin=kmin, ystar=ystar)
    if declared is not None:
        return declared
    kd = kmin + kverif + 1
    if logp <= logr and kd <= k1:
        return kd
    return None


def _lower_bounds(y: np.ndarray, tr: np.ndarray, dm: np.ndarray, dof: np.ndarray | None
                  ) -> np.ndarray:
    """Return the lower bound of log p_k that :func:`candidate_log_p2` tests, per candidate.

    core/llr_kernel.py ``lower_bound`` (the streaming path's test uses the same): equal to
    the scalar one up to rounding, far below the relative margin ``_SKIP_REL`` with which
    it is used.
    """
    y = np.ascontiguousarray(y, dtype=float)
    dof = np.full(y.size, -1.0) if dof is None else np.ascontiguousarray(dof, dtype=float)
    return llr_kernel.lower_bounds(y, np.ascontiguousarray(tr, dtype=float),
                                   np.ascontiguousarray(dm, dtype=float), dof)


def paper_h1(speed: np.ndarray) -> np.ndarray:
    """Return ``-sign(w)`` as the streaming detector forms it (``+0.0`` at rest)."""
    return np.where(speed > 0.0, -1.0, np.where(speed < 0.0, 1.0, 0.0))


def detect_paper_model(t: np.ndarray, w: np.ndarray, f: np.ndarray, cfg: Mapping[str, Any]
                       ) -> tuple[list[AnomalyEvent], dict[str, int]]:
    """Return ``(events, counters)`` of the streaming detector on the paper's model (eq. (1)).

    ``cfg``: validated parameters (:func:`llr_common.validate_parameters`). With an
    autoregressive noise model the first ``noise_fit_samples`` accepted samples fit it
    (none fitted, no test, if there are fewer) and all samples are prewhitened
    (:func:`llr_common.whiten`) before the sums, as in the streaming path.
    """
    component = cfg['component']
    accepted, counts = accepted_mask(t, w, f, cfg['max_abs_speed'], cfg['max_abs_friction'])
    if accepted.all():
        rows = np.arange(t.size)
        tv, wv, fv = t, w, f
    else:
        rows = np.flatnonzero(accepted)
        tv, wv, fv = t[rows], w[rows], f[rows]
    counters = dict(counts, missing_aux=0, ill_conditioned=0)
    h1, h2 = -np.sign(wv), -wv
    speed_model = cfg['noise_speed_model']
    if cfg['noise_ar_max_order'] > 0 or speed_model:
        aw = np.abs(wv) if speed_model else None
        fit_n = cfg['noise_fit_samples']
        m = speed_fit_length(aw, fit_n) if speed_model else fit_n
        while True:   # the streaming detector's schedule of fits (llr.LLRDetector)
            if m is None or m > rows.size:
                return [], counters
            h_fit = np.column_stack([paper_h1(wv[:m]), -wv[:m]])
            model = fit_noise_model(h_fit, fv[:m], cfg['noise_ar_max_order'],
                                    None if aw is None else aw[:m])
            if not speed_model or speed_fit_done(m, fit_n, model):
                break
            m += fit_n
        ar = model.ar
        if model.speed_std is not None:
            level = speed_scale(aw, model.speed_std)
            h1, h2, fv = paper_h1(wv) / level, h2 / level, fv / level
        elif ar:
            h1 = paper_h1(wv)
        if ar:
            h1, h2, fv = whiten(h1, ar), whiten(h2, ar), whiten(fv, ar)
    terms = _Terms(h1, h2, fv)
    n_total = rows.size
    win, kverif = cfg['window'], cfg['k_verif']
    ref_max = cfg['reference_max']
    logr = math.log(cfg['false_alarm_rate'])
    z_thr = llr_stats.z_threshold(cfg['category_level'])
    keep = 2 * win + kverif + 2 + (ref_max or 0)
    noise_var = None if cfg['noise_std'] is None else cfg['noise_std'] ** 2
    events: list[AnomalyEvent] = []
    state = {'ill': 0}
    cat: dict[str, Any] | None = None
    checks: list[int] = []

    def ramp_block(first: int, last: int, t0: float) -> np.ndarray:
        return llr_stats.ramp_sums(terms.block(first, last + 1).T, tv[first:last + 1] - t0)

    def revise(ref: _Reference, upto: int) -> None:
        while checks and checks[0] <= upto:
            j = checks.pop(0)
            cat['ramp'].append(ramp_block(cat['ramp_end'] + 1, j, cat['ramp_t0']))
            cat['ramp_end'] = j
            if j not in cat['checks']:
                continue
            ref.extend(j + 1)
            recheck(j, cat['gap'] + ref.at(j + 1))

    def recheck(j: int, after: np.ndarray) -> None:
        new = llr_stats.categorise(cat['before'], cat['n_before'], after, 2, noise_var,
                                   z_thr, np.asarray(cat['ramp']))
        if revision_due(cat['kind'], cat['guess'], cat['confirmed'], new):
            cat['kind'] = new.kind
            cat['guess'] = new.guess
            cat['confirmed'] = new.confirmed
            cat['revision'] += 1
            ev_rows = cat['rows'][:2] + (int(rows[j]),)
            events.append(make_event(component, new, ev_rows, (cat['time'], float(tv[j])),
                                     cat['log_p'], cat['revision']))

    def continues(tau: int, n: int, ref: _Reference) -> bool:
        """Return the streaming detector's ``_continues`` (same blocks, same floats)."""
        if cat is None or not checks:
            return False
        blocks = list(cat['ramp'])
        if cat['ramp_end'] < n:
            blocks.append(ramp_block(cat['ramp_end'] + 1, n, cat['ramp_t0']))
        after = cat['gap'] + ref.at(n + 1)
        if not llr_stats.continues(cat['before'], cat['n_before'], after, np.asarray(blocks),
                                   terms.block(tau, n + 1).T, tv[tau:n + 1] - cat['ramp_t0'],
                                   cat['kind'], 2, noise_var, z_thr):
            return False
        cat['ramp'] = blocks
        cat['ramp_end'] = n
        return True

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
        base = reference_base(c, first, ref_max)
        ref.extend(n + 1)
        prefix = ref.at(np.arange(first, n + 2))
        if base != c:
            prefix = prefix - ref.at(base)
        ramps: dict[int, np.ndarray] = {}

        def ramp_of(tau: int) -> np.ndarray:
            ramps[tau] = ramp_block(tau, n, float(tv[tau]))
            return ramps[tau]

        tau, start, category = declaration(prefix, first, base, k_min, n, cfg, z_thr,
                                           ramp_of)
        if continues(tau, n, ref):
            recheck(n, cat['gap'] + ref.at(n + 1))
            cat['gap'] = cat['gap'] + ref.at(start)
            c = start
            continue
        ev_rows = (int(rows[tau]), int(rows[k_min]), int(rows[n]))
        times = (float(tv[tau]), float(tv[n]))
        events.append(make_event(component, category, ev_rows, times, state['logp'], 0))
        revisions = checkpoints(tau, n, cfg['category_revisions'], win)
        cat = dict(before=prefix[tau - first].copy(), n_before=tau - base,
                   kind=category.kind, guess=category.guess,
                   confirmed=category.confirmed, revision=0,
                   rows=ev_rows, time=times[0], log_p=state['logp'], start=tau,
                   gap=prefix[start - first] - prefix[tau - first], checks=set(revisions),
                   ramp=[ramps[tau]], ramp_end=n, ramp_t0=times[0])
        checks = ramp_points(n, revisions, win)
        c = start
    counters['ill_conditioned'] = state['ill']
    return events, counters
