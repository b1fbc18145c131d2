"""rwa-monitor fleet: events equal detect on the joined passes; bad passes; outputs.

The archive (test/fleet_archive.py) holds two spacecraft whose passes are cut from one
simulated record each, written under names out of time order, with gaps and an overlap,
one spacecraft calibrated. The reference is ``rwa-monitor detect`` on the same rows as
one file. The engine runs on a local Dask cluster of 2 worker processes. Daily runs
(``--state``) are in test/test_fleet_history.py, the state folder in
test/test_fleet_state.py.
"""

import json
import math
import shutil

from distributed import Client, LocalCluster
from fleet_archive import (as_read, CUTS_A, CUTS_B, detect_events, events_of, joined,
                           joined_from_files, make_archive, references, rows, write_passes)
import numpy as np
import pyarrow.parquet as pq
import pytest
import yaml

from rwa_monitor.cli.main import main
from rwa_monitor.core.identify.model import plain
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet.engine import run_archive
from rwa_monitor.pipelines import calibrated
from rwa_monitor.sim.aocs import add_gyro_channels, named_fault
from rwa_monitor.sim.friction import parse_anomaly, simulate_friction
from rwa_monitor.telemetry import write_telemetry
from rwa_monitor.telemetry.parquet_io import write_parquet


@pytest.fixture(scope='module')
def archive(tmp_path_factory):
    """Return (archive folder, spacecraft -> detect events, work folder)."""
    root = tmp_path_factory.mktemp('fleet')
    joined = make_archive(root / 'archive', root / 'work')
    return root / 'archive', references(root / 'archive', joined), root


@pytest.fixture(scope='module')
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        yield c


def test_events_equal_detect_on_joined_passes(archive, client, monkeypatch):
    from rwa_monitor.fleet import plan
    folder, reference, _ = archive
    # A scan task per 3 passes, their chunks across the spacecraft's boundary.
    monkeypatch.setattr(plan, 'SCAN_TASK_PASSES', 3)
    result = run_archive(folder, client=client, task_bytes=1)   # a task per pass
    monkeypatch.undo()
    assert len(client.scheduler_info()['workers']) == 2
    for craft, events in reference.items():
        assert events, 'the reference must find something for the test to mean anything'
        assert events_of(result, craft) == events
    grouped = run_archive(folder, client=client)            # all passes in one task
    assert [h.event.to_json() for h in grouped.history] == \
        [h.event.to_json() for h in result.history]
    assert grouped.summary['spacecraft'] == result.summary['spacecraft']
    assert [r.fields() for r in grouped.trend] == [r.fields() for r in result.trend] or \
        json.dumps([r.fields() for r in grouped.trend]) == json.dumps(
            [r.fields() for r in result.trend])               # NaN-safe
    summary = result.summary['spacecraft']
    # Time order by first stamp, never by name; the overlap of 100 rows dropped.
    assert summary['sat-a']['passes'] == [name for _, _, name in CUTS_A]
    assert summary['sat-b']['passes'] == [name for _, _, name in CUTS_B]
    assert summary['sat-a']['rows_dropped'] == 100
    assert summary['sat-a']['overlapping'] == {'pass_b.parquet': (
        '100 of 11100 rows stamped at or before the last one fed before it (it overlaps an '
        'earlier pass): not fed again')} and summary['sat-b']['overlapping'] == {}
    assert summary['sat-a']['components']['rw1']['samples'] == 42000
    assert set(summary['sat-a']['components']) == {'rw1', 'rw2', 'gyro'}
    assert summary['sat-b']['components']['rw1']['not_tested']['outside_calibrated_range'] > 0
    # sat-b rw1 runs mostly outside its calibrated range: unknown, as detect judges the
    # joined file (core/coverage.py; test_not_examined_follows_detect_coverage_rule).
    assert summary['sat-b']['components']['rw1']['verdict'] == 'unknown'
    assert list(summary['sat-b']['not_examined']) == ['rw1'] and not summary['sat-a'][
        'not_examined']
    assert summary['sat-a']['components']['rw2']['health'] == 'dry'
    assert summary['sat-a']['components']['rw1']['health'] == 'healthy'
    assert result.anomaly and result.incomplete
    workers = result.timings['per_worker']
    assert workers and all(w['peak_rss_mb'] > 0 for w in workers.values())
    trend = [r for r in result.trend if r.spacecraft == 'sat-b' and r.wheel == 'rw2']
    assert [r.pass_name for r in trend] == [name for _, _, name in CUTS_B]
    assert {r.relative_to for r in trend} == {'nominal'}


