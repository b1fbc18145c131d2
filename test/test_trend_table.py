"""The fleet's trend table (fleet/trend_table.py): columns, order, groups, Parquet."""

import io
import math

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from rwa_monitor.fleet.records import TrendRow
from rwa_monitor.fleet.trend_table import COLUMNS, TrendTable


def rows():
    return [TrendRow('sc2', 'rw1', 'p3', 300.0, 360.0, 10, 1.0, 0.1, 2.0, 0.2, 'zero'),
            TrendRow('sc1', 'rw2', 'p2', 200.0, 260.0, 10, 3.0, 0.1, 4.0, 0.2, 'zero'),
            TrendRow('sc1', 'rw2', 'p1', 100.0, 160.0, 10, 5.0, 0.1, 6.0, 0.2, 'nominal'),
            TrendRow('sc1', 'rw1', 'p0', math.nan, math.nan, 0, math.nan, math.nan,
                     math.nan, math.nan, 'zero')]


def test_rows_come_back_as_they_went_in_through_parquet():
    table = TrendTable.from_rows(rows())
    back = TrendTable.from_parquet(table.to_parquet())
    assert [r.fields() for r in back][:3] == [r.fields() for r in rows()][:3]
    last = list(back)[3]
    assert last.pass_name == 'p0' and math.isnan(last.dry) and last.samples == 0
    arrow = pq.read_table(io.BytesIO(table.to_parquet()))
    assert arrow.column_names == list(COLUMNS)
    assert [str(arrow.schema.field(k).type) for k in COLUMNS] == [
        {'float64': 'double'}.get(v, v) for v in COLUMNS.values()]


def test_sorted_and_groups_follow_spacecraft_wheel_and_time():
    table = TrendTable.from_rows(rows()).sorted()
    assert [(r.spacecraft, r.wheel, r.pass_name) for r in table] == [
        ('sc1', 'rw1', 'p0'), ('sc1', 'rw2', 'p1'), ('sc1', 'rw2', 'p2'), ('sc2', 'rw1', 'p3')]
    groups = TrendTable.from_rows(rows()).by_wheel()
    assert list(groups) == [('sc1', 'rw1'), ('sc1', 'rw2'), ('sc2', 'rw1')]
    np.testing.assert_array_equal(groups[('sc1', 'rw2')]['t_start'], [100.0, 200.0])
    assert list(groups[('sc1', 'rw2')]['relative_to']) == ['nominal', 'zero']
    assert TrendTable.empty().by_wheel() == {} and TrendTable.empty().span() is None
    assert TrendTable.from_rows(rows()).span() == (100.0, 360.0)


def test_plus_appends_and_mappings_read_as_trend_rows():
    first, second = rows()[:2], rows()[2:]
    table = TrendTable.from_rows(first).plus(second)
    assert [r.fields() for r in table][:3] == [r.fields() for r in rows()][:3]
    mapped = TrendTable.of([r.fields() for r in rows()[:3]])
    assert [r.fields() for r in mapped] == [r.fields() for r in rows()[:3]]
    assert TrendTable.of(table) is table


def test_a_table_that_is_not_a_trend_table_is_refused():
    buffer = io.BytesIO()
    pq.write_table(pa.table({'spacecraft': ['sc1'], 'wheel': ['rw1']}), buffer)
    with pytest.raises(ValueError, match='no column pass'):
        TrendTable.from_parquet(buffer.getvalue())
    with pytest.raises(ValueError, match='not a trend table'):
        TrendTable.from_parquet(b'not parquet')
    with pytest.raises(ValueError, match='differ in length'):
        TrendTable({**{k: [] for k in COLUMNS}, 'dry': [1.0]})


def test_a_table_read_from_parquet_appends_orders_and_groups_as_one_made_from_rows():
    parts = [TrendTable.from_parquet(TrendTable.from_rows(rows()[i:i + 2]).to_parquet())
             for i in (0, 2)]
    joined = parts[0].plus(parts[1]).plus([rows()[0]])           # three Arrow chunks
    made = TrendTable.from_rows(rows() + [rows()[0]])
    assert [r.fields() for r in joined.sorted()][1:] == [r.fields() for r in made.sorted()][1:]
    assert joined.sorted().to_parquet() == made.sorted().to_parquet()
    for key, group in made.by_wheel().items():
        for name, values in group.items():
            np.testing.assert_array_equal(joined.by_wheel()[key][name], values)
    assert len(joined) == 5 and joined.columns['samples'].dtype == np.int64


def test_nulls_in_a_parquet_table_read_as_nan_zero_and_empty_text():
    buffer = io.BytesIO()
    pq.write_table(pa.table({k: pa.array([None], type=getattr(pa, v)()) for k, v in
                             COLUMNS.items()}), buffer)
    row, = TrendTable.from_parquet(buffer.getvalue())
    assert row.spacecraft == '' and row.samples == 0 and math.isnan(row.dry)
