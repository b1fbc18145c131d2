"""rwa-monitor fleet: events equal detect on the joined passes; bad passes; --state.

The archive (test/fleet_archive.py) holds two spacecraft whose passes are cut from one
simulated record each, written under names out of time order, with gaps and an overlap,
one spacecraft calibrated. The reference is ``rwa-monitor detect`` on the same rows as
one file. The engine runs on a local Dask cluster of 2 worker processes.
"""

import json
import shutil

from distributed import Client, LocalCluster
from fleet_archive import (as_read, CUTS_A, CUTS_B, detect_events, events_of, joined,
                           joined_from_files, make_archive, references, rows, write_passes)
import pytest
import yaml

from rwa_monitor.cli.main import main
from rwa_monitor.core.identify.model import plain
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet import state
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


def test_events_equal_detect_on_joined_passes(archive, client):
    folder, reference, _ = archive
    result = run_archive(folder, client=client, task_bytes=1)   # a task per pass
    assert len(client.scheduler_info()['workers']) == 2
    for craft, events in reference.items():
        assert events, 'the reference must find something for the test to mean anything'
        assert events_of(result.events, craft) == events
    grouped = run_archive(folder, client=client)            # all passes in one task
    assert grouped.events == result.events
    assert json.dumps(grouped.trend) == json.dumps(result.trend)   # NaN-safe
    summary = result.summary['spacecraft']
    # Time order by first stamp, never by name; the overlap of 100 rows dropped.
    assert summary['sat-a']['passes'] == [name for _, _, name in CUTS_A]
    assert summary['sat-b']['passes'] == [name for _, _, name in CUTS_B]
    assert summary['sat-a']['rows_dropped'] == 100
    assert summary['sat-a']['components']['rw1']['samples'] == 42000
    assert set(summary['sat-a']['components']) == {'rw1', 'rw2', 'gyro'}
    assert summary['sat-b']['components']['rw1']['not_tested']['outside_calibrated_range'] > 0
    # sat-b rw1 runs mostly outside its calibrated range: unknown, as detect judges the
    # joined file (core/coverage.py; test_not_examined_follows_detect_coverage_rule).
    assert summary['sat-b']['components']['rw1']['verdict'] == 'unknown'
    assert list(summary['sat-b']['not_examined']) == ['rw1'] and not summary['sat-a'][
        'not_examined']
    assert result.anomaly and result.incomplete
    workers = result.timings['per_worker']
    assert workers and all(w['peak_rss_mb'] > 0 for w in workers.values())
    trend = [r for r in result.trend if r['spacecraft'] == 'sat-b' and r['wheel'] == 'rw2']
    assert [r['pass'] for r in trend] == [name for _, _, name in CUTS_B]
    assert {r['relative_to'] for r in trend} == {'nominal'}


def test_cli_outputs_and_unreadable_pass(tmp_path):
    """A healthy spacecraft with a broken pass: the rest runs, exit code 3."""
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
    (tmp_path / 'archive' / 'sat-empty').mkdir()
    broken_cal = tmp_path / 'archive' / 'sat-d'
    broken_cal.mkdir()
    shutil.copy(craft / 'p1.csv', broken_cal / 'p1.csv')
    (broken_cal / 'calibration.yaml').write_text('calibration: [not, a, mapping\n')
    out = tmp_path / 'out'
    code = main(['fleet', str(tmp_path / 'archive'), '-o', str(out), '--workers', '1'])
    assert code == 3
    fleet = json.loads((out / 'summary.json').read_text())['spacecraft']
    assert 'no readable pass' in fleet['sat-empty']['not_examined']['spacecraft']
    assert 'calibration.yaml' in fleet['sat-d']['not_examined']['spacecraft']
    summary = fleet['sat-c']
    assert summary['not_examined']['pass p8.csv'].endswith('no rows')
    assert 'not a number' in summary['not_examined']['pass p0.csv']
    assert 'pass p9.csv' in summary['not_examined']
    assert summary['ignored'] == {'notes.txt': summary['ignored']['notes.txt']}
    assert summary['components']['rw1']['passes'] == 2
    assert summary['components']['rw1']['samples'] == 6000
    for name in ('events.json', 'events.parquet', 'summary.json', 'trend.parquet',
                 'report.html'):
        assert (out / name).stat().st_size > 0
    inside = tmp_path / 'archive' / 'out'
    assert main(['fleet', str(tmp_path / 'archive'), '-o', str(inside)]) == 2
    assert not inside.exists()
    for name in ('p0.csv', 'p8.csv', 'p9.csv'):
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
    assert not list(kept.glob('*.json'))
    assert main(['fleet', str(tmp_path / 'archive'), '-o', str(out), '--state', str(kept),
                 '--workers', '1']) == 0
    assert (kept / 'sat-c.json').exists()