def test_cli_outputs_and_unreadable_pass(tmp_path):
    """A healthy spacecraft with broken passes: the rest runs, exit code 3."""
    craft = tmp_path / 'archive' / 'sat-c'
    craft.mkdir(parents=True)
    tele = simulate_friction(duration_s=600, rate_hz=10, wheels=('rw1',), seed=5)
    write_telemetry(craft / 'p2.csv', rows(tele, 3000, 6000))
    write_telemetry(craft / 'p1.csv', rows(tele, 0, 3000))
    broken = (craft / 'p1.csv').read_text().splitlines()
    broken[50] = broken[50].replace(',', ',x', 1)
    (craft / 'p0.csv').write_text('\n'.join(broken) + '\n')   # readable first row only
    (craft / 'notes.txt').write_text('not telemetry')
    (craft / 'p9.csv').write_bytes(b'\xff\xfe junk')
    (craft / 'p8.csv').write_text(broken[0] + '\n')              # header only
    import pyarrow as pa
    pq.write_table(pa.table({'time': pa.array([None] * 5, type=pa.float64()),
                             'rw1_speed': [1.0] * 5, 'rw1_friction': [0.0] * 5}),
                   craft / 'p7.parquet')                         # a time column all null
    (tmp_path / 'archive' / 'sat-empty').mkdir()
    broken_cal = tmp_path / 'archive' / 'sat-d'
    broken_cal.mkdir()
    shutil.copy(craft / 'p1.csv', broken_cal / 'p1.csv')
    (broken_cal / 'calibration.yaml').write_text('calibration: [not, a, mapping\n')
    out = tmp_path / 'out'
    code = main(['fleet', str(tmp_path / 'archive'), '-o', str(out), '--workers', '1'])
    assert code == 3
    whole = json.loads((out / 'summary.json').read_text())
    # Without --config: the fleet's own file, and the operating point it sets, said twice.
    assert whole['config'].endswith('fleet.yaml')
    assert whole['operating_point'] == {'false_alarm_rate': 3e-6, 'window': 500,
                                        'category_level': 1e-3}
    assert 'false-alarm rate r = 3e-06 per test' in (out / 'report.html').read_text()
    fleet = whole['spacecraft']
    assert 'no readable pass' in fleet['sat-empty']['not_examined']['spacecraft']
    assert 'calibration.yaml' in fleet['sat-d']['not_examined']['spacecraft']
    summary = fleet['sat-c']
    assert summary['not_examined']['pass p8.csv'].endswith('no rows')
    assert 'not a number' in summary['not_examined']['pass p0.csv']
    assert 'pass p9.csv' in summary['not_examined']
    assert 'first time is None' in summary['not_examined']['pass p7.parquet']
    assert summary['ignored'] == {'notes.txt': summary['ignored']['notes.txt']}
    assert summary['components']['rw1']['passes_this_run'] == 2
    assert summary['components']['rw1']['samples'] == 6000
    for name in ('events.json', 'events.parquet', 'summary.json', 'trend.parquet',
                 'report.html'):
        assert (out / name).stat().st_size > 0
    inside = tmp_path / 'archive' / 'out'
    assert main(['fleet', str(tmp_path / 'archive'), '-o', str(inside)]) == 2
    assert not inside.exists()
    for name in ('p0.csv', 'p7.parquet', 'p8.csv', 'p9.csv'):
        (craft / name).unlink()
    (tmp_path / 'archive' / 'sat-empty').rmdir()
    shutil.rmtree(broken_cal)
    # All examined, nothing found: 0 (seeded; a false alarm in these 6000 fault-free
    # samples has probability below 6000 x 1e-5 = 0.06 by the union bound).
    assert main(['fleet', str(tmp_path / 'archive'), '-o', str(out), '--workers', '1']) == 0
    # Outputs that cannot be written: exit 2 and the state does not move on.
    blocked, kept = tmp_path / 'blocked', tmp_path / 'state'
    blocked.write_text('a file, not a folder')
    assert main(['fleet', str(tmp_path / 'archive'), '-o', str(blocked), '--state',
                 str(kept), '--workers', '1']) == 2
    assert not (kept / 'current.json').exists()
    assert main(['fleet', str(tmp_path / 'archive'), '-o', str(out), '--state', str(kept),
                 '--workers', '1']) == 0
    assert (kept / 'current.json').exists()
    # --state inside -o, or -o inside --state: refused before anything is run.
    for state_dir, output in ((out / 'state', out), (kept, kept / 'out')):
        assert main(['fleet', str(tmp_path / 'archive'), '-o', str(output), '--state',
                     str(state_dir), '--workers', '1']) == 2


