"""The declaration, revision, re-check and continuation rules of the LLR detector.

llr-realtime paper, Algorithm 1 lines 13-21 (declaration and restart) and the kind of each
change (not in the paper; docs/llr.md "Categorisation", "Kinds on ramps"). Written once,
for the compiled path of the paper's model and the numpy path of larger models alike: the
per-sample loops (core/llr_kernel.py, core/llr_general.py) return flags at the rare samples
that need these rules, and :func:`after` acts on them. Every function receives the
detector's working state (core/llr_state.py ``Live``: the kernel arrays with the rings of
the last samples, and :class:`DeclaredChange`, the record of the last declared change,
replaced when it changes) and its configuration (core/llr_config.py), nothing else.
"""

from __future__ import annotations

from dataclasses import replace
import math

import numpy as np

from rwa_monitor.core import llr_general, llr_growth, llr_kernel as kern, llr_kinds
from rwa_monitor.core import llr_layout as layout
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.jit import kernel_array
from rwa_monitor.core.llr_common import (checkpoints, declaration, make_event, ramp_points,
                                         reference_base, revision_due)
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_ramp_kernel import BLOCK_WIDTH, ring_ramp_block, ring_ramp_taken
from rwa_monitor.core.llr_state import DeclaredChange, Live
from rwa_monitor.core.records import evolve

# A change whose position's interval to the sample before it exceeds this many times the
# median interval fell in a gap of the stream (docs/llr.md "Changes in a gap").
GAP_FACTOR = 10.0

__all__ = ['after', 'DeclaredChange', 'finish', 'growth_kind']


def after(live: Live, config: LLRConfig, flags: int) -> list[AnomalyEvent]:
    """Act on the flags of a kernel call: revise, finish the test, declare."""
    j = live.position - 1
    events = _revise(live, config, j) if flags & kern.REVISE else []
    if flags & kern.DECLARE:
        events.extend(_declare(live, config, j))
    return events


def _declare(live: Live, config: LLRConfig, n: int) -> list[AnomalyEvent]:
    """Algorithm 1 lines 18-21: declare the change and restart the reference.

    The paper restarts at ``k_min``; here at ``max(tau, k_min)`` (``tau`` the refined
    change position), so that the new reference holds post-change samples only. The
    kind is re-checked on ``[tau, j]`` (the gap ``[tau, start)`` is kept as one
    prefix-sum row). Tests of the new reference whose window is already complete run
    at once (never, since the start is at or after ``k_min``; kept for safety). Not in
    the paper: a declaration that the previous change's growth explains
    (:func:`_continues`, docs/llr.md "Kinds on ramps") is no new change: its kind is
    re-checked instead and the reference restarts as after any declaration.
    """
    ring = live.ring
    length = len(ring.row)
    c, k_min = live.reference_start, int(live.ints[layout.I_KMIN])
    log_p = float(live.floats[layout.F_LOGPMIN])
    first = max(c, k_min - config.window)
    base = reference_base(c, first, config.reference_max)
    prefix = ring.pref[np.arange(first, n + 2) % length]
    if base != c:
        prefix = prefix - ring.pref[base % length]
    ramps: dict[int, np.ndarray] = {}
    speeds: dict[int, np.ndarray] = {}

    def ramp_of(tau: int) -> np.ndarray:
        ramps[tau], speeds[tau] = _ramp_block(live, config, tau, n,
                                              float(ring.time[tau % length]))
        return ramps[tau]

    def log_prior(taus: np.ndarray) -> np.ndarray:
        return np.log(_intervals(ring.time, taus, length))

    tau, start, cat = declaration(prefix, first, base, k_min, n, config, ramp_of, log_prior)
    if _continues(live, config, tau, n):
        events = _recheck(live, config, n, live.change.gap + live.prefix_now())
        live.change = replace(live.change, gap=live.change.gap + ring.pref[start % length])
        return events + _restart_and_test(live, config, start, n)
    rows = (int(ring.row[tau % length]), int(ring.row[k_min % length]),
            int(ring.row[n % length]))
    times = (float(ring.time[tau % length]), float(ring.time[n % length]))
    gap = _gap_before(ring.time, tau, first, n, length)
    event = make_event(config.component, cat, rows, times, log_p, 0, after_gap_s=gap)
    live.last_event = event
    checks = checkpoints(tau, n, config.category_revisions, config.window)
    points = ramp_points(n, checks, config.window)
    live.ints[layout.I_CHECKPOINT] = points[0] if points else -1
    live.change = DeclaredChange(
        n_before=tau - base, kind=cat.kind, guess=cat.guess, confirmed=cat.confirmed,
        revision=0, rows=rows, time=times[0], log_p=log_p, checks=tuple(checks),
        points=tuple(points[1:]), ramp_end=n, tau=tau, closed=not checks, tail=False,
        finished=False, after_gap_s=gap, shape=cat.shape, before=prefix[tau - first].copy(),
        gap=prefix[start - first] - prefix[tau - first], ramp=ramps[tau][None, :],
        speeds=speeds[tau][None, :])
    return [event] + _restart_and_test(live, config, start, n)