def _partial(folder, target, keep):
    """Copy the archive with only the passes named in ``keep``."""
    for craft in folder.iterdir():
        (target / craft.name).mkdir(parents=True, exist_ok=True)
        for entry in craft.iterdir():
            if entry.name in keep or entry.name == 'calibration.yaml':
                shutil.copy(entry, target / craft.name / entry.name)


def test_resumed_state_equals_full_run(archive, client, tmp_path):
    folder, reference, _ = archive
    first = {'pass_k.csv', 'pass_b.parquet', 'zz.csv'}
    growing = tmp_path / 'archive'
    _partial(folder, growing, first)
    kept = tmp_path / 'state'
    one = run_archive(growing, client=client, state_dir=kept, task_bytes=1)
    _partial(folder, growing, {name for _, _, name in CUTS_A + CUTS_B})
    two = run_archive(growing, client=client, state_dir=kept)
    for craft, events in reference.items():
        # The first run's end-of-archive categorisations are superseded by the second run
        # (its state is the one before them): every other event is reported once.
        before = [e for e in events_of(one.events, craft) if not e.get('final')]
        assert before + events_of(two.events, craft) == events
        assert events_of(two.events, craft), 'the second part must hold events'
    done = two.summary['spacecraft']['sat-a']['already_processed']
    assert done == ['pass_k.csv', 'pass_b.parquet']
    three = run_archive(growing, client=client, state_dir=kept)
    assert three.events == [] and not three.incomplete
    # The friction trend covers the wheel's life: earlier passes' rows come from the state.
    full = run_archive(folder, client=client)
    assert json.dumps(two.trend) == json.dumps(full.trend) == json.dumps(three.trend)


def test_foreign_state_is_refused(archive, client, tmp_path):
    folder, _, _ = archive
    kept = tmp_path / 'state'
    run_archive(folder, client=client, state_dir=kept)
    other = tmp_path / 'other.yaml'
    other.write_text('llr_detector:\n  ros__parameters:\n    window: 400\n')
    with pytest.raises(state.StateMismatch, match='other parameters'):
        run_archive(folder, client=client, state_dir=kept, config=other)
    document = json.loads((kept / 'sat-a.json').read_text())
    document['version'] = state.VERSION + 1
    (kept / 'sat-a.json').write_text(json.dumps(document))
    with pytest.raises(ConfigError, match='refusing to mix'):
        run_archive(folder, client=client, state_dir=kept)
    code = main(['fleet', str(folder), '-o', str(tmp_path / 'out'), '--state', str(kept),
                 '--workers', '1'])
    assert code == 2


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
    assert events_of(result.events, 'sat-r') == reference
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
    assert events_of(result.events, 'sat-g') == reference


