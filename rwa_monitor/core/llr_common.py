"""What the LLR detector's parts share (llr-realtime paper, Algorithm 1).

p_k of one candidate (eq. (7) with Algorithm 2's skip bound), the statistic vectorised
(eq. (5)), the declaration (change time, categorisation, restart point), the revision
rules and events. Imported by the detector (:mod:`rwa_monitor.core.llr_detector`) and its
rules (:mod:`rwa_monitor.core.llr_changes`); the parameters are core/llr_config.py.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import numpy as np

from rwa_monitor.core import keys, llr_kinds, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_skip import exact_log_p2

_LN10 = math.log(10.0)


def make_event(component: str, category: llr_kinds.Category, rows: tuple[int, int, int],
               times: tuple[float, float], log_p: float, revision: int,
               final_samples: int | None = None, after_gap_s: float = math.nan
               ) -> AnomalyEvent:
    """Build the AnomalyEvent of a declaration or revision.

    ``rows = (change row, argmin row, declaration row)``, ``times = (change time,
    declaration time)``; ``category.confirmed``: the data tell the kind apart (docs/llr.md).
    An undecided kind carries its reason; ``final_samples``: the end-of-record
    categorisation on that many samples after the change (``final`` True); ``after_gap_s``:
    a change that fell in a gap of the samples, the time since the last sample before it
    (the change lies in ``[time - after_gap_s, time]``).
    """
    dx, z = category.dx, category.z
    details = {keys.DELTA_DRY: float(dx[0]), keys.DELTA_VISCOUS: float(dx[1]),
               keys.NOISE_STD: math.sqrt(category.noise_var), keys.Z_DRY: z[0],
               keys.Z_VISCOUS: z[1], keys.KIND_CONFIRMED: bool(category.confirmed),
               keys.ARGMIN_INDEX: rows[1], keys.LOG10_P_VALUE: log_p / _LN10,
               keys.KIND_GUESS: category.guess,
               keys.KIND_SHAPE: category.shape,
               keys.DETECTABLE_DRY: category.detectable[0],
               keys.DETECTABLE_VISCOUS: category.detectable[1]}
    if category.kind == llr_kinds.UNDECIDED:
        details[keys.KIND_REASON] = llr_kinds.REASONS.get(category.reason, category.reason)
    if math.isfinite(after_gap_s):
        details[keys.AFTER_GAP] = float(after_gap_s)
    if final_samples is not None:
        details[keys.FINAL] = True
        details[keys.FINAL_SAMPLES] = int(final_samples)
    return AnomalyEvent(detector='llr', component=component, kind=category.kind,
                        time=times[0], index=rows[0], declared_time=times[1],
                        declared_index=rows[2], p_value=math.exp(log_p), revision=revision,
                        details=details)


class Declaration(NamedTuple):
    """Outcome of a declaration: change position, restart position and categorisation."""

    change: int
    restart: int
    category: llr_kinds.Category


def declaration(prefix: np.ndarray, first: int, c: int, k_min: int, n: int,
                config: LLRConfig, ramp_of: Callable[[int], np.ndarray] | None = None,
                log_prior: Callable[[np.ndarray], np.ndarray] | None = None) -> Declaration:
    """Return the change position, restart position and category at a declaration.

    ``prefix[i]`` is the prefix-sum row (reference start ``c``) at position ``first + i``,
    covering ``[max(c, k_min - window), n + 1]``. Change position ``tau``: the ML refinement
    (:func:`llr_stats.refine_change`) over ``k_min +- window`` if enabled, else ``k_min``
    (the argmin of p_k, Algorithm 1 line 15). Categorisation: before = ``[c, tau)``, after
    = ``[tau, n]`` (:func:`llr_kinds.categorise`). The new reference starts at
    ``max(tau, k_min)``, the later of the two change estimates, so that an estimate that
    falls before the true change does not put pre-change samples in it (they would be
    declared as the same change again). With a sliding reference (``reference_max``) the
    caller passes ``c`` = the start of the reference window and rows relative to it.
    ``ramp_of(tau)``: the :func:`llr_growth.ramp_sums` of ``[tau, n]`` (the kind of a
    growing change, docs/llr.md "Kinds on ramps"); None: steps only. ``log_prior``: the
    positions' log prior for the refinement (:func:`llr_stats.refine_change`).
    """
    p, noise_var, z_thr = config.p, config.noise_var, config.z_threshold
    tau = k_min
    if config.refine_change:
        w = config.window
        tau = llr_stats.refine_change(prefix, first, c, n, k_min - w, k_min + w, p,
                                      noise_var, z_thr, k_min, log_prior)
    before = prefix[tau - first]
    after = prefix[n + 1 - first] - before
    ramp = None if ramp_of is None else ramp_of(tau)
    category = llr_kinds.categorise(before, tau - c, after, p, noise_var, z_thr, ramp)
    return Declaration(tau, max(tau, k_min), category)


def revision_due(kind: str, guess: str, confirmed: bool, new: llr_kinds.Category) -> bool:
    """Return True when a re-check of a declared change's kind gives a revision event.

    Not in the paper (docs/llr.md "Categorisation"): a kind confirmed for the first time
    or replaced by another confirmed kind, or, while unconfirmed, a new best guess. A
    confirmed kind is never withdrawn to ``undecided``: a later evaluation whose other
    component sits between the 5 % and the category level is ambiguous, not evidence
    against it (a different confirmed kind is).
    """
    if new.confirmed:
        return not confirmed or new.kind != kind
    return not confirmed and (new.kind, new.guess) != (kind, guess)


def reference_base(c: int, first: int, reference_max: int | None) -> int:
    """Return the first position of the before-segment used at a declaration.

    The whole reference ``c`` without ``reference_max``; otherwise at most
    ``reference_max`` samples before ``first`` (the earliest candidate change position),
    as the tests saw it.
    """
    return c if reference_max is None else max(c, first - reference_max)


def ramp_points(n: int, checks: list[int], window: int) -> list[int]:
    """Return where the ramp sums of a change declared at ``n`` take in new samples.

    Every ``window`` samples after ``n`` up to the last re-check, and at each re-check
    (:func:`checkpoints`): the streaming detector holds the per-sample terms of the last
    ``2 window + k_verif + 2`` samples only, so it adds them to the time-weighted sums
    (:func:`llr_growth.ramp_sums`) block by block; the batch path takes the same blocks so
    that both sum the same floats in the same order.
    """
    if not checks:
        return []
    return sorted(set(range(n + window, checks[-1], window)) | set(checks))


def checkpoints(start: int, n: int, count: int, window: int) -> list[int]:
    """Return the positions where the kind of a change declared at ``n`` is re-checked.

    The after-segment ``[start, n]`` holds ``n - start + 1`` samples at declaration; with
    ``L0 = max(n - start + 1, window)`` the kind is re-evaluated when it holds ``2 L0, 4 L0,
    ...`` samples (``count`` checks).
    """
    length = max(n - start + 1, window)
    return [start + length * 2 ** i - 1 for i in range(1, count + 1)]


def candidate_log_p2(y: float, tr: float, dm: float, log_p_min: float,
                     dof: float | None = None) -> float | None:
    """Return log p_k (eq. (7), Algorithm 2) if it may be below ``log_p_min``, else None.

    ``dof`` None when the noise level is given. The compiled ``llr_skip.exact_log_p2``,
    which the kernel calls at each candidate its skip bounds leave (the same floats, the
    same decision), with None for its NaN.
    """
    value = exact_log_p2(float(y), float(tr), float(dm), float(log_p_min),
                         -1.0 if dof is None else float(dof))
    return None if math.isnan(value) else value


def window_statistics(pp: np.ndarray, pt: np.ndarray, n_p: np.ndarray, min_excitation: float,
                      noise_std: float | None):
    """Return ``(ok, testable, y, tr, dm)`` of eq. (5) for stacked candidates (numpy).

    The operations of core/llr_kernel.py ``test``, vectorised: ``pp``, ``pt`` are the
    prefix rows at ``k`` and ``k + w``, shape ``(6, n)``; ``n_p`` the lengths of P_k;
    ``noise_std`` None when estimated on the reference. For
    :attr:`LLRDetector.last_statistic` and the tests of Lemma 1.
    """
    A, B, C, U, V, E = pp[0], pp[1], pp[2], pp[3], pp[4], pp[5]
    At, Bt, Ct, Ut, Vt = pt[0], pt[1], pt[2], pt[3], pt[4]
    ac = A * C
    det = ac - B * B
    dett = At * Ct - Bt * Bt
    ok = (det > min_excitation * ac) & (dett > 0.0)
    with np.errstate(all='ignore'):
        x1 = (C * U - B * V) / det
        x2 = (A * V - B * U) / det
        if noise_std is None:
            s2 = (E - (x1 * U + x2 * V)) / (n_p - 2.0)
            floor = llr_stats.NOISE_FLOOR_REL * E / n_p + llr_stats.NOISE_FLOOR_ABS
            s2 = np.fmax(s2, floor)
        else:
            s2 = noise_std ** 2
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
    return ok, ok & (tr > 0.0) & (y > 0.0), y, tr, dm