def _intervals(time: np.ndarray, positions: np.ndarray, length: int) -> np.ndarray:
    """Return the time between each position's sample and the one before it (s)."""
    return time[positions % length] - time[(positions - 1) % length]


def _gap_before(time: np.ndarray, tau: int, first: int, n: int, length: int) -> float:
    """Return the gap the change at ``tau`` fell in, or NaN if it fell between samples.

    A gap: the time from the sample before ``tau`` to ``tau``'s exceeds GAP_FACTOR times
    the median interval of the samples held (``[first, n]``): a pause of the stream (a
    downlink gap between passes), not its sampling.
    """
    if tau - 1 < first:
        return math.nan
    interval = float(time[tau % length] - time[(tau - 1) % length])
    typical = float(np.median(_intervals(time, np.arange(first + 1, n + 1), length)))
    return interval if interval > GAP_FACTOR * typical else math.nan


def _restart_and_test(live: Live, config: LLRConfig, start: int, n: int
                      ) -> list[AnomalyEvent]:
    """Restart the reference at ``start``; run the tests whose window is complete."""
    _restart(live, config, start, n)
    events: list[AnomalyEvent] = []
    w = config.window
    pref, length = live.ring.pref, len(live.ring.row)
    for k in range(start + w + 1, n - w + 2):
        row = pref[(k + w) % length].copy()
        if config.p == 2:
            flags = kern.test_row(live.floats, live.ints, k, row)
            declare = bool(flags & kern.DECLARE)
        else:
            declare = llr_general.test(live, config, k, row)
        if declare:
            events.extend(_declare(live, config, n))
    return events


def _restart(live: Live, config: LLRConfig, c: int, n: int) -> None:
    """Start the new reference at position ``c`` and rebuild its prefix sums (line 20)."""
    ring = live.ring
    length = len(ring.row)
    live.ints[layout.I_C] = c
    live.ints[layout.I_C_ROW] = ring.row[c % length]
    total = (0.0,) * 6 if config.p == 2 else np.zeros(config.width)
    ring.pref[c % length] = total
    for j in range(c, n + 1):
        if config.p == 2:
            h1, h2, f = ring.term[j % length]
            total = (total[0] + h1 * h1, total[1] + h1 * h2, total[2] + h2 * h2,
                     total[3] + h1 * f, total[4] + h2 * f, total[5] + f * f)
        else:
            total = total + ring.term[j % length]
        ring.pref[(j + 1) % length] = total
    if config.p == 2:
        live.floats[layout.F_PREF:layout.F_PREF + 6] = total
    else:
        live.general = replace(live.general, reference_sums=total)
    live.floats[layout.F_LOGPMIN] = 0.0
    live.ints[layout.I_KMIN] = c
    live.floats[layout.F_YSTAR] = 0.0


def _continues(live: Live, config: LLRConfig, tau: int, n: int) -> bool:
    """Return True if the change declared at ``n`` is the previous one still growing.

    Its ramp sums are kept up to date whether its re-checks are over (closed) or not:
    :func:`llr_growth.continues` on its segments up to ``n`` and on the samples ``[tau,
    n]``. If so, its ramp sums take in the samples up to ``n``. A closed change is tested
    too: a slow wear grows for days, past the last re-check (docs/llr.md "One declaration
    per ramp"). The kind it may grow in: :func:`growth_kind`.
    """
    prev = live.change
    if prev is None or prev.finished:
        return False
    blocks, speeds = prev.ramp, prev.speeds
    if prev.ramp_end < n:
        blocks, speeds = _ramp_with(live, config, prev, n)
    after_sums = prev.gap + live.prefix_now()
    times = live.ring.time[np.arange(tau, n + 1) % len(live.ring.row)]
    if not llr_growth.continues(prev.before, prev.n_before, after_sums, blocks,
                                _terms(live, config, tau, n), times - prev.time,
                                growth_kind(prev, after_sums, config), config.p,
                                config.noise_var, config.z_threshold):
        return False
    live.change = replace(prev, ramp=blocks, speeds=speeds, ramp_end=n)
    return True


