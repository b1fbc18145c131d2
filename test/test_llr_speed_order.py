"""Kinds on an after segment whose speed runs in one order (a coast-down after a change).

docs/llr.md "Kinds that survive collinearity", *Speed in one order*: where the speed falls
(or rises) through the after segment block by block, each candidate time shape of the
growth tests is a function of the speed there, and a speed shape of the residual that the
model misses fits them as well as a growth would; the step outcome stands.
"""

import numpy as np

from rwa_monitor.core import keys
from rwa_monitor.core.llr import detect_batch
from rwa_monitor.core.llr_kinds import speed_ordered


def test_speed_order_needs_two_blocks_whose_ranges_do_not_overlap():
    falling = np.array([[20.0, 30.0], [12.0, 19.5], [5.0, 11.0]])
    assert speed_ordered(falling)
    assert speed_ordered(falling[::-1])        # speeding up
    assert not speed_ordered(falling[:1])      # one block: no order to see
    touching = falling.copy()
    touching[1, 1] = 20.0                      # the ranges share a speed
    assert not speed_ordered(touching)
    swinging = np.array([[8.0, 30.0], [7.0, 31.0], [9.0, 29.0]])
    assert not speed_ordered(swinging)
    assert not speed_ordered(np.full((3, 2), np.nan))   # p > 2: speeds not kept


def _two_coasts(seed: int, n: int = 1200, step_s: float = 0.25):
    """Two identical coasts 30 s apart, the second with 0.05 N m more dry friction.

    The friction holds a drag-like term ``w |w|`` that model (1) lacks, in both coasts.
    """
    t = np.arange(n) * step_s
    w = 30.0 * np.exp(-t / 150.0)
    time = np.concatenate([t, t + t[-1] + 30.0])
    speed = np.concatenate([w, w])
    friction = -0.02 * np.sign(speed) - 1.0e-3 * speed - 4.0e-5 * speed * np.abs(speed)
    friction += np.random.default_rng(seed).normal(0.0, 5.0e-4, time.size)
    friction[n:] -= 0.05 * np.sign(speed[n:])
    return time, speed, friction, n


def test_a_dry_step_between_two_coasts_with_a_missing_speed_shape_is_named_dry():
    # Fresh seeds (development: 3600-3605). The code before this rule named all 20
    # `undecided` ("the change grows"): the after segment's time shapes fitted the drag
    # term. Under the step model the step tests confirm dry unless the viscous component
    # passes the 5 % level or a false significance at the category level (1e-3): each run
    # is right with probability >= 0.94, and <= 15 of 20 right has probability below 0.02.
    right = 0
    for seed in range(3610, 3630):
        t, w, f, change = _two_coasts(seed)
        events = detect_batch(t, w, f, category_level=1.0e-3)
        first = [e for e in events if e.revision == 0]
        assert [abs(e.index - change) <= 100 for e in first] == [True], first
        last = max((e for e in events if e.index == first[0].index),
                   key=lambda e: e.revision)
        assert last.kind in ('dry', 'undecided'), last
        right += last.kind == 'dry' and bool(last.details[keys.KIND_CONFIRMED])
    assert right >= 16
