"""Fleet archive pieces without a cluster: Parquet passes, scans, the drop of old rows."""

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.fleet import archive
from rwa_monitor.sim.friction import simulate_friction
from rwa_monitor.telemetry import read_telemetry, Telemetry, write_telemetry
from rwa_monitor.telemetry.parquet_io import write_parquet


@pytest.fixture
def record():
    return simulate_friction(duration_s=60, rate_hz=10, wheels=('rw1', 'rw2'), seed=1)


def test_parquet_round_trip_and_detect_reader(record, tmp_path):
    path = tmp_path / 'p.parquet'
    write_parquet(path, record)
    back = read_telemetry(path)
    for name, values in record.columns().items():
        assert np.array_equal(back.columns()[name], values)


def test_read_pass_reads_each_format_as_detect_does_and_never_raises(record, tmp_path):
    """A Parquet pass takes the reader's direct path: the same record, the same refusals."""
    write_parquet(tmp_path / 'p.parquet', record)
    write_telemetry(tmp_path / 'c.csv', record)
    for name in ('p.parquet', 'c.csv'):
        got, want = archive.read_pass(str(tmp_path / name)), read_telemetry(tmp_path / name)
        assert got.columns().keys() == want.columns().keys()
        for column, values in want.columns().items():
            assert np.array_equal(got.columns()[column], values)
    (tmp_path / 'text.parquet').write_bytes(b'PAR1 not really')
    pq.write_table(pa.table({'time': [1.0, 1.0]}), tmp_path / 'back.parquet')
    pq.write_table(pa.table({'time': pa.array([], pa.float64())}), tmp_path / 'empty.parquet')
    assert archive.read_pass(str(tmp_path / 'text.parquet')).startswith(
        'unreadable: TelemetrySchemaError')
    assert 'strictly increasing' in archive.read_pass(str(tmp_path / 'back.parquet'))
    assert archive.read_pass(str(tmp_path / 'empty.parquet')) == 'no rows'
    assert archive.read_pass(str(tmp_path / 'gone.parquet')).startswith('unreadable:')


def test_parquet_columns_come_as_float_arrays_the_kernels_take_without_a_copy(tmp_path):
    """Plain float64 columns are the reader's buffers, writable; others converted, nulls NaN."""
    from rwa_monitor.core.jit import kernel_array
    from rwa_monitor.telemetry.parquet_io import read_parquet
    path = tmp_path / 'mixed.parquet'
    table = pa.table({'time': [0.0, 0.5, 1.0, 1.5],
                      'rw1_speed': pa.array([1.0, None, 3.0, 4.0], pa.float64()),
                      'rw1_friction': pa.array([2, -3, 2**53, 0], pa.int64()),
                      'rw2_speed': pa.chunked_array([[5.0, 6.0], [7.0, 8.0]]),
                      'rw2_friction': pa.array([0.5, 0.25, 0.125, 1.0], pa.float32())})
    pq.write_table(table, path)
    tele = read_parquet(path)
    assert tele.time.dtype == np.float64 and tele.time.flags.writeable
    assert kernel_array(tele.time) is tele.time
    assert np.array_equal(tele.wheels['rw1'].speed, [1.0, np.nan, 3.0, 4.0], equal_nan=True)
    assert tele.wheels['rw1'].friction.tolist() == [2.0, -3.0, 2.0**53, 0.0]
    assert tele.wheels['rw2'].friction.tolist() == [0.5, 0.25, 0.125, 1.0]
    for wheel in tele.wheels.values():
        assert wheel.speed.dtype == wheel.friction.dtype == np.float64
    pq.write_table(pa.table({'time': [0.0, 1.0], 'rw1_speed': [1.0, 2.0],
                             'rw1_friction': [0.1, 0.2]}), tmp_path / 'plain.parquet',
                   row_group_size=1)         # two row groups: two chunks, converted
    two = read_parquet(tmp_path / 'plain.parquet')
    assert two.time.tolist() == [0.0, 1.0] and two.wheels['rw1'].speed.tolist() == [1.0, 2.0]


@pytest.mark.parametrize('table, message', [
    ({'t': [0.0, 1.0]}, "column 'time'"),
    ({'time': [0.0, 0.0], 'rw1_speed': [1.0, 2.0]}, 'strictly increasing'),
    ({'time': [0.0, 1.0], 'rw1_speed': ['a', 'b']}, 'not a numeric column'),
    ({'time': [0.0, 1.0], 'rw1_friction': [1.0, 2.0]}, 'rw1_speed'),
    ({'time': pa.array([0, 10**8], pa.timestamp('ns'))}, 'times are seconds as numbers'),
])
def test_parquet_schema_errors_name_file_and_column(tmp_path, table, message):
    path = tmp_path / 'bad.parquet'
    pq.write_table(pa.table(table), path)
    with pytest.raises(TelemetrySchemaError, match=message) as err:
        read_telemetry(path)
    assert str(path) in str(err.value)


def test_scan_orders_by_first_stamp_and_names_components(record, tmp_path):
    cols = record.columns()
    first = {k: v[:300] for k, v in cols.items()}
    second = {k: v[300:] for k, v in cols.items()}
    write_telemetry(tmp_path / 'b.csv', Telemetry.from_columns(first))
    write_parquet(tmp_path / 'a.parquet', Telemetry.from_columns(second))
    scans = [archive.scan_pass(str(tmp_path / n)) for n in ('a.parquet', 'b.csv')]
    assert [s.first for s in scans] == [30.0, 0.0]
    assert archive.components(scans[0].columns) == ['rw1', 'rw2']
    assert archive.scan_pass(str(tmp_path / 'missing.csv')).startswith(
        'unreadable: FileNotFoundError')


