"""Telemetry CSV reader and writer: round trip, and errors naming file, line and column."""

import numpy as np
import pytest

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel, write_telemetry


def _record(n=50):
    rng = np.random.default_rng(1)
    t = np.arange(n) * 0.1
    return Telemetry(
        time=t,
        wheels={'rw1': Wheel(rng.normal(size=n), rng.normal(size=n)),
                'rw2': Wheel(rng.normal(size=n), rng.normal(size=n))},
        gyro=rng.normal(size=(n, 3)), attitude=rng.normal(size=(n, 4)),
        reference_rate=rng.normal(size=(n, 3)),
        aux={'rw1_temperature': rng.normal(size=n)},
        truth={'rw1_dry': np.zeros(n)})


def test_round_trip(tmp_path):
    rec = _record()
    path = tmp_path / 'a.csv'
    write_telemetry(path, rec)
    back = read_telemetry(path)
    assert list(back.columns()) == list(rec.columns())
    for name, values in rec.columns().items():
        np.testing.assert_allclose(back.columns()[name], values, rtol=1e-9, atol=1e-12)
    assert back.source == str(path)


def test_empty_cells_and_nan_are_read_as_nan(tmp_path):
    path = tmp_path / 'gap.csv'
    path.write_text('time,rw1_speed,rw1_friction\n0,1,2\n0.1,,nan\n0.2,inf,3\n')
    rec = read_telemetry(path)
    assert np.isnan(rec.wheels['rw1'].speed[1]) and np.isnan(rec.wheels['rw1'].friction[1])
    assert np.isinf(rec.wheels['rw1'].speed[2])


@pytest.mark.parametrize('text, line, column, words', [
    ('time,rw1_speed\n0,1\n0.1,abc\n', 3, 'rw1_speed', 'not a number'),
    ('time,rw1_speed\n0,1\n0.1,2,3\n', 3, None, 'expected 2 values'),
    ('time,rw1_speed\n0,1\n0,2\n', 3, 'time', 'strictly increasing'),
    ('time,rw1_speed\n0,1\n0.2,2\n0.1,2\n', 4, 'time', 'strictly increasing'),
    ('time,rw1_speed\n0,1\nnan,2\n', 3, 'time', 'finite'),
    ('rw1_speed\n1\n', 1, 'time', 'missing required column'),
    ('time,gyro_x,gyro_y\n0,1,2\n', 1, 'gyro_z', 'missing column'),
    ('time,rw1_friction\n0,1\n', 1, 'rw1_speed', 'missing column'),
    ('time,a,a\n0,1,2\n', 1, 'a', 'duplicate'),
])
def test_schema_errors_name_file_line_and_column(tmp_path, text, line, column, words):
    path = tmp_path / 'bad.csv'
    path.write_text(text)
    with pytest.raises(TelemetrySchemaError) as info:
        read_telemetry(path)
    err = info.value
    assert err.path == str(path) and err.line == line and err.column == column
    assert words in str(err) and str(path) in str(err)


def test_missing_and_empty_files(tmp_path):
    with pytest.raises(TelemetrySchemaError, match='no such file'):
        read_telemetry(tmp_path / 'absent.csv')
    empty = tmp_path / 'empty.csv'
    empty.write_text('')
    with pytest.raises(TelemetrySchemaError, match='empty file'):
        read_telemetry(empty)


def test_header_only_gives_empty_record(tmp_path):
    path = tmp_path / 'h.csv'
    path.write_text('time,rw1_speed,rw1_friction\n')
    rec = read_telemetry(path)
    assert len(rec) == 0 and 'rw1' in rec.wheels
