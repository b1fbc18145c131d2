"""Cases of the ARL and detection-loss benchmark (``python -m bench arl``).

Realistic SI profile (:func:`rwa_monitor.sim.profiles.realistic_profile`: holds, slews,
zero crossings, orbital drift) at 10 Hz, the SI regime of :mod:`rwa_monitor.sim.friction`
(dry 2e-4 N m, viscous 5e-7 N m s, noise std 5e-5 N m), window 400, k_verif 200, noise
level estimated. Each noise case replaces the white Gaussian noise of model (1):

- ``gaussian``: white Gaussian (the paper's assumption);
- ``student_t3``: white Student-t, 3 degrees of freedom, scaled to the same std;
- ``ar1_0.3``, ``ar1_0.5``, ``ar1_0.8``: stationary AR(1) of the same std;
- ``speed_noise``: white Gaussian whose std grows with speed, ``s (0.5 + |w| / 200)``
  (x0.5 at rest, x3.5 at the 600 rad/s limit);
- ``dry_orbit``: dry friction ``x (1 + 0.1 sin(2 pi t / T_orbit + phase))``, white noise,
  no auxiliary channel (the detector uses a sliding reference);
- ``dry_orbit_temperature``: the same drift following a temperature channel
  ``T = 20 + 10 sin(...) + N(0, 0.1^2)`` degC (dry ``x (1 + 0.01 (T - 20))``), given to
  the detector as a third regressor column.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from scipy import signal

from rwa_monitor.core.friction import dry_column, RegressorSet, viscous_column
from rwa_monitor.sim.friction import REGIMES
from rwa_monitor.sim.profiles import ORBIT_PERIOD_S, realistic_profile

RATE_HZ = 10.0
SI = REGIMES['si']
NOISE_CASES = ('gaussian', 'student_t3', 'ar1_0.3', 'ar1_0.5', 'ar1_0.8', 'speed_noise',
               'dry_orbit', 'dry_orbit_temperature')
DETECTOR = {'window': 400, 'k_verif': 200, 'noise_std': None}
# Sliding reference for a drift without an auxiliary channel (docs/llr.md "Slow drifts").
REFERENCE_MAX = 2000
TEMPERATURE = 'temperature_c'
T0_C = 20.0


def temperature_column(speed, time=None, aux=None) -> np.ndarray:
    """Return the dry regressor scaled by the temperature offset, ``-sign(w) (T - T0)``."""
    return -np.sign(np.asarray(speed, dtype=float)) * (np.asarray(aux[TEMPERATURE]) - T0_C)


def temperature_model() -> RegressorSet:
    """Return eq. (1) plus a dry-friction temperature coefficient column."""
    return RegressorSet(('dry', 'viscous', 'dry_per_degc'),
                        (dry_column, viscous_column, temperature_column))


def detector_config(case: str, rate: float, variant: str = 'default') -> dict[str, Any]:
    """Return the detector keywords for ``case``.

    ``variant``: ``default`` (AR prewhitening; a sliding reference for ``dry_orbit``, the
    temperature column for ``dry_orbit_temperature``, the noise level modelled against
    ``|w|`` for ``speed_noise``), ``paper`` (white noise, growing
    reference: the paper's Algorithm 1 with the studentised noise level), ``sliding``
    (default plus the sliding reference whatever the case).
    """
    cfg = dict(DETECTOR, false_alarm_rate=rate)
    if variant == 'paper':
        return dict(cfg, noise_ar_max_order=0)
    if case == 'dry_orbit' or variant == 'sliding':
        cfg['reference_max'] = REFERENCE_MAX
    if case == 'dry_orbit_temperature':
        cfg['regressors'] = temperature_model()
    if case == 'speed_noise':
        cfg['noise_speed_model'] = True
    return cfg


def _ar1(n: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    burn = int(20 / (1.0 - rho))
    e = rng.standard_normal(n + burn) * math.sqrt(1.0 - rho * rho)
    return signal.lfilter([1.0], [1.0, -rho], e)[burn:]


def simulate(case: str, n: int, seed: int, step: tuple[int, float, float] | None = None
             ) -> dict[str, Any]:
    """Return ``{'time', 'speed', 'friction', 'aux'}`` of one seeded run of ``case``.

    ``step = (index, delta_dry_nm, delta_viscous_nms)`` adds a friction change.
    """
    rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(NOISE_CASES.index(case),)))
    t = np.arange(n, dtype=float) / RATE_HZ
    w = realistic_profile(t, rng)
    s = SI['noise_std_nm']
    dry = np.full(n, SI['dry_nm'])
    visc = np.full(n, SI['viscous_nms'])
    aux = None
    if case == 'student_t3':
        noise = s * rng.standard_t(3, n) / math.sqrt(3.0)
    elif case.startswith('ar1_'):
        noise = s * _ar1(n, float(case[4:]), rng)
    elif case == 'speed_noise':
        noise = s * (0.5 + np.abs(w) / 200.0) * rng.standard_normal(n)
    else:
        noise = s * rng.standard_normal(n)
    if case.startswith('dry_orbit'):
        wave = np.sin(2.0 * np.pi * t / ORBIT_PERIOD_S + rng.uniform(0.0, 2.0 * np.pi))
        dry = dry * (1.0 + 0.1 * wave)
        if case == 'dry_orbit_temperature':
            aux = {TEMPERATURE: T0_C + 10.0 * wave + 0.1 * rng.standard_normal(n)}
    if step is not None:
        dry[step[0]:] += step[1]
        visc[step[0]:] += step[2]
    friction = -dry * np.sign(w) - visc * w + noise
    return {'time': t, 'speed': w, 'friction': friction, 'aux': aux}


def false_alarm_task(task: dict[str, Any]) -> dict[str, Any]:
    """Run one nominal run; return the number of declarations and the samples tested."""
    from rwa_monitor.core.llr import detect_batch
    data = simulate(task['case'], task['n'], task['seed'])
    cfg = detector_config(task['case'], task['rate'], task['variant'])
    start = time.process_time()
    events = detect_batch(data['time'], data['speed'], data['friction'], aux=data['aux'],
                          **cfg)
    return {'alarms': sum(e.revision == 0 for e in events), 'samples': task['n'],
            'seconds': time.process_time() - start}


def detection_task(task: dict[str, Any]) -> dict[str, Any]:
    """Run one run with a step at ``task['at']``; return whether and when it was found.

    Detected: a first declaration at or after the change whose estimated change is within
    one window before it; delay in samples from the change to that declaration.
    """
    from rwa_monitor.core.llr import detect_batch
    at = task['at']
    data = simulate(task['case'], task['n'], task['seed'],
                    (at, task['delta_dry'], task['delta_viscous']))
    cfg = detector_config(task['case'], task['rate'], task['variant'])
    events = detect_batch(data['time'], data['speed'], data['friction'], aux=data['aux'],
                          **cfg)
    window = cfg['window']
    hits = [e for e in events if e.revision == 0 and e.index >= at - window
            and e.declared_index >= at]
    early = any(e.revision == 0 and e.declared_index < at for e in events)
    if not hits:
        return {'detected': False, 'delay': math.nan, 'early_alarm': early}
    hit = min(hits, key=lambda e: e.declared_index)
    return {'detected': True, 'delay': hit.declared_index - at, 'early_alarm': early}
