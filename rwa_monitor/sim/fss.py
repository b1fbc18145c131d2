"""Friction switching system telemetry: eq. (4)-(8) of the physics-informed FSS paper.

Per wheel, in the paper's normalised units (speed / SPEED_SCALE_RAD_S, torque /
TORQUE_SCALE_NM, both of order one): f_k = f^d_k sign(w_k) + f^v w_k + v_k (eq. 4a),
f^d_k = base dry + sum of the FSS levels (eq. 4b), each FSS a semi-Markov chain
(:mod:`rwa_monitor.core.fss.model`, Examples 1 and 2). The telemetry is written in SI
units with the project's sign, friction torque = -f^d sign(w) - f^v w + noise.

Statuses (docs/simulators.md, "FSS"): ``nominal`` and one anomaly at a time, ``dry``
(base dry friction up), ``viscous`` (viscous coefficient up), ``fss1`` and ``fss2``
(that system's friction-level distribution changed, eq. 9b). Anomaly sizes
(``anomalies``): ``realistic`` (default) multiplies the wheel's own nominal quantity by a
factor ``size`` in ANOMALY_SIZE (x1.1 to x3, docs/fss.md); ``legacy`` is the first
bench's fixed ranges, 2.5-3x away from nominal, reproduced draw for draw from the same
seeds. A labelled data set is a directory of windows (``.npz``, each with a nominal
window of the same wheel for its commissioning reference) and a ``manifest.json``.
"""

from __future__ import annotations

import json
import os
import pathlib
from typing import Sequence

import numpy as np

from rwa_monitor.core.fss.model import DEFAULT_SYSTEMS, SwitchingSystem
from rwa_monitor.core.params import check_choice, check_int, check_real
from rwa_monitor.telemetry import Telemetry, Wheel
from rwa_monitor.telemetry.atomic import atomic_write, write_text_atomic

STATUSES = ('nominal', 'dry', 'viscous', 'fss1', 'fss2')
TORQUE_SCALE_NM = 2.0e-4       # one normalised torque unit (the nominal base dry friction)
SPEED_SCALE_RAD_S = 400.0      # one normalised speed unit
RATE_HZ = 10.0
WINDOW_SAMPLES = 80_000        # ~2.2 h at 10 Hz: the paper's window size
BURN_IN = 60_000               # steps simulated before the window: FSS states at random

# Nominal parameters, normalised, drawn per window (uniform ranges).
NOMINAL_BASE_DRY = (0.9, 1.1)
NOMINAL_VISCOUS = (0.9, 1.1)
NOISE_STD = (0.02, 0.03)       # the paper's Fig. 9: |error| > 0.08 at 1e-3 -> sigma ~ 0.025
# Realistic anomalies: factor on the wheel's own nominal (base dry, viscous, FSS-1 active
# level, FSS-2 level step), drawn uniformly unless given.
ANOMALY_SIZE = (1.1, 3.0)
ANOMALY_MODES = ('realistic', 'legacy')
# Legacy anomalies (the first bench; docs/fss.md explains the magnitudes).
ANOMALY_BASE_DRY = (2.5, 3.0)
ANOMALY_VISCOUS = (1.3, 1.6)
ANOMALY_FSS1_LEVELS = ((0.0, 0.1), (0.42, 0.55))
ANOMALY_FSS2_LEVELS = ((0.0, 0.2), (1.1, 1.3), (2.2, 2.4))


def systems_for(status: str,
                systems: Sequence[SwitchingSystem] = DEFAULT_SYSTEMS,
                size: float | None = None) -> tuple[SwitchingSystem, ...]:
    """Return the switching systems of a wheel with ``status`` (eq. 9b for fss1/fss2).

    ``size`` None: the legacy anomalous levels. Else the factor on the nominal levels:
    FSS 1's active level range times ``size``; FSS 2's configuration q level range
    shifted from 0.5 q to 0.5 q ``size`` (every cage step ``size`` times larger).
    """
    check_choice('status', status, STATUSES)
    out = list(systems)
    if status == 'fss1':
        if size is None:
            out[0] = out[0].with_levels(ANOMALY_FSS1_LEVELS)
        else:
            low = out[0].levels[0]
            out[0] = out[0].with_levels((low,) + tuple(
                (lo * size, hi * size) for lo, hi in out[0].levels[1:]))
    elif status == 'fss2':
        if size is None:
            out[1] = out[1].with_levels(ANOMALY_FSS2_LEVELS)
        else:
            floor = out[1].levels[0][0]
            out[1] = out[1].with_levels(tuple(
                (lo + (size - 1.0) * (lo - floor), hi + (size - 1.0) * (lo - floor))
                for lo, hi in out[1].levels))
    return tuple(out)