def test_output_folder_of_someone_else_is_refused(tmp_path, capsys):
    """An -o folder holding a user's events.json or report.html is never replaced."""
    craft = tmp_path / 'archive' / 'sat-c'
    craft.mkdir(parents=True)
    write_telemetry(craft / 'p1.csv', simulate_friction(duration_s=300, rate_hz=10,
                                                        wheels=('rw1',), seed=5))
    for name in ('events.json', 'report.html', 'notes.md'):
        out = tmp_path / f'out-{name}'
        out.mkdir()
        (out / name).write_text('mine')
        assert main(['fleet', str(tmp_path / 'archive'), '-o', str(out), '--workers',
                     '1']) == 2
        assert (out / name).read_text() == 'mine' and len(list(out.iterdir())) == 1
        assert 'not replacing' in capsys.readouterr().err


def test_outputs_have_every_event_field_and_utc_times(archive, client, tmp_path):
    from rwa_monitor.fleet.outputs import write_outputs
    folder, reference, _ = archive
    copy = tmp_path / 'archive'
    shutil.copytree(folder, copy)
    (copy / 'archive.yaml').write_text('epoch_utc: 2026-03-01T12:00:00Z\n')
    result = run_archive(copy, client=client)
    write_outputs(tmp_path / 'out', result)
    table = pq.read_table(tmp_path / 'out' / 'events.parquet').to_pylist()
    document = json.loads((tmp_path / 'out' / 'events.json').read_text())['events']
    assert len(table) == len(document) == sum(len(v) for v in reference.values())
    keys = set().union(*(e.keys() for v in reference.values() for e in v))
    assert keys <= set(table[0]) and {'final', 'final_samples', 'time_utc', 'new',
                                      'superseded'} <= set(table[0])
    first = min(document, key=lambda e: e['time'])
    assert first['time_utc'].startswith('2026-03-0') and first['time_utc'].endswith('Z')
    assert all(e['new'] and not e['superseded'] for e in document)
    summary = json.loads((tmp_path / 'out' / 'summary.json').read_text())
    assert summary['epoch_utc'] == '2026-03-01T12:00:00.000Z'
    page = (tmp_path / 'out' / 'report.html').read_text()
    assert 'UTC' in page and '<h2>Events</h2>' in page and 'Data from 2026-03-01' in page


def test_recording_passes_equal_detect(client, tmp_path):
    """Passes as a rosbag2 folder, a bare .mcap, a bare .db3 and a Parquet file."""
    tele = simulate_friction(duration_s=2400, rate_hz=10, wheels=('rw1', 'rw2'), seed=31,
                             anomalies=[parse_anomaly('rw1:dry:1300:3e-4')])
    craft = tmp_path / 'archive' / 'sat-r'
    craft.mkdir(parents=True)
    names = ['q_bag', 'c.mcap', 'x.db3', 'a.parquet']
    for (first, end), name in zip([(0, 6000), (7000, 13000), (12900, 18000),
                                   (19000, 24000)], names):
        target = craft / name
        part = rows(tele, first, end)
        if name.endswith('.parquet'):
            write_parquet(target, part)
        else:
            write_telemetry(target, part)     # rosbag2 folder, bare .mcap or .db3
    reference = detect_events(joined_from_files([craft / n for n in names],
                                                tmp_path / 'joined.parquet'))
    assert reference
    result = run_archive(tmp_path / 'archive', client=client, task_bytes=1)
    assert events_of(result, 'sat-r') == reference
    summary = result.summary['spacecraft']['sat-r']
    assert summary['passes'] == names and summary['rows_dropped'] == 100


def test_calibrated_gyro_equals_detect(client, tmp_path):
    """A calibration with a gyro block: the gyro diagnosis uses its thresholds."""
    healthy = add_gyro_channels(simulate_friction(duration_s=2500, rate_hz=10,
                                                  wheels=('rw1',), seed=41), seed=42)
    document, _, _ = calibrated.commission([as_read(healthy, tmp_path)])
    assert set(document['calibration']['gyro']) == {'x', 'y', 'z'}
    craft = tmp_path / 'archive' / 'sat-g'
    craft.mkdir(parents=True)
    (craft / 'calibration.yaml').write_text(yaml.safe_dump(plain(document), sort_keys=False))
    tele = simulate_friction(duration_s=3000, rate_hz=10, wheels=('rw1',), seed=43)
    tele = as_read(add_gyro_channels(tele, fault=named_fault('fast', 2, 1500.0), seed=44),
                   tmp_path)
    cuts = [(0, 10000, 'b.csv'), (11000, 20000, 'a.parquet'), (20000, 30000, 'c.csv')]
    write_passes(craft, tele, cuts)
    reference = detect_events(joined(tele, cuts, tmp_path / 'joined.csv'),
                              craft / 'calibration.yaml')
    assert any(e['component'] == 'gyro_z' for e in reference)
    result = run_archive(tmp_path / 'archive', client=client, task_bytes=1)
    assert events_of(result, 'sat-g') == reference


