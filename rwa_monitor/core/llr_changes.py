"""The declaration, revision, re-check and continuation rules of the LLR detector.

llr-realtime paper, Algorithm 1 lines 13-21 (declaration and restart) and the kind of each
change (not in the paper; docs/llr.md "Categorisation", "Kinds on ramps"). Written once:
:class:`ChangeRules` is a base of :class:`rwa_monitor.core.llr_detector.LLRDetector`,
whose per-sample loop (core/llr_kernel.py, compiled) stops at the rare samples that need
them, in the streaming path (``update``) and in the batch path (``process_arrays``) alike.
The state they act on is the detector's: the kernel arrays ``_fs`` / ``_ints`` (rings of
the last samples, positions) and :class:`DeclaredChange`, the typed record of the last
declared change.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from rwa_monitor.core import llr_growth, llr_kernel as kern, llr_kinds
from rwa_monitor.core import llr_layout as layout, llr_stats
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.gchi2 import skip_threshold
from rwa_monitor.core.llr_common import (candidate_log_p2, checkpoints, declaration,
                                         make_event, ramp_points, reference_base,
                                         revision_due)


@dataclass
class DeclaredChange:
    """The last declared change, whose kind is re-checked as data arrive.

    Positions count accepted samples; the change was found at position ``tau`` (time
    ``time``, row ``rows[0]``) and declared at ``rows[2]``. ``before``: prefix sums of the
    before segment (``n_before`` samples), ``gap``: sums of the after samples before the
    new reference starts (the after segment is ``gap`` + the new reference). ``checks``:
    positions where the kind is re-checked (:func:`llr_common.checkpoints`), ``points``:
    the remaining positions where the ramp sums take in samples
    (:func:`llr_common.ramp_points`), ``ramp``: :func:`llr_growth.ramp_sums` blocks of
    ``[tau, ramp_end]`` (times since ``time``). ``closed``: the re-checks are over; the
    ramp sums still take in the samples every ``window`` samples, into one last block
    (``tail``), for the continuation test (:meth:`ChangeRules._continues`) and the end of
    record. ``finished``: :meth:`ChangeRules.finish` has run.
    """

    before: np.ndarray
    n_before: int
    kind: str
    guess: str
    confirmed: bool
    revision: int
    rows: tuple[int, int, int]
    time: float
    log_p: float
    gap: np.ndarray
    checks: tuple[int, ...]
    points: list[int]
    ramp: list[np.ndarray]
    ramp_end: int
    tau: int = -1   # position of the change
    closed: bool = False
    tail: bool = False
    finished: bool = False


class Rings(NamedTuple):
    """Views of the kernel's rings of the last ``L`` accepted samples (by position % L)."""

    pref: np.ndarray   # (L, width): prefix-sum row at each position
    term: np.ndarray   # (L, 3) (h1, h2, f) for p = 2, else (L, width) terms
    time: np.ndarray   # (L,) sample time
    row: np.ndarray    # (L,) row index


def rings(fs: np.ndarray, ints: np.ndarray, width: int) -> Rings:
    """Return the ring views of the kernel arrays (core/llr_kernel.py ``allocate``)."""
    length = int(ints[layout.I_L])
    pref = fs[ints[layout.I_O_RPREF]:ints[layout.I_O_RTERM]].reshape(length, width)
    term = fs[ints[layout.I_O_RTERM]:ints[layout.I_O_RTIME]].reshape(length, -1)
    return Rings(pref, term, fs[ints[layout.I_O_RTIME]:ints[layout.I_O_AR]],
                 ints[layout.I_SCALARS:layout.I_SCALARS + length])