def simulate_switching(system: SwitchingSystem, n: int, rng: np.random.Generator,
                       burn_in: int = BURN_IN) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return (level, configuration, jumped) over n steps of one FSS, eq. (5)-(6).

    The chain starts ``burn_in`` steps before the window in a uniformly drawn
    configuration, so the window begins in a random state and sojourn phase. Drawing
    whole residence times is equivalent to the hazard form P^t(q, tau) of the examples.
    """
    starts, configs, levels = [], [], []
    t = -int(burn_in)
    q = int(rng.integers(system.n_config))
    while t < n:
        starts.append(t)
        configs.append(q)
        levels.append(rng.uniform(*system.levels[q]))
        t += system.sample_residence(q, rng)
        q = system.sample_next(q, rng)
    bounds = np.clip(np.append(starts, n), 0, n)
    counts = np.diff(bounds)
    level = np.repeat(np.asarray(levels), counts)
    config = np.repeat(np.asarray(configs), counts)
    jumped = np.zeros(n, dtype=bool)
    inside = np.asarray(starts[1:])
    jumped[inside[(inside > 0) & (inside < n)]] = True
    return level, config, jumped


def fallback_profile(n: int, rng: np.random.Generator, rate_hz: float) -> np.ndarray:
    """Return a normalised spin rate: holds and slews around a bias, an orbital drift."""
    t = np.arange(n) / rate_hz
    knots_t, knots_w = [0.0], [rng.uniform(0.4, 1.2)]
    while knots_t[-1] <= t[-1]:
        knots_t += [knots_t[-1] + rng.uniform(60.0, 900.0)]
        knots_w += [knots_w[-1]]
        target = float(np.clip(knots_w[-1] + rng.normal(0.0, 0.4), 0.2, 1.4))
        knots_t += [knots_t[-1] + abs(target - knots_w[-1]) / rng.uniform(2e-3, 2e-2) + 1e-3]
        knots_w += [target]
    phase = rng.uniform(0.0, 2.0 * np.pi)
    return np.interp(t, knots_t, knots_w) + 0.04 * np.sin(2 * np.pi * t / 5700.0 + phase)


def spin_profile(n: int, rng: np.random.Generator, rate_hz: float = RATE_HZ,
                 kind: str = 'realistic') -> np.ndarray:
    """Return a normalised spin-rate profile.

    ``realistic`` (the shared operational profile, with zero crossings), ``biased``
    (holds and slews that never cross zero) or ``constant``.
    """
    check_choice('profile', kind, ('realistic', 'biased', 'constant'))
    if kind == 'constant':
        return np.full(n, 0.8)
    if kind == 'realistic':
        try:
            from rwa_monitor.sim.profiles import realistic_profile
        except ImportError:  # the shared profile module is optional
            realistic_profile = None
        if realistic_profile is not None:
            return realistic_profile(np.arange(n) / rate_hz, rng) / SPEED_SCALE_RAD_S
    return fallback_profile(n, rng, rate_hz)


def simulate_wheel(n: int, status: str, rng: np.random.Generator, *,
                   systems: Sequence[SwitchingSystem] = DEFAULT_SYSTEMS,
                   profile: str = 'realistic', rate_hz: float = RATE_HZ,
                   anomalies: str = 'realistic', size: float | None = None,
                   wheel: dict | None = None) -> dict:
    """Return one wheel's normalised signals and truth, paper sign (eq. 4a-4b).

    Keys: ``speed``, ``friction`` (f_k, positive opposes motion), ``base_dry``,
    ``viscous``, ``noise_std``, ``dry`` (f^d_k), per system ``levels`` / ``configs``
    (n x S), ``jump`` (1-based index of the system that jumped at k, 0 if none),
    ``size`` (the anomaly factor, None for legacy or nominal), ``nominal`` (the wheel's
    nominal base dry, viscous and noise std). ``anomalies='realistic'``: the wheel's
    nominal is drawn (or given as ``wheel``, a ``nominal`` dict) and the anomaly
    multiplies it by ``size`` (drawn in ANOMALY_SIZE when None). ``'legacy'``: the
    first bench's draws, unchanged.
    """
    check_choice('status', status, STATUSES)
    check_choice('anomalies', anomalies, ANOMALY_MODES)
    n = check_int('n', n, 1)
    if anomalies == 'legacy':
        sys_used = systems_for(status, systems)
        base = rng.uniform(*(ANOMALY_BASE_DRY if status == 'dry' else NOMINAL_BASE_DRY))
        visc = rng.uniform(*(ANOMALY_VISCOUS if status == 'viscous' else NOMINAL_VISCOUS))
        noise = rng.uniform(*NOISE_STD)
        nominal = None
    else:
        if wheel is None:
            nominal = {'base_dry': rng.uniform(*NOMINAL_BASE_DRY),
                       'viscous': rng.uniform(*NOMINAL_VISCOUS),
                       'noise_std': rng.uniform(*NOISE_STD)}
        else:
            nominal = {k: float(wheel[k]) for k in ('base_dry', 'viscous', 'noise_std')}
        if status != 'nominal' and size is None:
            size = float(rng.uniform(*ANOMALY_SIZE))
        if status != 'nominal':
            size = check_real('size', size, 1.0)
        sys_used = systems_for(status, systems, size)
        base = nominal['base_dry'] * (size if status == 'dry' else 1.0)
        visc = nominal['viscous'] * (size if status == 'viscous' else 1.0)
        noise = nominal['noise_std']
    levels = np.empty((n, len(sys_used)))
    configs = np.empty((n, len(sys_used)), dtype=int)
    jump = np.zeros(n, dtype=int)
    for s, system in enumerate(sys_used):
        levels[:, s], configs[:, s], jumped = simulate_switching(system, n, rng)
        jump[jumped & (jump == 0)] = s + 1
    speed = spin_profile(n, rng, rate_hz, profile)
    dry = base + levels.sum(axis=1)
    friction = dry * np.sign(speed) + visc * speed + rng.normal(0.0, noise, n)
    return {'speed': speed, 'friction': friction, 'base_dry': base, 'viscous': visc,
            'noise_std': noise, 'dry': dry, 'levels': levels, 'configs': configs,
            'jump': jump, 'status': status, 'size': size if status != 'nominal' else None,
            'nominal': nominal}


def to_si(speed: np.ndarray, friction: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Return (rad/s, N m in the project's sign) from normalised paper-sign signals."""
    return speed * SPEED_SCALE_RAD_S, -friction * TORQUE_SCALE_NM


