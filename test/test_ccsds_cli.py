"""Packets wherever a recording goes in, and ``simulate ... --format ccsds``.

detect, diagnose, calibrate, identify, the fleet and the replay node.

The reference is the same command on the CSV file the packets were made from (every value
as the CSV holds it, float64 in the packets): the outputs must be equal, not close.
"""

import json

from ccsds_files import MAP, mixed_file, pymdb_xtce
from fleet_archive import detect_events, events_of, joined_from_files, rows
import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.telemetry import read_telemetry, write_telemetry
from rwa_monitor.telemetry.ccsds_write import write_packets


def _simulate(tmp_path, *args):
    assert main(['simulate', *args]) == 0


def _json(path):
    document = json.loads(path.read_text())
    document.get('summary', {}).pop('source', None)   # the input's own name
    for info in document.get('summary', {}).get('pipelines', {}).values():
        info.pop('runtime_s', None)           # wall time: the one field allowed to differ
        for entry in info.get('components', {}).values():
            if isinstance(entry, dict):
                entry.pop('runtime_s', None)
    return document


@pytest.fixture(scope='module')
def friction(tmp_path_factory):
    """Return (CSV, the same rows as packets) of a friction run with a dry step."""
    folder = tmp_path_factory.mktemp('friction')
    csv = folder / 'w.csv'
    assert main(['simulate', 'friction', '--wheels', '2', '--seconds', '2400', '--anomaly',
                 'rw2:dry:1200:+3e-4', '--seed', '33', '-o', str(csv)]) == 0
    write_telemetry(folder / 'w.bin', read_telemetry(csv))
    return csv, folder / 'w.bin'


def test_detect_on_packets_gives_the_csv_events_exactly(friction, tmp_path):
    csv, packets = friction
    assert main(['detect', str(csv), '-o', str(tmp_path / 'csv.json')]) == 1
    assert main(['detect', str(packets), '-o', str(tmp_path / 'bin.json')]) == 1
    from_csv, from_bin = _json(tmp_path / 'csv.json'), _json(tmp_path / 'bin.json')
    assert from_csv['events'] and from_bin['events'] == from_csv['events']
    assert from_bin['summary'] == from_csv['summary']


def test_gyro_detector_on_packets_gives_the_csv_events_exactly(tmp_path):
    csv = tmp_path / 'g.csv'
    _simulate(tmp_path, 'aocs', '--seconds', '1500', '--fault', 'fast', '--fault-time', '700',
              '--seed', '34', '-o', str(csv))
    write_telemetry(tmp_path / 'g.bin', read_telemetry(csv))
    main(['detect', str(csv), '-o', str(tmp_path / 'csv.json')])
    main(['detect', str(tmp_path / 'g.bin'), '-o', str(tmp_path / 'bin.json')])
    events = _json(tmp_path / 'csv.json')['events']
    assert any(e['detector'] == 'vsadc' for e in events)
    assert _json(tmp_path / 'bin.json')['events'] == events


def test_simulate_format_ccsds_writes_three_files_equal_to_the_recording(tmp_path):
    common = ['friction', '--wheels', '2', '--seconds', '1800', '--anomaly',
              'rw1:viscous:900:+3e-7', '--seed', '35']
    _simulate(tmp_path, *common, '-o', str(tmp_path / 'run.csv'), '--format', 'ccsds')
    assert sorted(p.name for p in tmp_path.iterdir()) == ['run.bin', 'run.xml',
                                                          'run_map.yaml']
    _simulate(tmp_path, *common, '-o', str(tmp_path / 'run.mcap'))
    for name in ('run.bin', 'run.mcap'):
        main(['detect', str(tmp_path / name), '-o', str(tmp_path / f'{name}.json')])
    events = _json(tmp_path / 'run.bin.json')['events']
    assert events and events == _json(tmp_path / 'run.mcap.json')['events']


def test_diagnose_calibrate_and_identify_take_packets(friction, tmp_path):
    csv, packets = friction
    healthy = tmp_path / 'h.csv'                  # calibrate: a short fault-free run
    _simulate(tmp_path, 'friction', '--wheels', '1', '--seconds', '900', '--seed', '38',
              '-o', str(healthy))
    write_telemetry(tmp_path / 'h.bin', read_telemetry(healthy))
    for name, source, fault_free in (('csv', csv, healthy), ('bin', packets, tmp_path / 'h.bin')):
        assert main(['diagnose', str(source), '-o', str(tmp_path / f'{name}.json'),
                     '--last', '3000']) in (0, 1)
        assert main(['identify', str(source), '--wheel', 'rw1', '-o',
                     str(tmp_path / f'id_{name}')]) == 0
        assert main(['calibrate', str(fault_free), '-o', str(tmp_path / f'cal_{name}')]) == 0
    diagnosis = [_json(tmp_path / f'{n}.json') for n in ('csv', 'bin')]
    for document in diagnosis:
        for wheel in document['wheels'].values():
            wheel.pop('timings_s')                  # wall times
    assert diagnosis[0] == diagnosis[1]
    cal = [(tmp_path / f'cal_{n}' / 'calibration.yaml').read_text().replace(
        str(tmp_path / f'h.{n}'), 'SOURCE') for n in ('csv', 'bin')]
    assert 'SOURCE' in cal[0] and cal[0] == cal[1]
    report = [json.loads((tmp_path / f'id_{n}' / 'report.json').read_text())
              for n in ('csv', 'bin')]
    assert report[0]['rmse_after'] == report[1]['rmse_after']
    assert report[0]['effects'] == report[1]['effects']


