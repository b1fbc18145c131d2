"""Stream rules shared by the nodes and file pipelines (ROS-free; docs/nodes.md "Bad input").

- :class:`StampGate`: per component, a stamp equal to the last accepted one is a
  duplicate, a stamp up to ``time_jump`` s before it is out of order (both dropped), a
  stamp more than ``time_jump`` s before it is a time jump (a replay loop: the caller
  restarts the component's detector and the stamp is accepted); non-finite stamps are
  dropped.
- :class:`StampPairer`: gyro and star-tracker samples paired by stamp (within
  ``tolerance`` s) with bounded buffers; a gyro sample whose partner cannot come any more
  (the star tracker is past its stamp) or that has waited behind ``max_lag`` others is
  released without a quaternion and counted; quaternions no gyro sample matches are
  dropped and counted.
- :class:`SilenceTracker`: which components have been silent longer than a timeout.

Every rule counts what it drops; nothing here raises on any float input.
"""

from __future__ import annotations

from collections import deque
import math
from typing import Any, Callable, Hashable, Iterator, Sequence

ACCEPT = 'accepted'
DUPLICATE = 'duplicate_stamp'
OUT_OF_ORDER = 'out_of_order'
TIME_JUMP = 'time_jump_reset'
NON_FINITE = 'non_finite_stamp'


class StampGate:
    """The stamp rule of one component's stream (see the module docstring)."""

    def __init__(self, time_jump: float = 1.0) -> None:
        self.time_jump = time_jump
        self.counters = {DUPLICATE: 0, OUT_OF_ORDER: 0, TIME_JUMP: 0, NON_FINITE: 0}
        self.last: float | None = None

    def check(self, t: float) -> str:
        """Return the verdict on stamp ``t``: ACCEPT, TIME_JUMP (accepted) or a drop reason."""
        if not math.isfinite(t):
            self.counters[NON_FINITE] += 1
            return NON_FINITE
        last = self.last
        if last is not None and t <= last:
            back = last - t
            if back > self.time_jump:
                self.counters[TIME_JUMP] += 1
                self.last = t
                return TIME_JUMP
            reason = DUPLICATE if back == 0.0 else OUT_OF_ORDER
            self.counters[reason] += 1
            return reason
        self.last = t
        return ACCEPT

    def reset(self) -> None:
        """Forget the last stamp (the counters stay)."""
        self.last = None


class StampPairer:
    """Pair gyro samples with star-tracker quaternions by stamp, in stamp order.

    ``push_gyro``/``push_star`` queue samples; :meth:`drain` yields ``(t, rate, q or
    None, reference)`` for every gyro sample that can be decided now. ``reference_for(t,
    lagging)`` gives the reference rate for ``t``, or None to wait for it. Memory: at most
    ``max_lag + 1`` gyro samples and ``4 * max_lag`` quaternions. A gyro stamp more than
    ``time_jump`` s before the last one released empties the buffers but for the
    quaternions of the new pass (``push_gyro`` returns True: the caller restarts its
    detector).
    """

    def __init__(self, tolerance: float = 1e-3, max_lag: int = 40,
                 time_jump: float = 1.0) -> None:
        self.tolerance = tolerance
        self.max_lag = max_lag
        self.time_jump = time_jump
        self.counters = {'unpaired_gyro': 0, 'unpaired_star_tracker': 0,
                         'time_jump_reset': 0, 'non_finite_stamp': 0}
        self._gyro: deque = deque()
        self._star: deque = deque()
        self.last_released = -math.inf

    def reset(self) -> None:
        """Empty the buffers (the counters stay)."""
        self._gyro.clear()
        self._star.clear()
        self.last_released = -math.inf

    @property
    def waiting(self) -> tuple[int, int]:
        """Return the numbers of queued (gyro samples, quaternions)."""
        return len(self._gyro), len(self._star)

    def push_gyro(self, t: float, rate: Sequence[float]) -> bool:
        """Queue a gyro sample; return True if its stamp jumped back (buffers emptied)."""
        if not math.isfinite(t):
            self.counters['non_finite_stamp'] += 1
            return False
        jumped = t < self.last_released - self.time_jump
        if jumped:
            # Quaternions of the new pass may have arrived first: keep those.
            new_pass = [s for s in self._star if s[0] < self.last_released - self.time_jump]
            self.counters['time_jump_reset'] += 1
            self.reset()
            self._star.extend(new_pass)
        self._gyro.append((t, rate))
        return jumped

    def push_star(self, t: float, q: Sequence[float]) -> None:
        """Queue a star-tracker quaternion (the oldest is dropped beyond the bound)."""
        if not math.isfinite(t):
            self.counters['non_finite_stamp'] += 1
            return
        self._star.append((t, q))
        if len(self._star) > 4 * self.max_lag:
            self._star.popleft()
            self.counters['unpaired_star_tracker'] += 1

    def drain(self, reference_for: Callable[[float, bool], Any]
              ) -> Iterator[tuple[float, Sequence[float], Sequence[float] | None, Any]]:
        """Yield every gyro sample that can be released now, paired or not."""
        tol = self.tolerance
        gyro, star = self._gyro, self._star
        while gyro:
            t, rate = gyro[0]
            while star and star[0][0] < t - tol:
                star.popleft()                           # a quaternion no gyro matches
                self.counters['unpaired_star_tracker'] += 1
            lagging = len(gyro) > self.max_lag
            paired = bool(star) and abs(star[0][0] - t) <= tol
            if not (paired or star or lagging):
                return                                   # wait for the star tracker
            ref = reference_for(t, lagging)
            if ref is None:
                return                                   # wait for the reference
            q = star.popleft()[1] if paired else None
            gyro.popleft()
            if q is None:
                self.counters['unpaired_gyro'] += 1
            self.last_released = max(self.last_released, t)
            yield t, rate, q, ref


class SilenceTracker:
    """Remember when each component was last heard; list those silent past a timeout."""

    def __init__(self, timeout: float) -> None:
        self.timeout = timeout
        self._last: dict[Hashable, float] = {}

    def heard(self, component: Hashable, now: float) -> None:
        """Record input from ``component`` at time ``now``."""
        self._last[component] = now

    def forget(self, component: Hashable) -> None:
        """Stop tracking ``component``."""
        self._last.pop(component, None)

    def silent(self, now: float) -> list[Hashable]:
        """Return the components not heard for more than ``timeout`` (0: never silent)."""
        if not self.timeout > 0.0:
            return []
        return [c for c, t in self._last.items() if now - t > self.timeout]


class SensorFaultMonitor:
    """Persistent implausible input of one channel: a sensor fault, not an anomaly.

    ``update(seen, rejected)`` takes the running totals of samples seen and samples
    rejected as implausible (outside the plausibility limits, or not finite) and returns
    the fault text when, since the previous call, at least ``min_samples`` arrived and
    at least ``fraction`` of them were rejected; else None.
    """

    def __init__(self, min_samples: int = 20, fraction: float = 0.5) -> None:
        self.min_samples = min_samples
        self.fraction = fraction
        self._last = (0, 0)
        self.fault: str | None = None

    def update(self, seen: int, rejected: int) -> str | None:
        """Return the fault text of the interval since the last call (None if healthy)."""
        n, bad = seen - self._last[0], rejected - self._last[1]
        if n < 0 or bad < 0:            # the totals restarted
            n, bad = seen, rejected
        self._last = (seen, rejected)
        if n >= self.min_samples:
            self.fault = (f'sensor fault: {bad} of the last {n} samples implausible or not '
                          'finite' if bad >= self.fraction * n else None)
        return self.fault
