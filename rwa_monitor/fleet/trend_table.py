"""The trend table: every pass's friction levels of every wheel, held as columns.

A fleet's state keeps one row per spacecraft, wheel and pass for as long as it runs (a
year of 100 spacecraft, 4 wheels and 6 passes a day: 876,000 rows), and a daily run reads
it, adds its passes, fits each wheel's trend, draws the report and writes it twice
(trend.parquet of the outputs and of the state). Held as one Python object per row, that
work took 14 s of a daily run's 21 s at a year's end (bench fleet_year); as numpy columns
read and written by pyarrow it is a few vectorised passes. :class:`TrendRow` stays the
row a task hands back (fleet/records.py); the table gathers them.
"""

from __future__ import annotations

import io
import math
from typing import Any, Iterable, Iterator, Mapping, Sequence

import numpy as np

from rwa_monitor.fleet.records import TrendRow

# trend.parquet's columns and Arrow types (docs/contracts.md "Fleet outputs").
COLUMNS = {'spacecraft': 'string', 'wheel': 'string', 'pass': 'string',
           't_start': 'float64', 't_end': 'float64', 'samples': 'int64',
           'dry': 'float64', 'dry_se': 'float64', 'viscous': 'float64',
           'viscous_se': 'float64', 'relative_to': 'string'}
TEXT = tuple(k for k, v in COLUMNS.items() if v == 'string')
ATTRIBUTES = {'pass': 'pass_name'}     # the column whose TrendRow field is named otherwise