def test_detect_takes_explicit_definitions_and_says_when_they_are_missing(tmp_path, capsys):
    xml = pymdb_xtce(tmp_path / 'def.xml')
    (tmp_path / 'map.yaml').write_text(MAP)
    mixed_file(tmp_path / 'pass.dat', seconds=60)
    code = main(['detect', str(tmp_path / 'pass.dat'), '--xtce', str(xml),
                 '--telemetry-map', str(tmp_path / 'map.yaml'), '-o',
                 str(tmp_path / 'e.json')])
    assert code in (0, 1, 3)
    err = capsys.readouterr().err
    assert ('rwa-monitor detect: warning: ' + str(tmp_path / 'pass.dat') + ': 60 packets of '
            'containers the map does not use skipped (APID 103: 60)') in err
    assert json.loads((tmp_path / 'e.json').read_text())['summary']['samples'] > 0
    (tmp_path / 'lone.bin').write_bytes((tmp_path / 'pass.dat').read_bytes())
    assert main(['detect', str(tmp_path / 'lone.bin')]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and '--xtce DEF.xml --telemetry-map MAP.yaml' in err[0]


@pytest.mark.slow
def test_a_fleet_of_packet_passes_equals_detect_on_the_joined_data(tmp_path):
    """Passes as packets (out of name order, a gap, an overlap) beside telemetry.xml."""
    from distributed import Client, LocalCluster

    from rwa_monitor.fleet.engine import run_archive
    from rwa_monitor.sim.aocs import add_gyro_channels, named_fault
    from rwa_monitor.sim.friction import parse_anomaly, simulate_friction
    tele = simulate_friction(duration_s=2400, rate_hz=10, wheels=('rw1', 'rw2'), seed=36,
                             anomalies=[parse_anomaly('rw2:dry:1300:3e-4')])
    tele = add_gyro_channels(tele, fault=named_fault('fast', 0, 1500.0), seed=37)
    craft = tmp_path / 'archive' / 'sat-p'
    craft.mkdir(parents=True)
    names = ['q.bin', 'c.bin', 'x.bin', 'a.bin']
    for (first, end), name in zip([(0, 6000), (7000, 13000), (12900, 18000),
                                   (19000, 24000)], names):
        write_packets(craft / name, rows(tele, first, end), craft / 'telemetry.xml',
                      craft / 'telemetry_map.yaml')
    reference = detect_events(joined_from_files([craft / n for n in names],
                                                tmp_path / 'joined.parquet'))
    assert {e['detector'] for e in reference} == {'llr', 'vsadc'}
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        result = run_archive(tmp_path / 'archive', client=client, task_bytes=1)
    assert events_of(result, 'sat-p') == reference
    summary = result.summary['spacecraft']['sat-p']
    assert summary['passes'] == names and summary['rows_dropped'] == 100
    assert not summary.get('ignored')


@pytest.mark.ros
def test_the_replay_node_reads_packets_with_its_definition_parameters(tmp_path):
    from rclpy.parameter import Parameter
    from ros_harness import RosWorld

    from rwa_monitor.exceptions import ConfigError
    from rwa_monitor.nodes.replay import TelemetryReplay
    xml = pymdb_xtce(tmp_path / 'def.xml')
    (tmp_path / 'map.yaml').write_text(MAP)
    mixed_file(tmp_path / 'pass.dat', seconds=10)
    expected = read_telemetry(tmp_path / 'pass.dat', xtce=xml,
                              telemetry_map=tmp_path / 'map.yaml')
    values = {'file': str(tmp_path / 'pass.dat'), 'xtce_file': str(xml),
              'telemetry_map_file': str(tmp_path / 'map.yaml'), 'exit_when_done': False}
    with RosWorld() as world:
        replay = world.node(TelemetryReplay, parameter_overrides=[
            Parameter(k, value=v) for k, v in values.items()])
        np.testing.assert_array_equal(replay.telemetry.time, expected.time)
        assert set(replay.telemetry.present) == {'wheels', 'gyro', 'star_tracker',
                                                 'reference_rate', 'columns'}
        values['telemetry_map_file'] = str(xml)          # the XTCE given as the map
        with pytest.raises(ConfigError, match='parameter file: .*map'):
            world.node(TelemetryReplay, parameter_overrides=[
                Parameter(k, value=v) for k, v in values.items()])