def simulate_fss(*, statuses: Sequence[str] = ('nominal',) * 4,
                 wheels: Sequence[str] | None = None, n_samples: int = WINDOW_SAMPLES,
                 rate_hz: float = RATE_HZ, profile: str = 'realistic',
                 seed: int = 0, anomalies: str = 'realistic',
                 size: float | None = None) -> Telemetry:
    """Return telemetry of one wheel per status, with truth columns (SI units).

    Wheel i draws from the seed sequence (seed, i). Truth per wheel ``<id>``:
    ``<id>_dry`` (N m), ``<id>_viscous`` (N m s/rad), ``<id>_noise_std`` (N m),
    ``<id>_base_dry`` (N m), ``<id>_fss<s>`` (level, N m) and ``<id>_fss<s>_q``,
    ``<id>_jump`` (which FSS jumped at the sample, 0 none) and ``<id>_status``
    (index into STATUSES). ``anomalies`` and ``size``: as :func:`simulate_wheel`.
    """
    for status in statuses:
        check_choice('status', status, STATUSES)
    n = check_int('n_samples', n_samples, 1, 10**8)
    rate_hz = check_real('rate_hz', rate_hz, 0.0, 1e6, low_open=True)
    ids = list(wheels) if wheels is not None else [f'rw{i + 1}' for i in range(len(statuses))]
    if len(ids) != len(statuses):
        raise ValueError('wheels and statuses must have the same length')
    tele = Telemetry(time=np.arange(n) / rate_hz)
    for i, (wheel_id, status) in enumerate(zip(ids, statuses)):
        rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(i,)))
        sig = simulate_wheel(n, status, rng, profile=profile, rate_hz=rate_hz,
                             anomalies=anomalies, size=size)
        speed, friction = to_si(sig['speed'], sig['friction'])
        tele.wheels[wheel_id] = Wheel(speed=speed, friction=friction)
        truth = {'dry': sig['dry'] * TORQUE_SCALE_NM,
                 'viscous': np.full(n, sig['viscous'] * TORQUE_SCALE_NM / SPEED_SCALE_RAD_S),
                 'noise_std': np.full(n, sig['noise_std'] * TORQUE_SCALE_NM),
                 'base_dry': np.full(n, sig['base_dry'] * TORQUE_SCALE_NM),
                 'jump': sig['jump'].astype(float),
                 'status': np.full(n, float(STATUSES.index(status)))}
        for s in range(sig['levels'].shape[1]):
            truth[f'fss{s + 1}'] = sig['levels'][:, s] * TORQUE_SCALE_NM
            truth[f'fss{s + 1}_q'] = sig['configs'][:, s].astype(float)
        for key, value in truth.items():
            tele.truth[f'{wheel_id}_{key}'] = value
    return tele