class TrendTable:
    """Trend rows as columns of :data:`COLUMNS`: numpy arrays, and an Arrow table.

    A table is not changed once made (``plus``, ``sorted`` and ``take`` make new ones):
    its Parquet bytes and its groups by wheel are made once, at the first call (a
    daily run late in the year writes 876,000 rows to its outputs and to its state,
    and groups them for the trends and for the report). A table read from Parquet keeps
    pyarrow's columns, and reading, appending, ordering, taking and writing it stay in
    them: its text columns (a name per pass) become Python strings only when
    :attr:`columns` is first asked for, where a year's table took 0.5 s to convert each
    way.
    """

    def __init__(self, columns: Mapping[str, Any] | None = None, *,
                 arrow: Any = None) -> None:
        self._columns: dict[str, np.ndarray] | None = None
        self._arrow = arrow
        self._parquet: bytes | None = None
        self._groups: dict[tuple[str, str], dict[str, np.ndarray]] | None = None
        self._ordered = False       # made by sorted(): already in by_wheel's order
        if arrow is not None:
            return
        columns = columns or {}
        missing = [k for k in COLUMNS if k not in columns]
        if missing:
            raise ValueError(f'a trend table needs the columns {", ".join(missing)}')
        sizes = {len(columns[k]) for k in COLUMNS}
        if len(sizes) > 1:
            raise ValueError('the columns of a trend table differ in length')
        self._columns = {k: _typed(k, columns[k]) for k in COLUMNS}

    @property
    def columns(self) -> dict[str, np.ndarray]:
        """Return the columns as numpy arrays (text as object arrays of str)."""
        if self._columns is None:
            self._columns = {k: _numpy(self._arrow.column(k), COLUMNS[k]) for k in COLUMNS}
        return self._columns

    def column(self, name: str) -> np.ndarray:
        """Return one column as numpy (without making the others: see :attr:`columns`)."""
        if self._columns is None:
            return _numpy(self._arrow.column(name), COLUMNS[name])
        return self._columns[name]

    def arrow(self) -> Any:
        """Return the table as a ``pyarrow.Table`` of :data:`COLUMNS` (no nulls)."""
        if self._arrow is None:
            import pyarrow as pa
            self._arrow = pa.table({k: pa.array(self._columns[k], type=_arrow_type(k))
                                    for k in COLUMNS})
        return self._arrow

    @classmethod
    def empty(cls) -> 'TrendTable':
        """Return a table without rows."""
        return cls({k: [] for k in COLUMNS})

    @classmethod
    def from_rows(cls, rows: Iterable[TrendRow]) -> 'TrendTable':
        """Return the table of these rows, in their order."""
        rows = list(rows)
        return cls({k: [getattr(r, ATTRIBUTES.get(k, k)) for r in rows] for k in COLUMNS})

    @classmethod
    def of(cls, rows: 'TrendTable | Iterable[Mapping[str, Any]]') -> 'TrendTable':
        """Return ``rows`` as a table: a table as it is, mappings as TrendRow reads them."""
        if isinstance(rows, TrendTable):
            return rows
        return cls.from_rows(TrendRow.from_fields(r) for r in rows)

    @classmethod
    def from_parquet(cls, data: bytes) -> 'TrendTable':
        """Return the table of trend.parquet's bytes (ValueError if it is not one).

        Nulls read as NaN (numbers), 0 (``samples``) and '' (text), as TrendRow does.
        """
        import pyarrow as pa
        import pyarrow.parquet as pq
        try:
            table = pq.read_table(io.BytesIO(data))
            missing = [k for k in COLUMNS if k not in table.column_names]
            if missing:
                raise ValueError(f'no column {", ".join(missing)}')
            out = {}
            for name, kind in COLUMNS.items():
                column = table.column(name).cast(_arrow_type(name))
                fill = '' if kind == 'string' else 0 if kind == 'int64' else math.nan
                out[name] = column.fill_null(fill) if column.null_count else column
        except (pa.ArrowException, OSError) as err:
            raise ValueError(f'not a trend table: {err}') from None
        return cls(arrow=pa.table(out))

    def to_parquet(self) -> bytes:
        """Return the table as trend.parquet's bytes (the columns and types of COLUMNS)."""
        if self._parquet is None:
            import pyarrow.parquet as pq
            buffer = io.BytesIO()
            pq.write_table(self.arrow(), buffer)
            self._parquet = buffer.getvalue()
        return self._parquet

    def __len__(self) -> int:
        if self._columns is None:
            return self._arrow.num_rows
        return len(self._columns['t_start'])

    def __iter__(self) -> Iterator[TrendRow]:
        cols = [self.columns[k] for k in COLUMNS]
        for values in zip(*cols):
            yield TrendRow(*(v.item() if isinstance(v, np.generic) else v for v in values))

    def plus(self, rows: 'TrendTable | Iterable[TrendRow]') -> 'TrendTable':
        """Return this table with ``rows`` appended."""
        import pyarrow as pa
        other = rows if isinstance(rows, TrendTable) else TrendTable.from_rows(rows)
        return TrendTable(arrow=pa.concat_tables([self.arrow(), other.arrow()]))

    def sorted(self) -> 'TrendTable':
        """Return the rows ordered by spacecraft, wheel, start time and pass (stable)."""
        ordered = self.take(self._order(('spacecraft', 'wheel', 't_start', 'pass')))
        ordered._ordered = True
        return ordered

    def take(self, index: np.ndarray) -> 'TrendTable':
        """Return the rows at ``index``."""
        return TrendTable(arrow=self.arrow().take(index))

    def by_wheel(self) -> dict[tuple[str, str], dict[str, np.ndarray]]:
        """Return each (spacecraft, wheel)'s columns, its rows in start-time order.

        The groups come in (spacecraft, wheel) order; rows of equal start time keep
        their order in the table. The same groups at every call: read them, do not change
        them.
        """
        if self._groups is None:
            self._groups = self._by_wheel()
        return self._groups

    def _by_wheel(self) -> dict[tuple[str, str], dict[str, np.ndarray]]:
        import pyarrow.compute as pc
        if not len(self):
            return {}
        ordered = self if self._ordered else self.take(
            self._order(('spacecraft', 'wheel', 't_start')))
        table = ordered.arrow()
        key = pc.binary_join_element_wise(table.column('spacecraft'),
                                          table.column('wheel'), '\x00')
        changed = pc.not_equal(key.slice(1), key.slice(0, len(key) - 1))
        cuts = np.flatnonzero(changed.to_numpy(zero_copy_only=False)) + 1
        starts = np.concatenate([[0], cuts])
        ends = np.concatenate([cuts, [len(ordered)]])
        c = ordered.columns
        return {(str(c['spacecraft'][a]), str(c['wheel'][a])): {k: v[a:b] for k, v in c.items()}
                for a, b in zip(starts, ends)}

    def _order(self, keys: Sequence[str]) -> np.ndarray:
        """Return the stable ascending order of the rows by ``keys`` (NaN times last).

        Sorted by pyarrow: 0.12 s for a year's 876,000 rows, against 1.1 s for numpy's
        lexsort of the text columns as Python strings.
        """
        import pyarrow.compute as pc
        return pc.sort_indices(self.arrow().select(list(keys)),
                               sort_keys=[(k, 'ascending') for k in keys]).to_numpy()

    def span(self) -> tuple[float, float] | None:
        """Return the earliest finite start and the latest finite end (None if none)."""
        starts, ends = self.column('t_start'), self.column('t_end')
        starts, ends = starts[np.isfinite(starts)], ends[np.isfinite(ends)]
        if not (starts.size and ends.size):
            return None
        return float(starts.min()), float(ends.max())

    def fields(self) -> list[dict[str, Any]]:
        """Return the rows as trend.parquet's mappings (for small tables and tests)."""
        return [row.fields() for row in self]


def _typed(name: str, values: Sequence[Any] | np.ndarray) -> np.ndarray:
    """Return a column as its numpy form: object (text), int64 or float64."""
    kind = COLUMNS[name]
    if kind == 'string':
        if isinstance(values, np.ndarray) and values.dtype == object:
            return values
        out = np.empty(len(values), dtype=object)
        out[:] = [str(v) for v in values]
        return out
    return np.asarray(values, dtype=np.int64 if kind == 'int64' else float).reshape(-1)


def _arrow_type(name: str) -> Any:
    import pyarrow as pa
    return getattr(pa, COLUMNS[name])()


def _numpy(column: Any, kind: str) -> np.ndarray:
    """Return an Arrow column without nulls as :func:`_typed` gives it."""
    if kind == 'string':
        return column.to_numpy(zero_copy_only=False).astype(object, copy=False)
    return column.to_numpy()
