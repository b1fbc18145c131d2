"""Seeded reaction-wheel friction telemetry: model (1) of the llr-realtime paper.

Per wheel and sample ``k``: f_k = -f_c,k sign(w_k) - f_v,k w_k + e_k, e_k ~ N(0, s^2)
(llr-realtime paper, eq. (1); torque in N m, or in noise units in the scaled regime).
The spin rate w_k comes from :mod:`rwa_monitor.sim.profiles`; f_c and f_v are the nominal
values plus the steps of the injected anomalies. Two parameter regimes
(docs/simulators.md): ``si`` (a small-satellite wheel in N m) and ``scaled`` (the paper's
units: noise standard deviation 1).
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Iterable, Sequence

import numpy as np

from rwa_monitor.core.keys import FRICTION_KINDS
from rwa_monitor.core.params import check_choice, check_int, check_real
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.sim.profiles import PROFILES, spin_profile
from rwa_monitor.telemetry import Telemetry, Wheel

# Nominal dry (N m), viscous (N m s/rad) and noise std (N m) per regime; scaled = si / noise.
REGIMES = {
    'si': {'dry_nm': 2.0e-4, 'viscous_nms': 5.0e-7, 'noise_std_nm': 5.0e-5},
    'scaled': {'dry_nm': 4.0, 'viscous_nms': 0.01, 'noise_std_nm': 1.0},
}
DEFAULT_WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')


@dataclass(frozen=True)
class Anomaly:
    """A step in a wheel's friction parameters at ``time_s`` (s from the first sample)."""

    wheel: str
    kind: str
    time_s: float
    delta_dry: float = 0.0
    delta_viscous: float = 0.0


@dataclass(frozen=True)
class Change:
    """An injected change as applied: the first sample carrying the new parameters."""

    wheel: str
    kind: str
    index: int
    time_s: float
    delta_dry: float
    delta_viscous: float


def parse_anomaly(spec: str) -> Anomaly:
    """Parse ``WHEEL:KIND:TIME_S:SIZE[:SIZE_VISCOUS]``; raise ConfigError saying what is wrong.

    KIND is dry (SIZE in N m), viscous (SIZE in N m s/rad) or both (SIZE dry, then
    SIZE_VISCOUS), e.g. ``rw2:dry:3600:+2e-4`` or ``rw1:both:600:1e-4:2e-7``.
    """
    usage = 'expected WHEEL:KIND:TIME_S:SIZE (KIND dry|viscous) or WHEEL:both:TIME_S:DRY:VISC'
    parts = spec.split(':')
    if len(parts) < 4 or not parts[0]:
        raise ConfigError(f'bad anomaly {spec!r}: {usage}')
    wheel, kind = parts[0], parts[1]
    if kind not in FRICTION_KINDS:
        raise ConfigError(f'bad anomaly {spec!r}: kind must be one of '
                          f'{", ".join(FRICTION_KINDS)}, got {kind!r}')
    if len(parts) != (5 if kind == 'both' else 4):
        raise ConfigError(f'bad anomaly {spec!r}: {usage}')
    try:
        numbers = [float(p) for p in parts[2:]]
    except ValueError:
        raise ConfigError(f'bad anomaly {spec!r}: time and sizes must be numbers') from None
    if not all(math.isfinite(x) for x in numbers) or numbers[0] < 0:
        raise ConfigError(f'bad anomaly {spec!r}: time must be >= 0 and sizes finite')
    time_s, sizes = numbers[0], numbers[1:]
    if kind == 'dry':
        return Anomaly(wheel, kind, time_s, delta_dry=sizes[0])
    if kind == 'viscous':
        return Anomaly(wheel, kind, time_s, delta_viscous=sizes[0])
    return Anomaly(wheel, kind, time_s, delta_dry=sizes[0], delta_viscous=sizes[1])


def _wheel_ids(wheels: Sequence[str] | None, n_wheels: int | None) -> tuple[str, ...]:
    if wheels is not None and n_wheels is not None:
        raise ValueError('give wheels or n_wheels, not both')
    if n_wheels is not None:
        return tuple(f'rw{i + 1}' for i in range(check_int('n_wheels', n_wheels, 1, 64)))
    ids = tuple(DEFAULT_WHEELS if wheels is None else wheels)
    if not ids or len(set(ids)) != len(ids) or not all(isinstance(w, str) and w for w in ids):
        raise ValueError(f'wheels must be distinct non-empty names, got {ids!r}')
    return ids


