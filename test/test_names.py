"""Names from data are data (issue 24, item 2): wheel ids never leave their folder.

On main 09648a8 a header ``../../x_speed,../../x_friction`` was read as wheel
``../../x`` and ``calibrate`` / ``identify --wheel all`` wrote outside ``-o``; a 200 KB
header cell was a traceback.
"""

import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.exceptions import OutputError, TelemetrySchemaError
from rwa_monitor.sim.undeclared import simulate_undeclared
from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel, write_telemetry

BAD_IDS = ['../../x', '/etc/x', 'a b', 'rw1\n', 'r\u00e9', '', 'x' * 65, '.', '..']


def _csv_with_wheels(path, ids):
    tele = simulate_undeclared('stribeck', n=3000, seed=1)
    w = tele.wheels['rw1']
    lines = ['time,' + ','.join(f'{i}_speed,{i}_friction' for i in ids)]
    for k in range(len(tele)):
        cells = ','.join(f'{w.speed[k]!r},{w.friction[k]!r}' for _ in ids)
        lines.append(f'{tele.time[k]!r},{cells}')
    path.write_text('\n'.join(lines) + '\n')
    return path


@pytest.mark.parametrize('wheel_id', [i for i in BAD_IDS if i and '\n' not in i])
def test_a_wheel_id_that_is_not_a_name_is_refused_naming_the_column(tmp_path, wheel_id):
    path = tmp_path / 'bad.csv'
    path.write_text(f'time,{wheel_id}_speed,{wheel_id}_friction\n0,1,0\n1,2,0\n')
    with pytest.raises(TelemetrySchemaError) as err:
        read_telemetry(path)
    assert f'{wheel_id[:80]}_speed' in str(err.value) and 'line 1' in str(err.value)


@pytest.mark.parametrize('command', [['calibrate'], ['identify', '--wheel', 'all']])
def test_commands_never_write_outside_their_folder(tmp_path, command, capsys):
    deep = tmp_path / 'a' / 'b'
    deep.mkdir(parents=True)
    path = _csv_with_wheels(deep / 'in.csv', ['rw1', '../../x'])
    flag = '-o' if command[0] == 'calibrate' else '--out'
    assert main([*command, str(path), flag, str(deep / 'out')]) == 2
    assert '../../x_speed' in capsys.readouterr().err
    written = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob('*'))
    assert written == ['a', 'a/b', 'a/b/in.csv']


def test_a_recording_with_a_bad_joint_name_is_refused(tmp_path):
    tele = Telemetry(time=np.arange(3.0), wheels={'../x': Wheel(np.ones(3), np.zeros(3))})
    write_telemetry(tmp_path / 'bag', tele)
    with pytest.raises(TelemetrySchemaError, match='joint name'):
        read_telemetry(tmp_path / 'bag')


def test_a_huge_header_cell_is_a_clear_error(tmp_path):
    path = tmp_path / 'huge.csv'
    path.write_text('time,' + 'x' * 200_000 + '\n0,1\n')
    with pytest.raises(TelemetrySchemaError, match='huge.csv, line 1'):
        read_telemetry(path)
    path.write_text('time,rw1_speed\n0,' + 'x' * 300_000 + '\n')
    with pytest.raises(TelemetrySchemaError, match='line 2'):
        read_telemetry(path)


def test_a_long_aux_column_name_is_refused(tmp_path):
    path = tmp_path / 'long.csv'
    path.write_text('time,' + 'y' * 300 + '\n0,1\n')
    with pytest.raises(TelemetrySchemaError, match='longer than 256'):
        read_telemetry(path)


def test_paths_are_built_only_from_valid_names(tmp_path):
    from rwa_monitor.telemetry.atomic import child
    assert child(tmp_path, 'rw-1_a', '.png') == tmp_path / 'rw-1_a.png'
    for name in BAD_IDS:
        with pytest.raises(OutputError, match='refusing the name'):
            child(tmp_path, name, '_friction.png')
