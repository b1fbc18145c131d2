"""CCSDS space packets in XTCE: decoded values equal space-packet-parser's, joins, round trips.

Test files: one written from an XTCE made with yamcs-pymdb (test/ccsds_files.py: bit
fields, two's complement, little-endian, polynomial and spline calibrators, a string
whose size comes from the data, four rates), and the package's own writer on a
multi-rate record with NaN, auxiliary and truth columns.
"""

import pathlib

from ccsds_files import GYRO, HOUSEKEEPING, MAP, mixed_file, pymdb_xtce, REFERENCE, STAR, WHEEL
import numpy as np
import pytest
import space_packet_parser as spp

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.telemetry import ccsds, read_telemetry, Telemetry, Wheel, write_telemetry
from rwa_monitor.telemetry import telemetry_map, xtce
from rwa_monitor.telemetry.ccsds_write import sibling_paths


@pytest.fixture(scope='module')
def mixed(tmp_path_factory):
    """Return (packets, XTCE, map, packets per APID) of the yamcs-pymdb definition."""
    folder = tmp_path_factory.mktemp('mixed')
    xml = pymdb_xtce(folder / 'def.xml')
    yml = folder / 'map.yaml'
    yml.write_text(MAP)
    counts = mixed_file(folder / 'pass.bin')
    return folder / 'pass.bin', xml, yml, counts


def multi_rate(n=400, seed=5):
    """Return a record whose streams have their own rows, with NaN, aux and truth."""
    rng = np.random.default_rng(seed)
    time = np.round(1000.0 + 0.05 * np.arange(n), 9)
    wheels = np.arange(n) % 2 == 0
    gyro = np.arange(n) % 4 == 1
    star = np.arange(n) % 4 == 3
    tele = Telemetry(time=time, source=None)

    def sparse(mask, width):
        out = np.full((n, width), np.nan)
        out[mask] = rng.normal(size=(mask.sum(), width))
        return out

    speed, friction = sparse(wheels, 2), sparse(wheels, 2)
    speed[10, 1] = np.nan
    tele.wheels = {'rw1': Wheel(speed[:, 0], friction[:, 0]), 'rw2': Wheel(speed[:, 1])}
    tele.gyro, tele.attitude = sparse(gyro, 3), sparse(star, 4)
    tele.aux = {'rw1_temperature': sparse(wheels, 1)[:, 0]}
    tele.truth = {'rw1_dry': sparse(wheels, 1)[:, 0]}
    tele.present = {'wheels': wheels, 'gyro': gyro, 'star_tracker': star, 'columns': wheels}
    return tele


def reference_values(path, xml, yml):
    """Return container -> parameter -> values decoded packet by packet by the reference."""
    definition = xtce.load(xml)
    tmap = telemetry_map.read_map(yml)
    columns_of = telemetry_map.check(tmap, definition)
    by_apid = {definition.apid(c, 'CCSDS_APID'): c for c in tmap.time}
    wanted = {c: list(dict.fromkeys([*tmap.time[c].parameters(),
                                     *(tmap.columns[k] for k in columns_of[c])]))
              for c in tmap.time}
    out = {c: {p: [] for p in wanted[c]} for c in tmap.time}
    with open(path, 'rb') as handle:
        for raw in spp.ccsds_generator(handle):
            container = by_apid.get((raw[0] & 7) << 8 | raw[1])
            if container is not None:
                packet = definition.spp.parse_bytes(raw)
                for name in wanted[container]:
                    out[container][name].append(float(packet[name]))
    return definition, tmap, columns_of, {c: {p: np.array(v) for p, v in d.items()}
                                          for c, d in out.items()}