def test_refined_friction_model_equals_detect(client, tmp_path):
    """The fleet takes every option detect takes, a refined friction model included."""
    t = np.arange(0.0, 3000.0, 0.1)
    rng = np.random.default_rng(8)
    w = 150.0 * np.sin(t / 60.0) + 20.0
    temp = 20.0 + 10.0 * np.sin(t / 700.0)
    f = (-(2e-4 + 1e-5 * (temp - 20.0) + 3e-4 * (t >= 2000.0)) * np.sign(w) - 5e-7 * w
         + rng.normal(0.0, 5e-5, t.size))
    from rwa_monitor.telemetry import Telemetry
    tele = Telemetry.from_columns({'time': t, 'rw1_speed': w, 'rw1_friction': f,
                                   'rw1_temperature': temp})
    model = tmp_path / 'model.yaml'
    model.write_text('friction_model:\n  wheel: rw1\n  effects:\n'
                     '  - name: aux:rw1_temperature:dry\n    kind: aux\n'
                     '    params: {column: rw1_temperature, component: dry, center: 20.0}\n')
    config = tmp_path / 'config.yaml'
    config.write_text(f'llr_detector:\n  ros__parameters:\n    friction_model_file: {model}\n'
                      '    window: 300\n')
    tele = as_read(tele, tmp_path)
    cuts = [(0, 12000, 'b.csv'), (12500, 30000, 'a.csv')]
    write_passes(tmp_path / 'archive' / 'sat-m', tele, cuts)
    reference = detect_events(joined(tele, cuts, tmp_path / 'joined.csv'), config=config)
    assert reference
    result = run_archive(tmp_path / 'archive', client=client, config=config, task_bytes=1)
    assert events_of(result, 'sat-m') == reference


def as_json(value):
    """Return ``value`` as summary.json holds it: a non-finite float as None."""
    if isinstance(value, list):
        return [as_json(v) for v in value]
    return None if isinstance(value, float) and not math.isfinite(value) else value


def test_limits_from_the_config_reach_summary(archive, client, tmp_path):
    """The fleet block's limits: each wheel's trend in summary.json; detectors unchanged."""
    from rwa_monitor.fleet.history import current
    from rwa_monitor.fleet.trends import trend_steps, wheel_trends
    folder, reference, _ = archive
    config = tmp_path / 'limits.yaml'
    config.write_text('fleet:\n  ros__parameters:\n    dry_limit: 2.0e-4\n'
                      '    viscous_limit: 3.0e-6\n')
    result = run_archive(folder, client=client, config=config)
    limits = {'dry': 2.0e-4, 'viscous': 3.0e-6}
    assert result.summary['trend_limits'] == limits
    for craft, events in reference.items():
        assert events_of(result, craft) == events
    starts = trend_steps((h.spacecraft, h.event) for h in current(result.history))
    expected = wheel_trends([r.fields() for r in result.trend], limits, starts)
    assert len(expected) == 4
    for entry in expected:
        shown = result.summary['spacecraft'][entry['spacecraft']]['components'][
            entry['wheel']]['trend']
        assert shown['passes'] == entry['passes'] > 0
        assert set(shown['steps_s']) <= set(starts.get((entry['spacecraft'],
                                                        entry['wheel']), ()))
        assert shown['dry_limit'] == 2.0e-4 and shown['viscous_limit'] == 3.0e-6
        for key, value in shown.items():
            assert value == as_json(entry[key]), key

    bad = tmp_path / 'bad.yaml'
    bad.write_text('fleet:\n  ros__parameters:\n    dry_limit: -1.0\n')
    with pytest.raises(ConfigError, match='dry_limit'):
        run_archive(folder, client=client, config=bad)
    bad.write_text('fleet:\n  ros__parameters:\n    epoch_utc: yesterday\n')
    with pytest.raises(ConfigError, match='epoch_utc'):
        run_archive(folder, client=client, config=bad)


