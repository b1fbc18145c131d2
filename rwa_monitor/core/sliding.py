"""Sliding windows of floats for VSADC's sigma limits (core/vsadc_axis.py), with records.

:class:`SlidingWindow` keeps running sums (mean, standard deviation), :class:`SlidingMax`
the maximum (monotonic deque). ``record()`` returns their state as a typed record
(core/gyro_state.py), ``check_record`` refuses one that does not fit the window,
``restore`` puts one back.
"""

from __future__ import annotations

from collections import deque
import math

import numpy as np

from rwa_monitor.core.gyro_state import (
    check_counts, check_finite, check_type, chronological, require, ring, SlidingMaxState,
    WindowState)

RESUM_EVERY = 4096


class SlidingWindow:
    """A fixed-length window of floats with its running sum and sum of squares."""

    __slots__ = ('size', 'values', 'pos', 'count', 'total', 'squares', 'updates')

    def __init__(self, size: int) -> None:
        self.size = size
        self.values = [0.0] * size
        self.pos = self.count = self.updates = 0
        self.total = self.squares = 0.0

    def push(self, x: float) -> float:
        """Add ``x``; return the value that left (0.0 while the window fills)."""
        old = self.values[self.pos]
        self.values[self.pos] = x
        self.pos = (self.pos + 1) % self.size
        if self.count < self.size:
            self.count += 1
            old = 0.0
        self.total += x - old
        self.squares += x * x - old * old
        self.updates += 1
        if self.updates % RESUM_EVERY == 0:    # bound the rounding drift of running sums
            vals = self.values[:self.count]
            self.total = math.fsum(vals)
            self.squares = math.fsum(v * v for v in vals)
        return old

    def mean(self) -> float:
        """Return the mean of the values in the window."""
        return self.total / self.count

    def std(self) -> float:
        """Return the standard deviation (population) of the values in the window."""
        m = self.total / self.count
        return math.sqrt(max(self.squares / self.count - m * m, 0.0))

    def record(self) -> WindowState:
        """Return the window's state (values oldest first, the running sums as they are)."""
        values = chronological(self.values, self.updates, self.size)
        return WindowState(np.array(values, dtype=np.float64), self.total, self.squares,
                           self.updates)

    def check_record(self, record: WindowState, path: str) -> None:
        """Refuse a record of another window length or inconsistent with itself."""
        check_type(record, WindowState, path)
        check_counts(record, ('updates',), path)
        count = min(record.updates, self.size)
        require(len(record.values) == count, f'{path}.values',
                f'expected {count} values (window {self.size}, {record.updates} pushed), '
                f'got {len(record.values)}')
        check_finite(path, record.values, record.total, record.squares)

    def restore(self, record: WindowState) -> None:
        """Put ``record`` back (checked first: RecordError, and the window unchanged)."""
        self.check_record(record, type(record).__name__)
        self.values = ring(record.values.tolist(), record.updates, self.size, 0.0)
        self.pos = record.updates % self.size
        self.count = min(record.updates, self.size)
        self.total, self.squares, self.updates = record.total, record.squares, record.updates


class SlidingMax:
    """Max over the last ``size`` pushed values (monotonic deque, O(1) amortised)."""

    __slots__ = ('size', 'items', 'n')

    def __init__(self, size: int) -> None:
        self.size = size
        self.items: deque = deque()
        self.n = 0

    def push(self, x: float) -> None:
        """Add ``x``; forget the values it dominates and the one that left the window."""
        items = self.items
        while items and items[-1][1] <= x:
            items.pop()
        items.append((self.n, x))
        self.n += 1
        if items[0][0] <= self.n - 1 - self.size:
            items.popleft()

    def max(self) -> float:
        """Return the maximum of the last ``size`` values pushed."""
        return self.items[0][1]

    def record(self) -> SlidingMaxState:
        """Return the candidates for the maximum and the number of values pushed."""
        return SlidingMaxState(np.array([p for p, _ in self.items], dtype=np.int64),
                               np.array([v for _, v in self.items], dtype=np.float64), self.n)

    def check_record(self, record: SlidingMaxState, path: str) -> None:
        """Refuse candidates outside the window, out of order or not decreasing."""
        check_type(record, SlidingMaxState, path)
        check_counts(record, ('pushed',), path)
        positions, values, n = record.positions, record.values, record.pushed
        require(len(positions) == len(values), path, 'positions and values differ in length')
        require(len(positions) <= min(n, self.size), f'{path}.positions',
                f'more candidates than the window ({self.size}) holds')
        require(n == 0 or (len(positions) and positions[-1] == n - 1), f'{path}.positions',
                'the last value pushed must be a candidate')
        require(not len(positions) or positions[0] > n - 1 - self.size, f'{path}.positions',
                'a candidate lies outside the window')
        require(bool(np.all(np.diff(positions) > 0)), f'{path}.positions', 'not increasing')
        require(bool(np.all(np.diff(values) < 0)), f'{path}.values', 'not decreasing')
        check_finite(f'{path}.values', values)

    def restore(self, record: SlidingMaxState) -> None:
        """Put ``record`` back (checked first: RecordError, and the maximum unchanged)."""
        self.check_record(record, type(record).__name__)
        self.items = deque(zip(record.positions.tolist(), record.values.tolist()))
        self.n = record.pushed