def build_dataset(out_dir: str | os.PathLike, *, per_status: int = 50, seed: int = 0,
                  n_samples: int = WINDOW_SAMPLES, profile: str = 'realistic',
                  anomalies: str = 'realistic', statuses: Sequence[str] = STATUSES,
                  sizes: Sequence[float] | None = None) -> dict:
    """Write a labelled data set: ``per_status`` windows of each status, and a manifest.

    Window j of status s is drawn from the seed sequence (seed, s, j), so any window can
    be regenerated alone (``legacy`` data sets are the first bench's, window for window).
    Files hold normalised float32 ``speed`` and ``friction`` (paper sign) and the truth;
    with ``realistic`` anomalies also ``ref_speed`` / ``ref_friction``, a nominal window
    of the same wheel (seed sequence (seed, s, j, 1)): its commissioning reference.
    ``sizes``: the anomaly factors to cycle through (window j gets sizes[j % len]);
    None draws them in ANOMALY_SIZE. ``manifest.json`` lists the windows with their
    labels and parameters.
    """
    per_status = check_int('per_status', per_status, 1, 100_000)
    n = check_int('n_samples', n_samples, 100, 10**7)
    check_choice('anomalies', anomalies, ANOMALY_MODES)
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    entries = []
    for status in statuses:
        s_idx = STATUSES.index(check_choice('status', status, STATUSES))
        for j in range(per_status):
            rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(s_idx, j)))
            size = None if sizes is None or status == 'nominal' else float(
                sizes[j % len(sizes)])
            sig = simulate_wheel(n, status, rng, profile=profile, anomalies=anomalies,
                                 size=size)
            arrays = {'speed': sig['speed'].astype(np.float32),
                      'friction': sig['friction'].astype(np.float32),
                      'jump': sig['jump'].astype(np.int8)}
            if sig['nominal'] is not None:
                ref_rng = np.random.default_rng(np.random.SeedSequence(
                    seed, spawn_key=(s_idx, j, 1)))
                ref = simulate_wheel(n, 'nominal', ref_rng, profile=profile,
                                     wheel=sig['nominal'])
                arrays.update(ref_speed=ref['speed'].astype(np.float32),
                              ref_friction=ref['friction'].astype(np.float32))
            name = f'{status}_{j:04d}.npz'
            with atomic_write(out / name, 'wb', encoding=None) as handle:
                np.savez(handle, **arrays)
            entries.append({'file': name, 'status': status, 'seed': [seed, s_idx, j],
                            'base_dry': sig['base_dry'], 'viscous': sig['viscous'],
                            'noise_std': sig['noise_std'], 'size': sig['size'],
                            'nominal': sig['nominal'],
                            'n_jumps': int(np.count_nonzero(sig['jump']))})
    manifest = {'kind': 'fss-dataset', 'version': 2, 'seed': seed, 'per_status': per_status,
                'n_samples': n, 'rate_hz': RATE_HZ, 'profile': profile,
                'anomalies': anomalies, 'sizes': None if sizes is None else list(sizes),
                'statuses': list(statuses), 'units': 'normalised, paper sign',
                'torque_scale_nm': TORQUE_SCALE_NM, 'speed_scale_rad_s': SPEED_SCALE_RAD_S,
                'windows': entries}
    write_text_atomic(out / 'manifest.json', json.dumps(manifest, indent=1) + '\n')
    return manifest