def test_calibrated_levels_use_only_the_samples_the_detector_tests(archive):
    """Speeds outside the calibrated range: NaN for the trend fit too, dropped and counted."""
    from rwa_monitor.core.trend import pass_levels
    from rwa_monitor.fleet.archive import PassFile
    from rwa_monitor.fleet.chain import setup_of, SpacecraftSpec, step
    from rwa_monitor.fleet.records import Chain
    from rwa_monitor.pipelines.llr import DEFAULTS
    folder, _, work = archive
    cal = str(folder / 'sat-b' / 'calibration.yaml')
    spec = SpacecraftSpec('sat-b', ('rw1',), False, {**DEFAULTS, 'calibration_file': cal})
    nominal = setup_of(spec).runner('rw1').nominal
    rng = np.random.default_rng(3)
    lo, hi = nominal.speed_range
    inside = rng.uniform(max(nominal.band_rad_s, 2.0), 0.9 * min(hi, -lo), 3000)
    inside *= rng.choice([-1.0, 1.0], inside.size)
    outside = hi + rng.uniform(5.0, 50.0, 1000)
    w = np.concatenate([inside, outside])
    t = 0.1 * np.arange(w.size)
    f = np.concatenate([nominal.nominal(inside) + rng.normal(0, 5e-5, inside.size),
                        np.full(outside.size, 0.5)])   # far off: would wreck a fit
    from rwa_monitor.telemetry import Telemetry
    path = work / 'levels.csv'
    write_telemetry(path, Telemetry.from_columns({'time': t, 'rw1_speed': w,
                                                  'rw1_friction': f}))
    chain = step(spec, Chain(-np.inf, {}), [PassFile('p1', str(path), 1, 0.0, ())])
    row = chain.trend[0]
    f = np.loadtxt(path, delimiter=',', skiprows=1, usecols=2)[:inside.size]
    alone = pass_levels(t[:inside.size], inside, f - nominal.nominal(inside))
    assert row.samples == alone.samples == inside.size
    assert row.dry == pytest.approx(alone.dry, rel=1e-6, abs=1e-12)
    assert abs(row.dry) < 5 * row.dry_se + 1e-9 and row.relative_to == 'nominal'
    assert chain.facts['rw1'].not_tested['outside_calibrated_range'] == outside.size


def test_not_examined_follows_detect_coverage_rule(client, tmp_path):
    """A wheel whose friction is mostly missing is ``unknown`` as in detect, with its counts."""
    from rwa_monitor.pipelines import detect
    from rwa_monitor.telemetry import read_telemetry, Telemetry
    tele = simulate_friction(duration_s=1200, rate_hz=10, wheels=('rw1', 'rw2'), seed=7)
    cols = tele.columns()
    cols['rw2_friction'] = np.where(np.arange(len(tele)) % 10 < 7, np.nan,
                                    cols['rw2_friction'])     # 70 % missing: > 50 %
    whole = tmp_path / 'whole.csv'
    write_telemetry(whole, Telemetry.from_columns(cols))
    tele = read_telemetry(whole)
    cuts = [(6000, 12000, 'a.csv'), (0, 6000, 'b.csv')]
    write_passes(tmp_path / 'archive' / 'sat-u', tele, cuts)
    result = run_archive(tmp_path / 'archive', client=client)
    reference = detect(tele, {}).summary['pipelines']['llr']['components']
    wheels = result.summary['spacecraft']['sat-u']['components']
    for wheel in ('rw1', 'rw2'):
        expected = reference[wheel]
        for key in ('verdict', 'samples', 'usable_samples', 'needed_samples', 'rejected'):
            assert wheels[wheel][key] == expected[key], (wheel, key)
    assert wheels['rw1']['verdict'] == 'examined'
    assert wheels['rw2']['verdict'] == 'unknown' and wheels['rw2']['health'] == 'unknown'
    missing = result.summary['spacecraft']['sat-u']['not_examined']
    assert missing == {'rw2': f'llr: unknown: {reference["rw2"]["verdict_reason"]}'}
    assert result.incomplete


def test_worker_peak_memory_is_its_own_not_its_starters():
    """A process started by a large one reports its own peak (ru_maxrss would not)."""
    import subprocess
    import sys
    from rwa_monitor.fleet.chain import peak_memory_mb
    ballast = np.ones(40_000_000)   # 320 MB in this process
    parent = peak_memory_mb()
    child = float(subprocess.run(
        [sys.executable, '-c', 'from rwa_monitor.fleet.chain import peak_memory_mb; '
         'print(peak_memory_mb())'], check=True, capture_output=True, text=True).stdout)
    assert parent > 320.0 > child > 0.0
    del ballast