def test_limits_from_the_config_reach_summary_and_leave_the_state(archive, client, tmp_path):
    """The fleet block's limits: each wheel's trend in summary.json; detectors unchanged."""
    from rwa_monitor.fleet.report import wheel_trends
    folder, reference, _ = archive
    kept = tmp_path / 'state'
    run_archive(folder, client=client, state_dir=kept, commit=False)
    config = tmp_path / 'limits.yaml'
    config.write_text('fleet:\n  ros__parameters:\n    dry_limit: 2.0e-4\n'
                      '    viscous_limit: 3.0e-6\n')
    result = run_archive(folder, client=client, state_dir=kept, config=config)
    limits = {'dry': 2.0e-4, 'viscous': 3.0e-6}
    assert result.summary['trend_limits'] == limits
    for craft, events in reference.items():
        assert events_of(result.events, craft) == events
    expected = wheel_trends(result.trend, limits)
    assert len(expected) == 4
    for entry in expected:
        shown = result.summary['spacecraft'][entry['spacecraft']]['components'][
            entry['wheel']]['trend']
        assert shown['passes'] == entry['passes'] > 0
        assert shown['dry_limit'] == 2.0e-4 and shown['viscous_limit'] == 3.0e-6
        for key, value in shown.items():
            want = entry[key]
            assert value == (None if isinstance(want, float) and want != want else want) \
                or abs(want) == float('inf') and value is None
    json.dumps(result.summary, allow_nan=False, default=str)      # valid JSON: no NaN
    bad = tmp_path / 'bad.yaml'
    bad.write_text('fleet:\n  ros__parameters:\n    dry_limit: -1.0\n')
    with pytest.raises(ConfigError, match='dry_limit'):
        run_archive(folder, client=client, config=bad)


def test_calibrated_levels_use_only_the_samples_the_detector_tests(archive):
    """Speeds outside the calibrated range: NaN for the trend fit too, dropped and counted."""
    import numpy as np
    from rwa_monitor.core.trend import pass_levels
    from rwa_monitor.fleet import components as comp
    from rwa_monitor.telemetry import Telemetry
    folder, _, _ = archive
    cal = str(folder / 'sat-b' / 'calibration.yaml')
    spec = comp.ComponentSpec('sat-b', 'rw1', {'calibration_file': cal})
    detector, nominal = comp.build(spec)
    rng = np.random.default_rng(3)
    lo, hi = nominal.speed_range
    inside = rng.uniform(max(nominal.band_rad_s, 2.0), 0.9 * min(hi, -lo), 3000)
    inside *= rng.choice([-1.0, 1.0], inside.size)
    outside = hi + rng.uniform(5.0, 50.0, 1000)
    w = np.concatenate([inside, outside])
    t = 0.1 * np.arange(w.size)
    f = np.concatenate([nominal.nominal(inside) + rng.normal(0, 5e-5, inside.size),
                        np.full(outside.size, 0.5)])   # far off: would wreck a fit
    chain = comp.new_chain()
    tele = Telemetry.from_columns({'time': t, 'rw1_speed': w, 'rw1_friction': f})
    comp._feed_wheel(spec, detector, nominal, tele, chain, 'p1')
    row = chain['trend'][0]
    alone = pass_levels(t[:inside.size], inside, f[:inside.size] - nominal.nominal(inside))
    assert row['samples'] == alone.samples == inside.size
    assert row['dry'] == pytest.approx(alone.dry, rel=1e-9, abs=1e-15)
    assert row['viscous'] == pytest.approx(alone.viscous, rel=1e-9, abs=1e-18)
    assert abs(row['dry']) < 5 * row['dry_se'] + 1e-9 and row['relative_to'] == 'nominal'
    assert chain['not_tested']['outside_calibrated_range'] == outside.size


def test_not_examined_follows_detect_coverage_rule(client, tmp_path):
    """A wheel whose friction is mostly missing is ``unknown`` as in detect, with its counts."""
    import numpy as np
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
        for key in ('verdict', 'samples', 'usable_samples', 'needed_samples'):
            assert wheels[wheel][key] == expected[key], (wheel, key)
    assert wheels['rw1']['verdict'] == 'examined' and wheels['rw1']['not_examined'] is None
    assert wheels['rw2']['verdict'] == 'unknown'
    assert wheels['rw2']['not_examined'] == (
        f'llr: rw2 unknown: {reference["rw2"]["verdict_reason"]}')
    assert result.incomplete
