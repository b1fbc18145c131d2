"""Seeded wheel telemetry with an effect that model (1) lacks and nobody declares.

Friction is model (1) of the llr-realtime paper, f = -dry sign(w) - viscous w + e, plus
one undeclared effect (docs/identify.md gives the sizes and why):

- ``none``: nothing (the identification must add nothing);
- ``stribeck``: -fs sign(w) exp(-(w / ws)^2) around the zero crossings;
- ``drag``: -c w |w| (aerodynamic drag);
- ``temperature``: dry friction (1 + k (T - 20 C)) with the wheel temperature T in the
  aux column ``<wheel>_temperature`` (orbital cycle);
- ``drift``: dry friction growing linearly in time;
- ``periodic``: a sinusoidal torque in time.

Every file carries the temperature channel (it matters only for ``temperature``) and a
constant bus-voltage channel. A dry-friction step (a true anomaly) can be injected.
The speed profile is a sum of two sinusoids that crosses zero many times.
"""

from __future__ import annotations

import numpy as np

from rwa_monitor.core.params import check_choice, check_int, check_real
from rwa_monitor.telemetry import Telemetry, Wheel

EFFECTS = ('none', 'stribeck', 'drag', 'temperature', 'drift', 'periodic')
DRY_NM = 1.0e-3
VISCOUS_NMS = 5.0e-6
NOISE_NM = 5.0e-5
SIZES = {'stribeck': {'static_excess_nm': 1.5e-3, 'velocity_rad_s': 4.0},
         'drag': {'coefficient_nms2': 2.0e-8},
         'temperature': {'per_kelvin': 0.03, 'mean_c': 20.0, 'amplitude_c': 8.0,
                         'period_s': 5400.0},
         'drift': {'dry_increase_nm': 5.0e-4},
         'periodic': {'amplitude_nm': 1.5e-4, 'period_s': 700.0}}


def speed_profile(time: np.ndarray) -> np.ndarray:
    """Return the spin rate (rad/s): 120 sin(2 pi t / 1500 s) + 60 sin(2 pi t / 370 s + 1)."""
    return 120.0 * np.sin(2 * np.pi * time / 1500.0) + 60.0 * np.sin(
        2 * np.pi * time / 370.0 + 1.0)


def simulate_undeclared(effect: str = 'none', n: int = 10000, dt: float = 1.0, seed: int = 0,
                        wheel: str = 'rw1', noise_std: float = NOISE_NM,
                        anomaly_time: float | None = None, anomaly_dry: float = 0.0
                        ) -> Telemetry:
    """Return telemetry with one undeclared effect (truth columns: clean friction, effect).

    ``anomaly_time`` (s) and ``anomaly_dry`` (N m) inject a step of the dry friction.
    """
    effect = check_choice('effect', effect, EFFECTS)
    n = check_int('n', n, 10, 10_000_000)
    dt = check_real('dt', dt, 0.0, low_open=True)
    noise_std = check_real('noise_std', noise_std, 0.0)
    anomaly_dry = check_real('anomaly_dry', anomaly_dry)
    rng = np.random.default_rng(seed)
    time = np.arange(n) * dt
    speed = speed_profile(time)
    t_size = SIZES['temperature']
    temperature = (t_size['mean_c'] + t_size['amplitude_c']
                   * np.sin(2 * np.pi * time / t_size['period_s'])
                   + 0.05 * rng.standard_normal(n))
    dry = np.full(n, DRY_NM)
    if anomaly_time is not None:
        dry[time >= check_real('anomaly_time', anomaly_time, 0.0)] += anomaly_dry
    extra = np.zeros(n)
    if effect == 'stribeck':
        s = SIZES['stribeck']
        extra = -s['static_excess_nm'] * np.sign(speed) * np.exp(
            -(speed / s['velocity_rad_s']) ** 2)
    elif effect == 'drag':
        extra = -SIZES['drag']['coefficient_nms2'] * speed * np.abs(speed)
    elif effect == 'temperature':
        extra = -DRY_NM * t_size['per_kelvin'] * (temperature - t_size['mean_c']) * np.sign(
            speed)
    elif effect == 'drift':
        extra = -SIZES['drift']['dry_increase_nm'] * (time / time[-1]) * np.sign(speed)
    elif effect == 'periodic':
        s = SIZES['periodic']
        extra = s['amplitude_nm'] * np.sin(2 * np.pi * time / s['period_s'])
    clean = -dry * np.sign(speed) - VISCOUS_NMS * speed + extra
    friction = clean + noise_std * rng.standard_normal(n)
    return Telemetry(time=time, wheels={wheel: Wheel(speed=speed, friction=friction)},
                     aux={f'{wheel}_temperature': temperature,
                          f'{wheel}_bus_voltage': np.full(n, 28.0)},
                     truth={f'{wheel}_friction_clean': clean, f'{wheel}_effect': extra,
                            f'{wheel}_dry': dry},
                     source=f'undeclared:{effect}:seed{seed}')