def simulate_friction_with_truth(
        *, wheels: Sequence[str] | None = None, n_wheels: int | None = None,
        duration_s: float | None = None, n_samples: int | None = None,
        rate_hz: float = 10.0, profile: str = 'realistic', units: str = 'si',
        dry_nm: float | None = None, viscous_nms: float | None = None,
        noise_std_nm: float | None = None, anomalies: Iterable[Anomaly] = (),
        seed: int = 0) -> tuple[Telemetry, list[Change]]:
    """Return (telemetry, injected changes) of model (1) for every wheel.

    Length: ``duration_s`` (samples at times k / rate_hz, k = 0 .. floor(duration_s *
    rate_hz) - 1) or ``n_samples``. Nominal parameters default to the ``units`` regime.
    An anomaly applies from the first sample with time >= its time_s; steps add up.
    Wheel i draws its profile and noise from seeds (seed, i, 0) and (seed, i, 1), so a
    wheel's data do not depend on how many wheels there are.
    Truth columns per wheel: ``<id>_dry``, ``<id>_viscous`` (per sample) and
    ``<id>_noise_std``.
    """
    ids = _wheel_ids(wheels, n_wheels)
    rate_hz = check_real('rate_hz', rate_hz, 0.0, 1e6, low_open=True)
    check_choice('profile', profile, PROFILES)
    regime = REGIMES[check_choice('units', units, tuple(REGIMES))]
    if (duration_s is None) == (n_samples is None):
        raise ValueError('give exactly one of duration_s and n_samples')
    if n_samples is None:
        duration_s = check_real('duration_s', duration_s, 0.0, 1e9, low_open=True)
        n_samples = int(math.floor(duration_s * rate_hz + 1e-9))
    n = check_int('n_samples', n_samples, 1, 10**9)
    dry = check_real('dry_nm', regime['dry_nm'] if dry_nm is None else dry_nm, 0.0)
    visc = check_real('viscous_nms',
                      regime['viscous_nms'] if viscous_nms is None else viscous_nms, 0.0)
    noise = check_real('noise_std_nm', regime['noise_std_nm'] if noise_std_nm is None
                       else noise_std_nm, 0.0)
    time = np.arange(n, dtype=float) / rate_hz
    changes = _place(list(anomalies), ids, time)
    tele = Telemetry(time=time)
    for i, wheel_id in enumerate(ids):
        profile_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(i, 0)))
        noise_rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(i, 1)))
        speed = spin_profile(profile, n, rate_hz=rate_hz, wheel_index=i, rng=profile_rng)
        dry_k = np.full(n, dry)
        visc_k = np.full(n, visc)
        for change in changes:
            if change.wheel == wheel_id:
                dry_k[change.index:] += change.delta_dry
                visc_k[change.index:] += change.delta_viscous
        friction = -dry_k * np.sign(speed) - visc_k * speed
        if noise > 0:
            friction += noise_rng.normal(0.0, noise, n)
        tele.wheels[wheel_id] = Wheel(speed=speed, friction=friction)
        tele.truth[f'{wheel_id}_dry'] = dry_k
        tele.truth[f'{wheel_id}_viscous'] = visc_k
        tele.truth[f'{wheel_id}_noise_std'] = np.full(n, noise)
    return tele, changes


def simulate_friction(**kwargs) -> Telemetry:
    """Return the telemetry of :func:`simulate_friction_with_truth` (same keywords)."""
    return simulate_friction_with_truth(**kwargs)[0]


def _place(anomalies: list[Anomaly], ids: tuple[str, ...], time: np.ndarray) -> list[Change]:
    changes = []
    for a in anomalies:
        if a.wheel not in ids:
            raise ValueError(f'anomaly on unknown wheel {a.wheel!r}; wheels: {", ".join(ids)}')
        check_choice('anomaly kind', a.kind, FRICTION_KINDS)
        check_real('anomaly time_s', a.time_s, 0.0, float(time[-1]))
        index = int(np.searchsorted(time, a.time_s - 1e-9, side='left'))
        changes.append(Change(a.wheel, a.kind, index, float(time[index]),
                              check_real('anomaly delta_dry', a.delta_dry),
                              check_real('anomaly delta_viscous', a.delta_viscous)))
    return sorted(changes, key=lambda c: (c.index, c.wheel))


def changes_from_truth(tele: Telemetry) -> list[Change]:
    """Recover the injected changes from a record's ``<id>_dry``/``<id>_viscous`` truth."""
    changes = []
    for wheel_id in tele.wheels:
        dry = tele.truth.get(f'{wheel_id}_dry')
        visc = tele.truth.get(f'{wheel_id}_viscous')
        if dry is None or visc is None:
            continue
        d_dry, d_visc = np.diff(dry), np.diff(visc)
        for j in np.flatnonzero((d_dry != 0) | (d_visc != 0)):
            kind = ('both' if d_dry[j] and d_visc[j] else 'dry' if d_dry[j] else 'viscous')
            changes.append(Change(wheel_id, kind, int(j + 1), float(tele.time[j + 1]),
                                  float(d_dry[j]), float(d_visc[j])))
    return sorted(changes, key=lambda c: (c.index, c.wheel))
