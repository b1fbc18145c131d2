"""The measured coast-down folder (drum-coastdown): per-revolution coasts and inertias.

Reads ``derived/coast_per_rev.csv`` (run, body, direction, t_s, omega_rad_s) in place,
one run and body at a time, into an in-memory Telemetry record with a speed column only,
and the body's moment of inertia from the folder's pendulum swings. Nothing is copied or
written. Used by ``rwa-monitor identify --format coastdown`` and the identify benchmark.
"""

from __future__ import annotations

import csv
import math
import os
import pathlib

import numpy as np

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.telemetry.schema import Telemetry, Wheel

GRAVITY = 9.81
# Body -> (wheelInfo.csv name, pendulum file) of the coast-down folder.
PENDULUM = {'drum': ('Drum', 'inertia/Drum_I1.csv'),
            'wheel': ('Vittoria Corsa Open', 'inertia/Vittoria_Corsa_Open_I1.csv')}


def coastdown_folder(path: os.PathLike) -> pathlib.Path:
    """Return the coast-down data folder of ``path`` (the folder or its per-rev CSV)."""
    path = pathlib.Path(path)
    folder = path if path.is_dir() else path.parent.parent
    if not (folder / 'derived' / 'coast_per_rev.csv').exists():
        raise TelemetrySchemaError(str(path), 'not a coast-down folder or its '
                                   'derived/coast_per_rev.csv')
    return folder


def _rows(path: os.PathLike) -> list[dict]:
    csv_path = coastdown_folder(path) / 'derived' / 'coast_per_rev.csv'
    with open(csv_path, newline='') as handle:
        return list(csv.DictReader(handle))


def coastdown_runs(path: os.PathLike) -> list[tuple[str, str, int]]:
    """Return (run, body, samples) of every coast in the per-revolution file."""
    counts: dict[tuple[str, str], int] = {}
    for row in _rows(path):
        key = (row['run'], row['body'])
        counts[key] = counts.get(key, 0) + 1
    return [(r, b, n) for (r, b), n in counts.items()]


def read_coastdown(path: os.PathLike, run: str, body: str = 'drum') -> Telemetry:
    """Return one coast (run, body) as an in-memory record: time and <body>_speed only."""
    rows = [r for r in _rows(path) if r['run'] == run and r['body'] == body]
    if not rows:
        raise TelemetrySchemaError(str(path), f'no coast for run {run!r} and body {body!r} '
                                   f'(see --run list)')
    time = np.array([float(r['t_s']) for r in rows])
    speed = np.array([float(r['omega_rad_s']) for r in rows])
    order = np.argsort(time)
    return Telemetry(time=time[order], wheels={body: Wheel(speed=speed[order])},
                     source=f'{path}:{run}:{body}')


def pendulum_inertia(folder: os.PathLike, body: str = 'drum') -> float:
    """Return the body's moment of inertia (kg m^2) from the folder's pendulum swings.

    A coin of mass m fixed at distance d from the axle turns the body into a physical
    pendulum of period T0 = 2 pi sqrt(I / (m g d)) at small amplitude, with
    I = J + m d^2, so J = m g d T0^2 / (4 pi^2) - m d^2. T is the median interval between
    successive passes in the pendulum file; the swing amplitude (theta_1 to theta_2 of
    wheelInfo.csv, their mean theta) lengthens the period by (1 + theta^2/16 +
    11 theta^4/3072), which is divided out.
    """
    folder = pathlib.Path(folder)
    name, swings = PENDULUM[body]
    with open(folder / 'wheelInfo.csv', newline='') as handle:
        info = next(r for r in csv.DictReader(handle) if r['name'] == name)
    with open(folder / swings, newline='') as handle:
        passes = np.array([float(r[0]) for r in csv.reader(handle) if r and r[0].strip()])
    period = float(np.median(np.diff(passes))) * 1e-6
    theta = math.radians(0.5 * (float(info['theta_1']) + float(info['theta_2'])))
    period0 = period / (1.0 + theta ** 2 / 16.0 + 11.0 * theta ** 4 / 3072.0)
    mass, dist = float(info['m_coin']), float(info['d_coin'])
    return mass * GRAVITY * dist * period0 ** 2 / (4.0 * math.pi ** 2) - mass * dist ** 2