def load_manifest(path: str | os.PathLike) -> dict:
    """Return the manifest of a data set directory (ValueError if it is not one)."""
    file = pathlib.Path(path) / 'manifest.json'
    if not file.is_file():
        raise ValueError(f'{path}: not an FSS data set (no manifest.json)')
    manifest = json.loads(file.read_text())
    if manifest.get('kind') != 'fss-dataset':
        raise ValueError(f'{file}: not an FSS data set manifest')
    return manifest


def load_window(path: str | os.PathLike, entry: dict, reference: bool = False
                ) -> tuple[np.ndarray, np.ndarray]:
    """Return (speed, friction) of one data-set window, normalised, paper sign.

    ``reference``: the window's nominal reference window instead (ValueError if the
    data set has none, i.e. legacy anomalies).
    """
    with np.load(pathlib.Path(path) / entry['file']) as data:
        if not reference:
            return data['speed'].astype(float), data['friction'].astype(float)
        if 'ref_speed' not in data:
            raise ValueError(f'{entry["file"]}: no reference window (legacy data set)')
        return data['ref_speed'].astype(float), data['ref_friction'].astype(float)


def extraction_item(speed: np.ndarray, friction: np.ndarray, config) -> dict:
    from rwa_monitor.core.fss.baseline import ls_summary
    from rwa_monitor.core.fss.pipeline import extract
    ext = extract(speed, friction, config)
    return {'features': ext.features(), 'identifiable': ext.identifiable,
            'ls': ls_summary(speed, friction, ext.accepted, dk_error=config.dk_error,
                             viscous_prior=config.viscous_prior),
            'stats': {'detected': int(ext.detected.size), 'rejected': ext.rejected,
                      'accepted': int(ext.accepted.size), 'iterations': ext.iterations,
                      'exact': ext.exact, 'rmse': ext.rmse, 'sigma': ext.sigma,
                      'viscous_se': ext.viscous_se,
                      'timings': ext.timings}}


def dataset_extractions(path: str | os.PathLike, config=None, *, cache: bool = True,
                        progress=None) -> list[dict]:
    """Return stages 1-3 of every window of a data set, cached in ``extractions.json``.

    Each item: ``file``, ``status``, ``size``, ``features`` (classifier input),
    ``identifiable``, ``ls`` (the baseline's least-squares estimates, core/fss/baseline.py)
    and ``stats`` (changepoints detected, rejected, DP iterations, exactness, stage times
    in s); with realistic anomalies also ``reference``, the same for the window's nominal
    reference window. The cache is reused only when it was made with the same diagnoser
    parameters, switching laws and code.
    """
    from dataclasses import asdict

    from rwa_monitor.core.fss.pipeline import FssConfig
    config = FssConfig() if config is None else config
    path = pathlib.Path(path)
    manifest = load_manifest(path)
    import hashlib

    from rwa_monitor.core import fss as core_fss
    code = hashlib.sha256(b''.join(p.read_bytes() for p in sorted(
        pathlib.Path(core_fss.__file__).parent.glob('*.py')))).hexdigest()
    signature = json.dumps({k: v for k, v in asdict(config).items() if k != 'systems'},
                           sort_keys=True) + repr(config.systems) + code
    cache_file = path / 'extractions.json'
    if cache and cache_file.is_file():
        cached = json.loads(cache_file.read_text())
        if cached.get('signature') == signature and len(cached['items']) == len(
                manifest['windows']):
            return cached['items']
    items = []
    for j, entry in enumerate(manifest['windows']):
        item = {'file': entry['file'], 'status': entry['status'], 'size': entry.get('size'),
                **extraction_item(*load_window(path, entry), config)}
        if entry.get('nominal') is not None:
            ref = extraction_item(*load_window(path, entry, reference=True), config)
            item['reference'] = {k: ref[k] for k in ('features', 'identifiable', 'ls')}
            item['reference']['sigma'] = ref['stats']['sigma']
        items.append(item)
        if progress is not None:
            progress(j + 1, len(manifest['windows']))
    if cache:
        write_text_atomic(cache_file, json.dumps({'signature': signature,
                                                  'items': items}) + '\n')
    return items