def test_scan_of_parquet_reads_the_first_row_group_that_has_rows(tmp_path):
    path = tmp_path / 'groups.parquet'
    with pq.ParquetWriter(path, pa.schema([('time', pa.float64()),
                                           ('rw1_speed', pa.float64())])) as writer:
        writer.write_table(pa.table({'time': pa.array([], pa.float64()),
                                     'rw1_speed': pa.array([], pa.float64())}))
        writer.write_table(pa.table({'time': [7.5, 8.0], 'rw1_speed': [1.0, 2.0]}))
    assert pq.ParquetFile(path).metadata.num_row_groups == 2
    scan = archive.scan_pass(str(path))
    assert scan.first == 7.5 and scan.columns == ('time', 'rw1_speed')
    empty = tmp_path / 'empty.parquet'
    pq.write_table(pa.table({'time': pa.array([], pa.float64())}), empty)
    no_time = tmp_path / 'no_time.parquet'
    pq.write_table(pa.table({'t': [0.0]}), no_time)
    text = tmp_path / 'text.parquet'
    text.write_bytes(b'PAR1 not really')
    assert archive.scan_pass(str(empty)).endswith('no rows')
    assert "column 'time'" in archive.scan_pass(str(no_time))
    assert archive.scan_pass(str(text)).startswith('unreadable:')


@pytest.mark.parametrize('times', [[7.5, 8.0], [0.0, 0.1], [-3.25, -1.0], [1, 2],
                                   [None, 1.0], [np.nan, 1.0]])
def test_scan_of_parquet_gives_the_first_stamp_with_or_without_statistics(tmp_path, times):
    """The footer's smallest time is used only where it is the first stamp's value."""
    found = []
    for stats in (True, False):
        path = tmp_path / f'stats_{stats}.parquet'
        pq.write_table(pa.table({'time': times, 'rw1_speed': [1.0, 2.0]}), path,
                       write_statistics=stats)
        found.append(archive.scan_pass(str(path)))
    with_stats, without = found
    if times[0] is None:
        assert with_stats.endswith('not a number') and without.endswith('not a number')
    elif np.isnan(times[0]):
        # Statistics leave NaN out: the smallest finite stamp orders a file the reader
        # refuses (time must be finite), which is not examined either way.
        assert with_stats.first == 1.0 and np.isnan(without.first)
        with pytest.raises(TelemetrySchemaError, match='finite'):
            read_telemetry(tmp_path / 'stats_True.parquet')
    else:
        assert repr(with_stats.first) == repr(without.first) == repr(float(times[0]))


def test_rows_at_or_before_the_last_time_are_dropped(record):
    kept, dropped = archive.after(record, 2.0)
    assert dropped == 21 and kept.time[0] == pytest.approx(2.1)
    assert len(kept.wheels['rw1'].friction) == len(kept) == len(record) - 21
    same, none = archive.after(record, -np.inf)
    assert same is record and none == 0


def test_events_parquet_takes_fields_of_mixed_types_and_of_every_row():
    import io
    from rwa_monitor.fleet.history import parquet
    rows = [{'spacecraft': 'a', 'x': 1.5, 'y': None}, {'spacecraft': 'b', 'x': 'text',
                                                       'y': [1, 2], 'final': True}]
    table = pq.read_table(io.BytesIO(parquet(rows, {})))
    assert table.column('x').to_pylist() == ['1.5', '"text"']
    assert table.column('y').to_pylist() == [None, '[1, 2]']
    assert table.column('final').to_pylist() == [None, True]   # a field the first row lacks


def test_listing_takes_each_kind_of_pass_with_its_size_and_names_the_rest(tmp_path):
    craft = tmp_path / 'archive' / 'sc1'
    bag = craft / 'bag1'
    bag.mkdir(parents=True)
    meta = b'rosbag2_bagfile_information: {}\n'
    (bag / 'metadata.yaml').write_bytes(meta)
    (bag / 'bag1_0.mcap').write_bytes(b'x' * 7)
    files = {'a.csv': 3, 'b.PARQUET': 5, 'c.mcap': 2, 'd.db3': 4, 'e.bin': 6, 'notes.txt': 1,
             '.hidden.csv': 1, 'calibration.yaml': 1, 'e.xml': 1, 'e_map.yaml': 1}
    for name, size in files.items():
        (craft / name).write_bytes(b'x' * size)
    (craft / 'folder.csv').mkdir()           # a folder is no CSV file, whatever its name
    (craft / 'gone.csv').symlink_to(craft / 'missing.csv')
    [found] = archive.list_archive(tmp_path / 'archive')
    names = {c.rsplit('/', 1)[1]: found.sizes[c] for c in found.candidates}
    assert names == {'a.csv': 3, 'b.PARQUET': 5, 'bag1': 7 + len(meta), 'c.mcap': 2,
                     'd.db3': 4, 'e.bin': 6}     # a folder: the size of its files
    assert found.candidates == sorted(found.candidates)
    assert set(found.ignored) == {'notes.txt', 'folder.csv', 'gone.csv'}
    assert found.calibration == str(craft / 'calibration.yaml')
