"""Small fleet archives for the fleet tests: one simulated record cut into passes.

Each spacecraft's record is written once as CSV and read back (so every value is what a
CSV pass holds), then cut into passes with gaps and one overlap, written as CSV or
Parquet under names whose order is not the time order. :func:`joined` is the same rows
as one file (the overlap once): ``rwa-monitor detect`` on it is the reference.
"""

from __future__ import annotations

import pathlib

import numpy as np
import yaml

from rwa_monitor.core.identify.model import plain
from rwa_monitor.pipelines import calibrated
from rwa_monitor.sim.aocs import add_gyro_channels, named_fault
from rwa_monitor.sim.friction import parse_anomaly, simulate_friction
from rwa_monitor.telemetry import read_telemetry, Telemetry, write_telemetry
from rwa_monitor.telemetry.parquet_io import write_parquet

RATE_HZ = 10.0
# (first row, end row, file name): out of name order, a gap, an overlap of 100 rows.
CUTS_A = [(0, 9000, 'pass_k.csv'), (8900, 20000, 'pass_b.parquet'),
          (23000, 32000, 'pass_z.csv'), (32000, 45000, 'pass_a.parquet')]
CUTS_B = [(0, 12000, 'zz.csv'), (15000, 27000, 'aa.csv'), (27000, 40000, 'mm.parquet')]


def rows(tele: Telemetry, first: int, end: int) -> Telemetry:
    """Return rows ``first:end`` of a single-rate record."""
    cols = {k: v[first:end] for k, v in tele.columns().items()}
    return Telemetry.from_columns(cols)


def as_read(tele: Telemetry, tmp: pathlib.Path) -> Telemetry:
    """Return the record as a CSV file holds it (values rounded as written)."""
    path = tmp / 'whole.csv'
    write_telemetry(path, tele)
    out = read_telemetry(path)
    path.unlink()
    return out


def write_passes(folder: pathlib.Path, tele: Telemetry, cuts: list) -> None:
    """Write the passes of ``cuts`` into ``folder``."""
    folder.mkdir(parents=True, exist_ok=True)
    for first, end, name in cuts:
        part = rows(tele, first, end)
        if name.endswith('.parquet'):
            write_parquet(folder / name, part)
        else:
            write_telemetry(folder / name, part)


def joined(tele: Telemetry, cuts: list, path: pathlib.Path) -> pathlib.Path:
    """Write the rows of every pass once, in time order, as one CSV file."""
    keep = np.unique(np.concatenate([np.arange(a, b) for a, b, _ in cuts]))
    cols = {k: v[keep] for k, v in tele.columns().items()}
    write_telemetry(path, Telemetry.from_columns(cols))
    return path


def spacecraft_a(tmp: pathlib.Path) -> Telemetry:
    """Two wheels (dry step on rw2) and the gyro (a drift on y), not calibrated."""
    tele = simulate_friction(duration_s=4500, rate_hz=RATE_HZ, wheels=('rw1', 'rw2'),
                             anomalies=[parse_anomaly('rw2:dry:2600:3e-4')], seed=11)
    tele = add_gyro_channels(tele, fault=named_fault('fast', 1, 2800.0), seed=12)
    return as_read(tele, tmp)


def spacecraft_b(tmp: pathlib.Path, folder: pathlib.Path) -> Telemetry:
    """Two calibrated wheels (viscous step on rw1); writes folder/calibration.yaml."""
    healthy = simulate_friction(duration_s=2500, rate_hz=RATE_HZ, wheels=('rw1', 'rw2'),
                                seed=21)
    document, _, _ = calibrated.commission([as_read(healthy, tmp)])
    folder.mkdir(parents=True, exist_ok=True)
    (folder / 'calibration.yaml').write_text(yaml.safe_dump(plain(document),
                                                            sort_keys=False))
    tele = simulate_friction(duration_s=4000, rate_hz=RATE_HZ, wheels=('rw1', 'rw2'),
                             anomalies=[parse_anomaly('rw1:viscous:2000:1.5e-6')], seed=22)
    return as_read(tele, tmp)


def make_archive(root: pathlib.Path, work: pathlib.Path) -> dict[str, pathlib.Path]:
    """Write the two-spacecraft archive; return spacecraft -> its joined reference file."""
    work.mkdir(parents=True, exist_ok=True)
    a = spacecraft_a(work)
    write_passes(root / 'sat-a', a, CUTS_A)
    b = spacecraft_b(work, root / 'sat-b')
    write_passes(root / 'sat-b', b, CUTS_B)
    return {'sat-a': joined(a, CUTS_A, work / 'sat-a.csv'),
            'sat-b': joined(b, CUTS_B, work / 'sat-b.csv')}


def detect_events(path: pathlib.Path, calibration: pathlib.Path | None = None,
                  config: pathlib.Path | None = None) -> list[dict]:
    """Return the events of ``rwa-monitor detect`` on one file.

    ``config`` None: the fleet's own parameters (config/fleet.yaml), which ``fleet`` reads
    without ``--config``: the engine equals ``detect`` given the same parameters.
    """
    import json

    from rwa_monitor.cli.main import main
    from rwa_monitor.fleet.engine import fleet_parameters_file
    out = path.with_suffix('.events.json')
    args = ['detect', str(path), '-o', str(out),
            '--config', str(config or fleet_parameters_file())]
    if calibration is not None:
        args += ['--calibration', str(calibration)]
    assert main(args) in (0, 1, 3)
    return json.loads(out.read_text())['events']


def events_of(result, spacecraft: str) -> list[dict]:
    """Return a spacecraft's current events of a fleet result (detect's JSON fields)."""
    from rwa_monitor.fleet import history
    return [h.event.to_json() for h in history.current(result.history)
            if h.spacecraft == spacecraft]


def references(archive: pathlib.Path, joined_files: dict[str, pathlib.Path]
               ) -> dict[str, list[dict]]:
    """Return spacecraft -> events of detect on its joined file (with its calibration)."""
    out = {}
    for craft, path in joined_files.items():
        cal = archive / craft / 'calibration.yaml'
        out[craft] = detect_events(path, cal if cal.exists() else None)
    return out


def joined_from_files(paths: list[pathlib.Path], target: pathlib.Path) -> pathlib.Path:
    """Join pass files (in time order) as read back, overlap once, into one Parquet file."""
    parts = []
    last = -np.inf
    for path in paths:
        cols = read_telemetry(path).columns()
        keep = cols['time'] > last
        parts.append({k: v[keep] for k, v in cols.items()})
        last = max(last, cols['time'][-1])
    joined = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    write_parquet(target, Telemetry.from_columns(joined))
    return target
