"""The seeded fleet archive (sim/fleet.py, ``rwa-monitor simulate fleet``, docs/fleet.md)."""

import json
import math

import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.core.trend import pass_levels
from rwa_monitor.sim.fleet import DAY_S, Fault, pass_telemetry, plan_fleet, write_fleet
from rwa_monitor.telemetry import read_telemetry
from rwa_monitor.telemetry.calibration_file import load

SMALL = dict(spacecraft=2, days=1.0, rate_hz=2.0, passes_per_day=8, pass_s=300.0)


def files_of(root):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob('*')) if p.is_file()}


def test_same_seed_same_bytes_other_seed_other_data(tmp_path):
    write_fleet(tmp_path / 'a', plan_fleet(**SMALL, seed=3))
    write_fleet(tmp_path / 'b', plan_fleet(**SMALL, seed=3))
    write_fleet(tmp_path / 'c', plan_fleet(**SMALL, seed=4))
    a, b, c = (files_of(tmp_path / x) for x in 'abc')
    assert a == b and len(a) == 2 * 8 + 1
    assert set(a) != set(c)


def test_layout_passes_with_gaps_and_names_not_in_time_order(tmp_path):
    plan = plan_fleet(**SMALL, seed=5)
    write_fleet(tmp_path, plan)
    truth = json.loads((tmp_path / 'truth.json').read_text())
    assert sorted(truth['spacecraft']) == ['sc1', 'sc2'] == sorted(
        p.name for p in tmp_path.iterdir() if p.is_dir())
    unsorted = 0
    for name, craft in truth['spacecraft'].items():
        passes = craft['passes']
        assert sorted(p.name for p in (tmp_path / name).iterdir()) == sorted(
            p['file'] for p in passes)
        starts = [p['t_start_s'] for p in passes]
        assert all(later > p['t_end_s'] for p, later in zip(passes, starts[1:]))
        unsorted += [p['file'] for p in passes] != sorted(p['file'] for p in passes)
        tele = read_telemetry(tmp_path / name / passes[3]['file'])
        assert list(tele.wheels) == ['rw1', 'rw2', 'rw3', 'rw4'] and not tele.truth
        assert tele.time[0] == passes[3]['t_start_s'] and len(tele) == passes[3]['samples']
        assert tele.time[-1] == pytest.approx(passes[3]['t_end_s'])
    assert unsorted == 2


def test_truth_matches_the_friction_in_the_passes(tmp_path):
    plan = plan_fleet(spacecraft=1, days=2.0, rate_hz=10.0, passes_per_day=4, pass_s=600.0,
                      wear_fraction=1.0, faults=2, commissioning_passes=2, seed=11)
    write_fleet(tmp_path, plan)
    document = json.loads((tmp_path / 'truth.json').read_text())
    truth, pass_s = document['spacecraft']['sc1'], document['pass_s']
    levels = {}
    for p in truth['passes']:
        tele = read_telemetry(tmp_path / 'sc1' / p['file'])
        for w, wheel in tele.wheels.items():
            levels.setdefault(w, []).append(pass_levels(tele.time, wheel.speed,
                                                        wheel.friction))
    faults = [(w, f) for w, block in truth['wheels'].items() for f in block['faults']]
    assert len(faults) == 2
    for w, block in truth['wheels'].items():
        assert block['wear_dry_nm_per_day'] > 0
        for p, lv in zip(truth['passes'], levels[w]):
            mid_day = (p['t_start_s'] + 0.5 * pass_s) / DAY_S
            dry = block['dry_nm'] + block['wear_dry_nm_per_day'] * mid_day + sum(
                f['delta_dry_nm'] for f in block['faults'] if f['time_s'] <= p['t_start_s'])
            visc = block['viscous_nms'] + sum(
                f['delta_viscous_nms'] for f in block['faults'] if f['time_s'] <= p['t_start_s'])
            if any(p['t_start_s'] < f['time_s'] <= p['t_end_s'] for f in block['faults']):
                continue                      # a step inside the pass: two levels
            assert abs(lv.dry - dry) < 5 * lv.dry_se, (w, p)
            assert abs(lv.viscous - visc) < 5 * lv.viscous_se, (w, p)
    for w, f in faults:
        size = f['delta_dry_nm'] if f['kind'] == 'dry' else f['delta_viscous_nms']
        assert size > 0 and f['time_s'] > truth['passes'][1]['t_end_s']
        first = f['first_sample_time_s']
        assert first is None or first >= f['time_s'] - 1e-9


def test_a_step_fault_inside_a_pass_shows_at_its_first_sample():
    plan = plan_fleet(spacecraft=1, days=1.0, rate_hz=10.0, passes_per_day=2, pass_s=600.0,
                      faults=0, commissioning_passes=1, seed=2)
    craft = plan.spacecraft[0]
    p = craft.passes[1]
    craft.faults.append(Fault('rw2', 'dry', p.start_s + 300.05, 1e-4, 0.0))
    tele = pass_telemetry(plan, craft, 1)
    wheel = tele.wheels['rw2']
    k = int(np.searchsorted(tele.time, p.start_s + 300.05))
    before = pass_levels(tele.time[:k], wheel.speed[:k], wheel.friction[:k])
    after = pass_levels(tele.time[k:], wheel.speed[k:], wheel.friction[k:])
    se = math.hypot(before.dry_se, after.dry_se)
    assert abs(after.dry - before.dry - 1e-4) < 5 * se and tele.time[k] == p.start_s + 300.1


def test_cli_writes_the_archive_with_calibrations_and_refuses_a_full_folder(tmp_path, capsys):
    out = tmp_path / 'archive'
    argv = ['simulate', 'fleet', '-o', str(out), '--spacecraft', '2', '--days', '1',
            '--rate', '5', '--passes-per-day', '4', '--commissioning-passes', '2',
            '--calibrate', '--seed', '1']
    assert main(argv) == 0
    assert 'wrote' in capsys.readouterr().out
    for name in ('sc1', 'sc2'):
        cal = load(out / name / 'calibration.yaml')
        assert sorted(cal['wheels']) == ['rw1', 'rw2', 'rw3', 'rw4']
        assert len(list((out / name).glob('*.csv'))) == 4
    assert main(argv) == 2
    assert 'not an empty folder' in capsys.readouterr().err


def test_bad_settings_are_config_errors(tmp_path, capsys):
    assert main(['simulate', 'fleet', '-o', str(tmp_path / 'x'), '--rate', '0.01']) == 2
    assert 'fewer than 20 samples' in capsys.readouterr().err
    with pytest.raises(ValueError, match='pass_s'):
        plan_fleet(passes_per_day=48, pass_s=3600.0)


def test_ccsds_archive_truth_names_the_packet_files(tmp_path):
    out = tmp_path / 'archive'
    assert main(['simulate', 'fleet', '-o', str(out), '--spacecraft', '1', '--days', '1',
                 '--rate', '2', '--passes-per-day', '3', '--pass-minutes', '5',
                 '--seed', '6', '--format', 'ccsds']) == 0
    passes = json.loads((out / 'truth.json').read_text())['spacecraft']['sc1']['passes']
    assert sorted(p['file'] for p in passes) == sorted(
        p.name for p in (out / 'sc1').glob('*.bin')) and len(passes) == 3