def _ramp_block(live: Live, config: LLRConfig, first: int, last: int, t0: float
                ) -> tuple[np.ndarray, np.ndarray]:
    """Return the ramp sums and the ``|w|`` range of positions ``first..last`` (the ring).

    :func:`llr_growth.ramp_sums` of their terms with ``u = time - t0``, and their lowest
    and highest speed. For p = 2 in one compiled walk of the rings
    (core/llr_ramp_kernel.py, the same floats); for larger models with numpy.
    """
    ring = live.ring
    if config.p == 2:
        out = ring_ramp_block(ring.term, ring.time, ring.speed, first, last, t0)
        return out[:BLOCK_WIDTH], out[BLOCK_WIDTH:]
    positions = np.arange(first, last + 1) % len(ring.row)
    speeds = ring.speed[positions]
    return (llr_growth.ramp_sums(_terms(live, config, first, last), ring.time[positions] - t0),
            np.array([speeds.min(), speeds.max()]))


def _with_range(speeds: np.ndarray, new: np.ndarray, tail: bool) -> np.ndarray:
    """Return the blocks' speed ranges with ``new`` appended, or merged (:func:`_with_block`)."""
    if tail:
        merged = np.array([min(speeds[-1, 0], new[0]), max(speeds[-1, 1], new[1])])
        return np.concatenate([speeds[:-1], merged[None, :]])
    return np.concatenate([speeds, new[None, :]])


def _terms(live: Live, config: LLRConfig, first: int, last: int) -> np.ndarray:
    """Return the per-sample terms of positions ``first..last`` (in the ring), ``(n, width)``.

    For p = 2 the ring holds ``(h1, h2, f)``: the six products are formed here with
    numpy, in the order of the kernel's prefix sums.
    """
    rows = live.ring.term[np.arange(first, last + 1) % len(live.ring.row)]
    if config.p != 2:
        return rows
    h1, h2, f = rows[:, 0], rows[:, 1], rows[:, 2]
    return np.column_stack((h1 * h1, h1 * h2, h2 * h2, h1 * f, h2 * f, f * f))


def _revise(live: Live, config: LLRConfig, j: int) -> list[AnomalyEvent]:
    """Take the new samples into the ramp sums; re-check the kind at a checkpoint.

    ``j`` is a point of :func:`llr_common.ramp_points`; the kind is re-checked only at
    the points of :func:`llr_common.checkpoints`. After the last re-check the change is
    closed and its sums keep taking in samples every ``tail_stride`` samples (the rings'
    length, core/llr_config.py), merged into one block (so the time shapes stay those of
    the re-checks plus the straight ramp to the end), for :func:`finish`.
    """
    cat = live.change
    live.ints[layout.I_CHECKPOINT] = cat.points[0] if cat.points else j + config.tail_stride
    fields = _ramp_taken(live, config, cat, j)
    if j in cat.checks:
        fields['closed'] = cat.closed or j == cat.checks[-1]
    live.change = evolve(cat, points=cat.points[1:], **fields)
    if j not in cat.checks:
        return []
    return _recheck(live, config, j, live.change.gap + live.prefix_now())


def _take_ramp(live: Live, config: LLRConfig, j: int) -> None:
    """Add the samples ``(ramp_end, j]`` to the ramp sums of the last change."""
    fields = _ramp_taken(live, config, live.change, j)
    if fields:
        live.change = evolve(live.change, **fields)


def _ramp_taken(live: Live, config: LLRConfig, cat: DeclaredChange, j: int
                ) -> dict[str, object]:
    """Return the fields of ``cat`` with the samples ``(ramp_end, j]`` in its ramp sums.

    Empty when ``j`` is not past ``ramp_end``. One ``replace`` of the record per
    revision point with its other fields (a record's copy costs more than its sums).
    """
    if j <= cat.ramp_end:
        return {}
    ramp, speeds = _ramp_with(live, config, cat, j)
    return {'ramp': ramp, 'speeds': speeds, 'tail': cat.closed, 'ramp_end': j}


def _ramp_with(live: Live, config: LLRConfig, cat: DeclaredChange, j: int
               ) -> tuple[np.ndarray, np.ndarray]:
    """Return ``cat``'s ramp blocks and speed ranges with the samples ``(ramp_end, j]``.

    For p = 2 in one compiled call (core/llr_ramp_kernel.py ``ring_ramp_taken``, the
    floats of :func:`_ramp_block`, :func:`_with_block` and :func:`_with_range`).
    """
    if config.p == 2:
        ring = live.ring
        return ring_ramp_taken(ring.term, ring.time, ring.speed, cat.ramp_end + 1, j,
                               cat.time, kernel_array(cat.ramp), kernel_array(cat.speeds),
                               cat.tail)
    block, block_speeds = _ramp_block(live, config, cat.ramp_end + 1, j, cat.time)
    return (_with_block(cat.ramp, block, cat.tail),
            _with_range(cat.speeds, block_speeds, cat.tail))