class ChangeRules:
    """Algorithm 1's declaration and restart, and the kinds of the declared changes."""

    def _rings(self) -> Rings:
        return rings(self._fs, self._ints, llr_stats.width(self._p))

    def _prefix_now(self) -> np.ndarray:
        """Return the prefix sums of the reference up to the last accepted sample."""
        if self._p == 2:
            return self._fs[layout.F_PREF:layout.F_PREF + 6].copy()
        return np.asarray(self._pref_general, dtype=float)

    def _base(self, k: int) -> tuple[np.ndarray, int]:
        """Return the prefix row where P_k starts and the length of P_k."""
        c = int(self._ints[layout.I_C])
        if self._R is not None and k - self._R > c:
            return self._rings().pref[(k - self._R) % self._L].copy(), self._R
        return np.zeros(llr_stats.width(self._p)), k - c

    def _after(self, flags: int) -> list[AnomalyEvent]:
        """Act on the flags of a kernel call: revise, finish the test, declare."""
        j = int(self._ints[layout.I_POS]) - 1
        events = self._revise(j) if flags & kern.REVISE else []
        if flags & kern.DECLARE or flags & kern.EXACT and self._exact():
            events.extend(self._declare(j))
        return events

    def _exact(self) -> bool:
        """Finish the test the kernel left at EXACT: eq. (7) tail, new minimum, decision."""
        fs, ints = self._fs, self._ints
        k = int(ints[layout.I_K])
        dof = int(ints[layout.I_DOF])
        logpmin = float(fs[layout.F_LOGPMIN])
        logp = candidate_log_p2(float(fs[layout.F_Y]), float(fs[layout.F_TR]),
                                float(fs[layout.F_DM]), logpmin,
                                None if dof < 0 else float(dof))
        if logp is not None and logp < logpmin:
            self._record(k, logp)
        return self._declares(k)

    def _declares(self, k: int) -> bool:
        """Algorithm 1 line 18: p_min at or below r and ``k`` past the verification."""
        return (float(self._fs[layout.F_LOGPMIN]) <= self._logr
                and k > int(self._ints[layout.I_KMIN]) + self._kverif)

    def _record(self, k: int, logp: float) -> None:
        """Algorithm 1 lines 13-15: new smallest p_k."""
        self._fs[layout.F_LOGPMIN] = logp
        self._ints[layout.I_KMIN] = k
        self._fs[layout.F_YSTAR] = skip_threshold(logp)

    def _declare(self, n: int) -> list[AnomalyEvent]:
        """Algorithm 1 lines 18-21: declare the change and restart the reference.

        The paper restarts at ``k_min``; here at ``max(tau, k_min)`` (``tau`` the refined
        change position), so that the new reference holds post-change samples only. The
        kind is re-checked on ``[tau, j]`` (the gap ``[tau, start)`` is kept as one
        prefix-sum row). Tests of the new reference whose window is already complete run
        at once (never, since the start is at or after ``k_min``; kept for safety). Not in
        the paper: a declaration that the previous change's growth explains
        (:meth:`_continues`, docs/llr.md "Kinds on ramps") is no new change: its kind is
        re-checked instead and the reference restarts as after any declaration.
        """
        L, ring = self._L, self._rings()
        c, k_min = int(self._ints[layout.I_C]), int(self._ints[layout.I_KMIN])
        log_p = float(self._fs[layout.F_LOGPMIN])
        first = max(c, k_min - self._w)
        base = reference_base(c, first, self._R)
        prefix = ring.pref[np.arange(first, n + 2) % L]
        if base != c:
            prefix = prefix - ring.pref[base % L]
        ramps: dict[int, np.ndarray] = {}

        def ramp_of(tau: int) -> np.ndarray:
            ramps[tau] = self._ramp_block(tau, n, float(ring.time[tau % L]))
            return ramps[tau]

        tau, start, cat = declaration(prefix, first, base, k_min, n, self._cfg, self._z_thr,
                                      ramp_of)
        if self._continues(tau, n):
            prev = self._cat
            events = self._recheck(n, prev.gap + self._prefix_now())
            prev.gap = prev.gap + ring.pref[start % L]
            return events + self._restart_and_test(start, n)
        rows = (int(ring.row[tau % L]), int(ring.row[k_min % L]), int(ring.row[n % L]))
        times = (float(ring.time[tau % L]), float(ring.time[n % L]))
        event = make_event(self._component, cat, rows, times, log_p, 0)
        self._last_event = event
        checks = checkpoints(tau, n, self._cfg['category_revisions'], self._w)
        points = ramp_points(n, checks, self._w)
        self._ints[layout.I_CHECKPOINT] = points.pop(0) if points else -1
        self._cat = DeclaredChange(
            before=prefix[tau - first].copy(), n_before=tau - base, kind=cat.kind,
            guess=cat.guess, confirmed=cat.confirmed, revision=0, rows=rows, time=times[0],
            log_p=log_p, gap=prefix[start - first] - prefix[tau - first],
            checks=tuple(checks), points=points, ramp=[ramps[tau]], ramp_end=n, tau=tau,
            closed=not checks)
        return [event] + self._restart_and_test(start, n)

    def _restart_and_test(self, start: int, n: int) -> list[AnomalyEvent]:
        """Restart the reference at ``start``; run the tests whose window is complete."""
        self._restart(start, n)
        events: list[AnomalyEvent] = []
        pref = self._rings().pref
        for k in range(start + self._w + 1, n - self._w + 2):
            row = pref[(k + self._w) % self._L].copy()
            if self._p == 2:
                flags = kern.test_row(self._fs, self._ints, k, row)
                declare = bool(flags & kern.DECLARE) or bool(flags & kern.EXACT) and \
                    self._exact()
            else:
                declare = self._test_general(k, row)
            if declare:
                events.extend(self._declare(n))
        return events

    def _restart(self, c: int, n: int) -> None:
        """Start the new reference at position ``c`` and rebuild its prefix sums."""
        L, ring = self._L, self._rings()
        self._ints[layout.I_C] = c
        self._ints[layout.I_C_ROW] = ring.row[c % L]
        P = (0.0,) * 6 if self._p == 2 else np.zeros(llr_stats.width(self._p))
        ring.pref[c % L] = P
        for j in range(c, n + 1):
            if self._p == 2:
                h1, h2, f = ring.term[j % L]
                P = (P[0] + h1 * h1, P[1] + h1 * h2, P[2] + h2 * h2, P[3] + h1 * f,
                     P[4] + h2 * f, P[5] + f * f)
            else:
                P = P + ring.term[j % L]
            ring.pref[(j + 1) % L] = P
        if self._p == 2:
            self._fs[layout.F_PREF:layout.F_PREF + 6] = P
        else:
            self._pref_general = P
        self._fs[layout.F_LOGPMIN] = 0.0
        self._ints[layout.I_KMIN] = c
        self._fs[layout.F_YSTAR] = 0.0

    def _continues(self, tau: int, n: int) -> bool:
        """Return True if the change declared at ``n`` is the previous one still growing.

        Its ramp sums are kept up to date whether its re-checks are over (closed) or not:
        :func:`llr_growth.continues` on its segments up to ``n`` and on the samples
        ``[tau, n]``. If so, its ramp sums take in the samples up to ``n``. A closed change
        is tested too: a slow wear grows for days, past the last re-check (docs/llr.md
        "One declaration per ramp").
        """
        prev = self._cat
        if prev is None or prev.finished:
            return False
        blocks = list(prev.ramp)
        if prev.ramp_end < n:
            _add_block(blocks, self._ramp_block(prev.ramp_end + 1, n, prev.time), prev.tail)
        after = prev.gap + self._prefix_now()
        times = self._rings().time[np.arange(tau, n + 1) % self._L]
        if not llr_growth.continues(prev.before, prev.n_before, after, np.asarray(blocks),
                                    self._terms(tau, n), times - prev.time, prev.kind,
                                    self._p, self._noise_var, self._z_thr):
            return False
        prev.ramp = blocks
        prev.ramp_end = n
        return True

    def _ramp_block(self, first: int, last: int, t0: float) -> np.ndarray:
        """Return :func:`llr_growth.ramp_sums` of positions ``first..last`` (in the ring)."""
        times = self._rings().time[np.arange(first, last + 1) % self._L]
        return llr_growth.ramp_sums(self._terms(first, last), times - t0)

    def _terms(self, first: int, last: int) -> np.ndarray:
        """Return the per-sample terms of positions ``first..last`` (in the ring), ``(n, w)``.

        For p = 2 the ring holds ``(h1, h2, f)``: the six products are formed here with
        numpy, in the order of the kernel's prefix sums.
        """
        rows = self._rings().term[np.arange(first, last + 1) % self._L]
        if self._p != 2:
            return rows
        h1, h2, f = rows[:, 0], rows[:, 1], rows[:, 2]
        return np.column_stack((h1 * h1, h1 * h2, h2 * h2, h1 * f, h2 * f, f * f))

    def _revise(self, j: int) -> list[AnomalyEvent]:
        """Take the new samples into the ramp sums; re-check the kind at a checkpoint.

        ``j`` is a point of :func:`llr_common.ramp_points`; the kind is re-checked only at
        the points of :func:`llr_common.checkpoints`. After the last re-check the change is
        closed and its sums keep taking in samples every ``window`` samples, merged into
        one block (so the time shapes stay those of the re-checks plus the straight ramp
        to the end), for :meth:`finish`.
        """
        cat = self._cat
        self._ints[layout.I_CHECKPOINT] = cat.points.pop(0) if cat.points else j + self._w
        self._take_ramp(j)
        if j not in cat.checks:
            return []
        cat.closed = cat.closed or j == cat.checks[-1]
        return self._recheck(j, cat.gap + self._prefix_now())

    def _take_ramp(self, j: int) -> None:
        """Add the samples ``(ramp_end, j]`` to the ramp sums of the last change."""
        cat = self._cat
        if j <= cat.ramp_end:
            return
        _add_block(cat.ramp, self._ramp_block(cat.ramp_end + 1, j, cat.time), cat.tail)
        cat.tail = cat.closed
        cat.ramp_end = j

    def finish(self) -> list[AnomalyEvent]:
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
        cat = self._cat
        if cat is None or cat.finished or not cat.checks:
            return []
        j = int(self._ints[layout.I_POS]) - 1
        self._take_ramp(j)
        self._ints[layout.I_CHECKPOINT] = -1
        cat.points = []
        cat.finished = True
        return self._recheck(j, cat.gap + self._prefix_now(), final=True,
                             quiet=cat.closed)

    def _recheck(self, j: int, after: np.ndarray, final: bool = False, quiet: bool = False
                 ) -> list[AnomalyEvent]:
        """Re-check the kind of the last declared change on its after segment up to ``j``.

        ``final``: the end of record (:meth:`finish`); ``quiet``: then an event only if
        the answer differs from the last one given.
        """
        cat = self._cat
        new = llr_kinds.categorise(cat.before, cat.n_before, after, self._p,
                                   self._noise_var, self._z_thr, np.asarray(cat.ramp))
        if not final and not revision_due(cat.kind, cat.guess, cat.confirmed, new):
            return []
        if final and cat.confirmed and not new.confirmed and \
                llr_kinds.supports(new, cat.kind, self._z_thr):
            new = new._replace(kind=cat.kind, guess=cat.guess, confirmed=True)
        answer = (new.kind, new.guess, new.confirmed)
        if quiet and (answer == (cat.kind, cat.guess, cat.confirmed) or cat.confirmed
                      and llr_kinds.adds_component(cat.kind, new.kind)):
            return []
        cat.kind, cat.guess, cat.confirmed = new.kind, new.guess, new.confirmed
        cat.revision += 1
        ring = self._rings()
        rows = cat.rows[:2] + (int(ring.row[j % self._L]),)
        times = (cat.time, float(ring.time[j % self._L]))
        self._last_event = make_event(self._component, new, rows, times, cat.log_p,
                                      cat.revision, j - cat.tau + 1 if final else None)
        return [self._last_event]


def _add_block(blocks: list[np.ndarray], block: np.ndarray, tail: bool) -> None:
    """Append a ramp-sum block, or merge it into the last one after the last re-check.

    Merged, the sums add and the knot moves to the new block's end: the time shapes of
    a closed change stay those of its re-checks plus the straight ramp to the end, so
    their number stays bounded however long the change grows.
    """
    if tail:
        blocks[-1] = np.concatenate([block[:1], blocks[-1][1:] + block[1:]])
    else:
        blocks.append(block)