def test_pymdb_definition_decodes_fixed_containers_vectorised(mixed):
    from rwa_monitor.telemetry.xtce_layout import layout
    _, xml, yml, _ = mixed
    definition = xtce.load(xml)
    tmap = telemetry_map.read_map(yml)
    columns = telemetry_map.check(tmap, definition)
    layouts = {c: layout(definition, c, {tmap.columns[k] for k in columns[c]}
                         | set(tmap.time[c].parameters()))
               for c in tmap.time}
    vectorised = [c for c, lay in layouts.items() if lay.fields]
    assert vectorised == ['WheelPacket', 'GyroPacket', 'StarPacket']
    assert layouts['WheelPacket'].length == 32
    temp = layouts['WheelPacket'].fields['TEMP']
    assert (temp.offset, temp.size, temp.kind) == (195, 13, 'int')   # off byte boundaries
    assert layouts['WheelPacket'].fields['RW2_TRQ'].little
    assert 'MODE_NAME' in layouts['RefPacket'].why      # its size depends on the data


@pytest.mark.parametrize('source', ['pymdb', 'writer'])
def test_decoded_values_equal_space_packet_parser(mixed, tmp_path, source):
    if source == 'pymdb':
        path, xml, yml, _ = mixed
    else:
        path = tmp_path / 'rec.bin'
        write_telemetry(path, multi_rate())
        xml, yml = sibling_paths(path)
    definition, tmap, columns_of, reference = reference_values(path, xml, yml)
    for chunk in (ccsds.scan.MAX_PACKET, 1 << 24):      # packets cut by chunk ends, or not
        decoded, report = ccsds.decode_file(path, definition, tmap, columns_of, chunk)
        assert set(decoded) == set(reference)
        for container, values in reference.items():
            assert len(next(iter(values.values()))) > 0
            for name, expected in values.items():
                np.testing.assert_array_equal(decoded[container][name], expected,
                                              err_msg=f'{container}.{name}')
        assert not report.length_mismatch and not report.undecodable and not report.gaps


def test_containers_at_four_rates_join_on_the_union_of_stamps(mixed):
    path, xml, yml, counts = mixed
    tele, report = ccsds.read_packets(path, xml, yml)
    wheel_t = np.round(np.arange(200) / 10 * 65536) / 65536    # CUC: 2**-16 s ticks
    gyro_t = np.arange(0, 200, 2) / 10 + 0.05                   # float64 seconds
    assert len(tele) == len(np.union1d(wheel_t, gyro_t))
    np.testing.assert_array_equal(tele.time[tele.rows('wheels')], wheel_t)
    np.testing.assert_array_equal(tele.time[tele.rows('gyro')], gyro_t)
    star = tele.rows('star_tracker')
    np.testing.assert_array_equal(tele.time[star], np.arange(20.0))
    assert len(tele.rows('reference_rate')) == counts[REFERENCE]
    assert np.isnan(tele.gyro[tele.rows('wheels')]).all()
    assert np.isfinite(tele.wheels['rw1'].speed[tele.rows('wheels')]).all()
    assert np.array_equal(tele.present['columns'], tele.present['wheels'])
    assert report.decoded == {'WheelPacket': counts[WHEEL], 'GyroPacket': counts[GYRO],
                              'StarPacket': counts[STAR], 'RefPacket': counts[REFERENCE]}
    assert report.unmapped_apids == {HOUSEKEEPING: counts[HOUSEKEEPING]}
    assert report.lines() == [f'{counts[HOUSEKEEPING]} packets of containers the map does '
                              f'not use skipped (APID {HOUSEKEEPING}: {counts[HOUSEKEEPING]})']
    assert report.packets == sum(counts.values())


def test_writer_round_trip_keeps_every_channel_and_the_rows_of_each_stream(tmp_path):
    tele = multi_rate()
    path = tmp_path / 'rec.bin'
    write_telemetry(path, tele)
    back = read_telemetry(path)
    np.testing.assert_array_equal(back.time, tele.time)
    for name, values in tele.columns().items():
        np.testing.assert_array_equal(back.columns()[name], values, err_msg=name)
    assert set(back.present) == set(tele.present)
    for stream, mask in tele.present.items():
        np.testing.assert_array_equal(back.present[stream], mask)