def _with_block(ramp: np.ndarray, block: np.ndarray, tail: bool) -> np.ndarray:
    """Return the ramp-sum blocks with ``block`` appended, or merged into the last one.

    Merged after the last re-check (``tail``): the sums add and the knot moves to the
    new block's end, so the time shapes of a closed change stay those of its re-checks
    plus the straight ramp to the end, their number bounded however long it grows.
    """
    if tail:
        merged = np.concatenate([block[:1], ramp[-1, 1:] + block[1:]])
        return np.concatenate([ramp[:-1], merged[None, :]])
    return np.concatenate([ramp, block[None, :]])


def finish(live: Live, config: LLRConfig) -> list[AnomalyEvent]:
    """End of record: the final categorisation of the last declared change, if any.

    Not in the paper (docs/llr.md "End of record"). The last declared change gets one
    more categorisation on every sample after it that the record holds (the same
    tests and levels as a re-check), as an event with ``final`` True and the samples
    it used: always while its re-checks are not all done (open), and, once they are
    (closed), only when the answer differs from the last one given (kind, guess or
    confirmation) and does not add a component to a confirmed single kind (one the
    re-checks did not find and the longer record does: a misfit of the model growing
    with the samples, or a later change). A kind confirmed earlier is kept, when this
    evaluation does not confirm one, only if its tests still find each of its
    components at the category level (:func:`llr_kinds.supports`): the record as a
    whole, not its shorter prefix, bears the answer. The change is then finished (a
    second call gives nothing). The batch path calls it after the last row; a live
    detector keeps its re-check schedule and calls it only when its input ends.
    Returns [] when no change was declared, or with ``category_revisions`` 0 (no
    re-checks, no sums kept).
    """
    cat = live.change
    if cat is None or cat.finished or not cat.checks:
        return []
    j = live.position - 1
    _take_ramp(live, config, j)
    live.ints[layout.I_CHECKPOINT] = -1
    live.change = replace(live.change, points=(), finished=True)
    return _recheck(live, config, j, live.change.gap + live.prefix_now(), final=True,
                    quiet=cat.closed)


def _recheck(live: Live, config: LLRConfig, j: int, after_sums: np.ndarray,
             final: bool = False, quiet: bool = False) -> list[AnomalyEvent]:
    """Re-check the kind of the last declared change on its after segment up to ``j``.

    ``final``: the end of record (:func:`finish`); ``quiet``: then an event only if
    the answer differs from the last one given.
    """
    cat = live.change
    z = config.z_threshold
    new = llr_kinds.categorise(cat.before, cat.n_before, after_sums, config.p,
                               config.noise_var, z, cat.ramp, cat.speeds)
    if not final and not revision_due(cat.kind, cat.guess, cat.confirmed, new):
        return []
    if final and cat.confirmed and not new.confirmed and \
            llr_kinds.supports(new, cat.kind, z):
        new = new._replace(kind=cat.kind, guess=cat.guess, confirmed=True)
    answer = (new.kind, new.guess, new.confirmed)
    if quiet and (answer == (cat.kind, cat.guess, cat.confirmed) or cat.confirmed
                  and llr_kinds.adds_component(cat.kind, new.kind)):
        return []
    cat = replace(cat, kind=new.kind, guess=new.guess, confirmed=new.confirmed,
                  shape=new.shape, revision=cat.revision + 1)
    live.change = cat
    ring = live.ring
    length = len(ring.row)
    rows = cat.rows[:2] + (int(ring.row[j % length]),)
    times = (cat.time, float(ring.time[j % length]))
    live.last_event = make_event(config.component, new, rows, times, cat.log_p,
                                 cat.revision, j - cat.tau + 1 if final else None,
                                 cat.after_gap_s)
    return [live.last_event]


def growth_kind(prev: DeclaredChange, after_sums: np.ndarray, config: LLRConfig) -> str:
    """Return the kind in which the continuation test lets the change ``prev`` grow.

    Not in the paper (docs/llr.md "One declaration per ramp", *Which kind grows*): its
    kind (``undecided`` and ``both``: either direction), except a single kind the step
    tests confirmed (shape ``step``) that the step tests on its after segment up to now
    (``after_sums``) no longer find (:func:`llr_kinds.supports`): a step fit of a growing
    level can name the other kind on the first samples, and that verdict says nothing of
    the direction the change grows in, so it may grow in both.
    """
    if not prev.confirmed or prev.shape != llr_kinds.SHAPES[0] \
            or prev.kind not in llr_kinds.KINDS[:2]:
        return prev.kind
    now = llr_kinds.categorise(prev.before, prev.n_before, after_sums, config.p,
                               config.noise_var, config.z_threshold)
    if llr_kinds.supports(now, prev.kind, config.z_threshold):
        return prev.kind
    return llr_kinds.UNDECIDED
