"""Wheel spin-rate profiles (rad/s) as functions of the sample index or of time.

The four profiles of the llr-realtime paper's experiments are functions of the sample
index ``k`` (section III): ``fig3`` w_k = 20 - 10 cos(pi k / 1200), ``fig4`` w_k = 20 +
5 cos(pi k / 1000), ``fig5`` w_k = 20 + 5 cos(k / 5000), ``fig6`` w_k = 100 - k / 1250.
The others are functions of time (seconds): ``ramp`` (triangle sweep through zero),
``constant`` (dry and viscous friction not separable: for tests) and ``realistic``
(holds at a bias speed, slews at a bounded acceleration, momentum unloads that cross
zero, an orbital-period drift; see docs/simulators.md).
"""

from __future__ import annotations

import math

import numpy as np

from rwa_monitor.core.params import check_choice, check_int, check_real

PAPER_PROFILES = ('fig3', 'fig4', 'fig5', 'fig6')
PROFILES = PAPER_PROFILES + ('ramp', 'constant', 'realistic')

# Realistic profile of a small-satellite wheel (docs/simulators.md, "Realistic profile").
MAX_SPEED_RAD_S = 600.0        # ~5700 rpm, the usual top speed of 10-50 mNms wheels
MAX_ACCEL_RAD_S2 = 10.0        # 2 mNm motor torque on a 2e-4 kg m^2 flywheel
ORBIT_PERIOD_S = 5700.0        # ~95 min low Earth orbit
ORBIT_AMPLITUDE_RAD_S = 15.0   # momentum accumulated from environmental torques
RAMP_PERIOD_S = 1200.0
RAMP_AMPLITUDE_RAD_S = 100.0
CONSTANT_SPEED_RAD_S = 50.0


def paper_profile(name: str, k: np.ndarray) -> np.ndarray:
    """Return the spin rate of one of the llr-realtime paper's experiments at indices ``k``.

    Section III: fig3 (III-A, Fig. 3), fig4 (III-A, Fig. 4), fig5 (III-B) and fig6
    (III-C, Figs. 6-7). ``k`` may be shifted (a phase) for further wheels.
    """
    check_choice('profile', name, PAPER_PROFILES)
    k = np.asarray(k, dtype=float)
    if name == 'fig3':
        return 20.0 - 10.0 * np.cos(np.pi * k / 1200.0)
    if name == 'fig4':
        return 20.0 + 5.0 * np.cos(np.pi * k / 1000.0)
    if name == 'fig5':
        return 20.0 + 5.0 * np.cos(k / 5000.0)
    return 100.0 - k / 1250.0


def ramp_profile(t: np.ndarray, phase: float = 0.0, amplitude: float = RAMP_AMPLITUDE_RAD_S,
                 period_s: float = RAMP_PERIOD_S) -> np.ndarray:
    """Return a triangle sweep between -amplitude and +amplitude (rad/s), period in s."""
    u = (np.asarray(t, dtype=float) / period_s + phase) % 1.0
    return amplitude * (4.0 * np.abs(u - 0.5) - 1.0)


def realistic_profile(t: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Return a seeded operational spin-rate history at times ``t`` (s).

    A sequence of segments drawn from ``rng``: holds at the current bias speed (60-900 s),
    slews to a new speed within +-MAX_SPEED_RAD_S at an acceleration drawn up to
    MAX_ACCEL_RAD_S2 (constant acceleration, so the speed ramps), and, one segment in five,
    a momentum unload to a speed of the opposite sign (a zero crossing). An orbital-period
    sinusoid (ORBIT_AMPLITUDE_RAD_S, ORBIT_PERIOD_S, random phase) is added on top, and
    the result is clipped to +-MAX_SPEED_RAD_S.
    """
    t = np.asarray(t, dtype=float)
    if t.size == 0:
        return np.empty(0)
    start, stop = float(t[0]), float(t[-1])
    knots_t = [start]
    knots_w = [float(rng.choice([-1.0, 1.0]) * rng.uniform(50.0, 250.0))]
    while knots_t[-1] <= stop:
        hold = rng.uniform(60.0, 900.0)
        knots_t.append(knots_t[-1] + hold)
        knots_w.append(knots_w[-1])
        current = knots_w[-1]
        if rng.random() < 0.2:
            target = -math.copysign(rng.uniform(50.0, 300.0), current)
        else:
            target = current + rng.normal(0.0, 150.0)
        target = float(np.clip(target, -0.9 * MAX_SPEED_RAD_S, 0.9 * MAX_SPEED_RAD_S))
        accel = rng.uniform(0.1, 1.0) * MAX_ACCEL_RAD_S2
        knots_t.append(knots_t[-1] + max(abs(target - current) / accel, 1e-3))
        knots_w.append(target)
    speed = np.interp(t, knots_t, knots_w)
    phase = rng.uniform(0.0, 2.0 * np.pi)
    speed += ORBIT_AMPLITUDE_RAD_S * np.sin(2.0 * np.pi * t / ORBIT_PERIOD_S + phase)
    return np.clip(speed, -MAX_SPEED_RAD_S, MAX_SPEED_RAD_S)


def spin_profile(name: str, n: int, *, rate_hz: float, wheel_index: int = 0,
                 rng: np.random.Generator | None = None) -> np.ndarray:
    """Return ``n`` samples of the named profile for the ``wheel_index``-th wheel.

    Wheel 0 of a paper profile is exactly the paper's formula; wheel i is shifted by
    i * 300 samples so that wheels differ. ``ramp`` wheels are shifted by a quarter
    period each; ``realistic`` wheels each draw their own history from ``rng``.
    """
    check_choice('profile', name, PROFILES)
    n = check_int('n', n, 0)
    rate_hz = check_real('rate_hz', rate_hz, 0.0, low_open=True)
    k = np.arange(n, dtype=float)
    if name in PAPER_PROFILES:
        return paper_profile(name, k + 300.0 * wheel_index)
    t = k / rate_hz
    if name == 'ramp':
        return ramp_profile(t, phase=0.25 * wheel_index)
    if name == 'constant':
        return np.full(n, CONSTANT_SPEED_RAD_S * (1.0 + 0.1 * wheel_index))
    if rng is None:
        raise ValueError('rng is required for the realistic profile')
    return realistic_profile(t, rng)