def test_a_csv_record_round_trips_exactly_and_single_rate_stays_single_rate(tmp_path):
    tele = Telemetry(time=np.arange(30) * 0.1, wheels={'rw1': Wheel(
        np.linspace(-3, 3, 30), np.full(30, 2e-4))}, gyro=np.ones((30, 3)))
    write_telemetry(tmp_path / 'a.csv', tele)
    from_csv = read_telemetry(tmp_path / 'a.csv')
    write_telemetry(tmp_path / 'a.bin', from_csv)
    back = read_telemetry(tmp_path / 'a.bin')
    assert back.present == {}
    for name, values in from_csv.columns().items():
        np.testing.assert_array_equal(back.columns()[name], values, err_msg=name)


def test_same_input_same_bytes(tmp_path):
    for run in ('a', 'b'):
        write_telemetry(tmp_path / run / 'rec.bin', multi_rate())
    for name in ('rec.bin', 'rec.xml', 'rec_map.yaml'):
        assert (tmp_path / 'a' / name).read_bytes() == (tmp_path / 'b' / name).read_bytes()


def test_sequence_counts_wrap_without_a_gap(tmp_path):
    n = 17000                                    # past the 14-bit count
    tele = Telemetry(time=np.arange(n) * 0.01, wheels={'rw1': Wheel(np.zeros(n))})
    write_telemetry(tmp_path / 'long.bin', tele)
    _, report = ccsds.read_packets(tmp_path / 'long.bin', *sibling_paths(tmp_path / 'long.bin'))
    assert report.gaps == {} and report.decoded == {'WheelPacket': n}


def test_definitions_are_found_beside_the_file(tmp_path, mixed):
    path, xml, yml, _ = mixed
    folder = tmp_path / 'sc'
    folder.mkdir()
    (folder / 'p.bin').write_bytes(path.read_bytes())
    with pytest.raises(TelemetrySchemaError, match='--xtce DEF.xml --telemetry-map'):
        read_telemetry(folder / 'p.bin')
    (folder / 'telemetry.xml').write_bytes(xml.read_bytes())
    (folder / 'telemetry_map.yaml').write_bytes(yml.read_bytes())
    archive_style = read_telemetry(folder / 'p.bin')
    other = folder / 'p.dat'                       # any suffix, told it is packets
    other.write_bytes(path.read_bytes())
    told = read_telemetry(other, xtce=xml, telemetry_map=yml)
    np.testing.assert_array_equal(told.time, archive_style.time)
    with pytest.raises(TelemetrySchemaError, match='no such XTCE'):
        read_telemetry(other, xtce=tmp_path / 'missing.xml')


def test_the_packet_report_is_logged_once_per_read(mixed, caplog):
    path, xml, yml, counts = mixed
    with caplog.at_level('WARNING', logger='rwa_monitor.telemetry'):
        read_telemetry(path, xtce=xml, telemetry_map=yml)
    assert [r.getMessage() for r in caplog.records] == [
        f'{path}: {counts[HOUSEKEEPING]} packets of containers the map does not use skipped '
        f'(APID {HOUSEKEEPING}: {counts[HOUSEKEEPING]})']


def test_epoch_is_read_as_utc(mixed):
    import datetime
    tmap = telemetry_map.read_map(mixed[2])
    assert tmap.epoch_utc == datetime.datetime(2026, 1, 1, tzinfo=datetime.timezone.utc)


def test_module_files_stay_short():
    folder = pathlib.Path(ccsds.__file__).parent
    for name in ('ccsds.py', 'ccsds_report.py', 'ccsds_scan.py', 'ccsds_write.py', 'xtce.py',
                 'xtce_layout.py', 'telemetry_map.py'):
        assert len((folder / name).read_text().splitlines()) < 400, name
