"""Fault cases of issue 24 items 1-4 and 7: outputs, names, journals, configuration, fuzz.

Each case is ``(name, scenario)``; ``scenario(folder)`` runs it in a fresh temporary
folder and returns a one-line outcome, raising AssertionError when the behaviour is
wrong (bench/bench_faults.py collects them). Commands run in-process through
``rwa_monitor.cli.main.main`` (exit codes as a user sees them; stderr captured).
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import pathlib
import stat
from typing import Callable

import numpy as np

from rwa_monitor.cli.main import main


def command(*argv: object) -> tuple[int, str]:
    """Run ``rwa-monitor ARGV`` in-process; return (exit code, stderr)."""
    err = io.StringIO()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
        code = main([str(a) for a in argv])
    return code, err.getvalue().strip()


def digest(folder: pathlib.Path) -> dict[str, str]:
    """Return relative path -> sha256 of every file under ``folder``."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob('*')) if p.is_file()}


def refused(code: int, err: str, expected: str) -> str:
    """Check a one-line refusal with exit 2 naming ``expected``; return its outcome text."""
    assert code == 2, f'exit {code}: {err}'
    assert expected in err, err
    assert len(err.splitlines()) == 1 and 'Traceback' not in err, err
    return f'exit 2: "{err.split("error: ", 1)[-1][:150]}"'


def wheels_csv(folder: pathlib.Path, seed: int = 1, n: int = 4000) -> pathlib.Path:
    """Write a fault-free one-wheel record (Stribeck excess) and return its path."""
    from rwa_monitor.sim.undeclared import simulate_undeclared
    from rwa_monitor.telemetry import write_telemetry
    path = folder / f'wheels_{seed}.csv'
    write_telemetry(path, simulate_undeclared('stribeck', n=n, seed=seed))
    return path


# ------------------------------------------------------------------------ 1. outputs
def symlink_output(folder: pathlib.Path) -> str:
    real = folder / 'archive' / 'events.json'
    real.parent.mkdir()
    real.write_text('old')
    link = folder / 'events.json'
    link.symlink_to(real)
    code, err = command('detect', wheels_csv(folder, n=2000), '-o', link)
    assert code in (0, 1), err
    assert link.is_symlink() and json.loads(real.read_text())
    return f'exit {code}; the link is kept and its target replaced'


def fifo_output(folder: pathlib.Path) -> str:
    fifo = folder / 'pipe'
    os.mkfifo(fifo)
    fd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        code, err = command('simulate', 'friction', '--seconds', '5', '--wheels', '1',
                            '-o', fifo)
        got = os.read(fd, 1 << 16)
    finally:
        os.close(fd)
    assert code == 0, err
    assert got.startswith(b'time,rw1_speed') and stat.S_ISFIFO(fifo.lstat().st_mode)
    return f'exit 0; {len(got)} bytes of CSV streamed into the FIFO, still a FIFO'


def dev_null_output(folder: pathlib.Path) -> str:
    codes = [command('simulate', 'friction', '--seconds', '5', '--wheels', '1', '-o',
                     os.devnull)[0],
             command('detect', wheels_csv(folder, n=2000), '-o', os.devnull)[0]]
    assert codes[0] == 0 and codes[1] in (0, 1), codes
    assert stat.S_ISCHR(pathlib.Path(os.devnull).stat().st_mode)
    return f'simulate exit {codes[0]}, detect exit {codes[1]}; /dev/null is still a device'


def umask_modes(folder: pathlib.Path) -> str:
    old = os.umask(0o022)
    try:
        code, err = command('calibrate', wheels_csv(folder), '-o', folder / 'cal')
    finally:
        os.umask(old)
    assert code == 0, err
    modes = {stat.S_IMODE(p.stat().st_mode) for p in (folder / 'cal').iterdir()}
    assert modes == {0o644}, modes
    assert stat.S_IMODE((folder / 'cal').stat().st_mode) == 0o755
    return 'umask 022: files 0644, folder 0755'


def simulate_foreign_folder(folder: pathlib.Path) -> str:
    out = folder / 'bag'
    assert command('simulate', 'friction', '--seconds', '5', '--wheels', '1', '-o', out)[0] == 0
    (out / 'notes.txt').write_text('mine')
    before = digest(out)
    outcome = refused(*command('simulate', 'friction', '--seconds', '9', '--wheels', '1',
                               '-o', out), 'notes.txt')
    assert digest(out) == before
    return outcome + '; folder byte-identical'


def calibrate_fails_mid_way(folder: pathlib.Path) -> str:
    from rwa_monitor.exceptions import OutputError
    from rwa_monitor.pipelines import calibrated
    out = folder / 'cal'
    assert command('calibrate', wheels_csv(folder), '-o', out)[0] == 0
    before = digest(out)
    other = wheels_csv(folder, seed=2)
    plot = calibrated._plot

    def broken(*args, **kwargs):
        raise OutputError('no space left on device (simulated after calibration.yaml)')
    calibrated._plot = broken
    try:
        outcome = refused(*command('calibrate', other, '-o', out), 'no space')
    finally:
        calibrated._plot = plot
    assert digest(out) == before
    assert sorted(p.name for p in folder.iterdir() if p.name.startswith('.')) == []
    return outcome + '; previous folder byte-identical, no temporary left'


def _foreign_folder(folder: pathlib.Path, name: str, foreign: str) -> str:
    """Run ``name`` (calibrate or identify) into a folder holding a file of the user's."""
    out = folder / 'out'
    out.mkdir()
    (out / foreign).write_text('mine')
    outcome = refused(*command(name, wheels_csv(folder), '-o', out), foreign)
    assert digest(out) == {foreign: hashlib.sha256(b'mine').hexdigest()}
    return outcome + '; folder untouched'


def calibrate_foreign_folder(folder: pathlib.Path) -> str:
    return _foreign_folder(folder, 'calibrate', 'thesis.tex')


def identify_foreign_folder(folder: pathlib.Path) -> str:
    return _foreign_folder(folder, 'identify', 'keep.txt')


# -------------------------------------------------------------------------- 2. names
def traversal_header(folder: pathlib.Path) -> str:
    deep = folder / 'a' / 'b'
    deep.mkdir(parents=True)
    path = deep / 'in.csv'
    source = wheels_csv(folder).read_text().splitlines()
    rows = [line + ',' + ','.join(line.split(',')[1:3]) for line in source[1:]]
    path.write_text('\n'.join([source[0] + ',../../x_speed,../../x_friction'] + rows) + '\n')
    results = []
    for argv in (('calibrate', path, '-o', deep / 'out'),
                 ('identify', path, '--wheel', 'all', '-o', deep / 'out')):
        before = sorted(str(p) for p in folder.rglob('*'))
        results.append(refused(*command(*argv), '../../x_speed'))
        assert sorted(str(p) for p in folder.rglob('*')) == before
    return results[0] + ' (calibrate and identify); nothing written'


# ----------------------------------------------------------------------- 3. journals
def journal_foreign_file(folder: pathlib.Path) -> str:
    from rwa_monitor.exceptions import JournalError
    from rwa_monitor.telemetry.alarms import AlarmStore
    path = folder / 'notes.txt'
    path.write_text('three years of notes\n')
    try:
        AlarmStore(path).load()
    except JournalError as err:
        outcome = f'JournalError: "{str(err).split(": ", 1)[-1][:110]}"'
    else:
        raise AssertionError('a foreign file was accepted as a journal')
    assert path.read_text() == 'three years of notes\n'
    return outcome + '; file untouched'


def journal_folder(folder: pathlib.Path) -> str:
    from rwa_monitor.exceptions import JournalError
    from rwa_monitor.telemetry.alarms import AlarmStore
    try:
        AlarmStore(folder).load()
    except JournalError as err:
        return f'JournalError: "{str(err).split(": ", 1)[-1][:110]}"'
    raise AssertionError('a folder was accepted as a journal')


# ---------------------------------------------------------------- 4. configuration
def alias_bomb_config(folder: pathlib.Path) -> str:
    lines = ['a0: &a0 [x]'] + [f'a{k}: &a{k} [' + ', '.join([f'*a{k - 1}'] * 10) + ']'
                               for k in range(1, 10)]
    bomb = folder / 'bomb.yaml'
    bomb.write_text('\n'.join(lines) + '\nllr_detector:\n  ros__parameters:\n'
                    '    window: *a9\n')
    return refused(*command('detect', wheels_csv(folder, n=2000), '--config', bomb),
                   'aliases expand') + ' (10^9 values, never built)'


def nan_calibration(folder: pathlib.Path) -> str:
    import yaml
    assert command('calibrate', wheels_csv(folder), '-o', folder / 'cal')[0] == 0
    path = folder / 'cal' / 'calibration.yaml'
    document = yaml.safe_load(path.read_text())
    document['calibration']['wheels']['rw1']['noise']['std_nm'] = float('nan')
    path.write_text(yaml.safe_dump(document))
    return refused(*command('detect', wheels_csv(folder, seed=3, n=2000), '--calibration',
                            path), 'noise.std_nm')


def huge_friction_column(folder: pathlib.Path) -> str:
    from rwa_monitor.telemetry import read_telemetry, write_telemetry
    tele = read_telemetry(wheels_csv(folder))
    tele.wheels['rw1'].friction = np.full(len(tele), 1e300)
    write_telemetry(folder / 'big.csv', tele)
    outcome = refused(*command('calibrate', folder / 'big.csv', '-o', folder / 'cal'),
                      'rw1_friction')
    assert not (folder / 'cal').exists()
    return outcome + '; nothing written'


def huge_header_cell(folder: pathlib.Path) -> str:
    path = folder / 'wide.csv'
    path.write_text('time,' + 'x' * 200_000 + '\n0,1\n')
    return refused(*command('detect', path), 'line 1')


# --------------------------------------------------------------------------- 7. fuzz
def random_inputs(folder: pathlib.Path, per_reader: int = 40) -> str:
    """Seeded random bytes and damaged valid files into every reader: own errors only."""
    from rwa_monitor.exceptions import RwaMonitorError
    from rwa_monitor.pipelines.llr import friction_model
    from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel, write_telemetry
    from rwa_monitor.telemetry.alarms import AlarmStore
    from rwa_monitor.telemetry.calibration_file import load
    from rwa_monitor.telemetry.fss_model import load_model
    from rwa_monitor.telemetry.parameters_file import read_parameters_file
    repo = pathlib.Path(__file__).resolve().parents[1]
    tele = Telemetry(time=np.arange(50.0), wheels={'rw1': Wheel(np.linspace(-5, 5, 50),
                                                                np.zeros(50))})
    write_telemetry(folder / 'seed.csv', tele)
    write_telemetry(folder / 'seed.mcap', tele)
    readers = {
        'csv': ('.csv', (folder / 'seed.csv').read_bytes(), read_telemetry),
        'mcap': ('.mcap', (folder / 'seed.mcap').read_bytes(), read_telemetry),
        'parameters': ('.yaml', (repo / 'config' / 'rwa_monitor.yaml').read_bytes(),
                       read_parameters_file),
        'calibration': ('.yaml', (repo / 'bench' / 'results' / 'calibration' /
                                  'calibration.yaml').read_bytes(), load),
        'friction model': ('.yaml', (repo / 'bench' / 'results' / 'identify_example_drag' /
                                     'friction_model.yaml').read_bytes(),
                           lambda p: friction_model(str(p), tele)),
        'FSS model': ('.json', (repo / 'rwa_monitor' / 'data' / 'fss_model.json').read_bytes(),
                      load_model),
        'journal': ('.jsonl', b'{"record": "acknowledged", "key": "k", "wall_time_s": 1}\n',
                    lambda p: AlarmStore(p).load()),
    }
    rng = np.random.default_rng(24)
    refusals = accepted = 0
    for name, (suffix, seed, read) in readers.items():
        for k in range(per_reader):
            data = bytearray(seed)
            if k % 2:
                data = bytearray(rng.integers(0, 256, int(rng.integers(0, 2000)),
                                              dtype=np.uint8).tobytes())
            else:
                for _ in range(3):
                    at = int(rng.integers(0, len(data) + 1))
                    data[at:at + int(rng.integers(0, 40))] = rng.integers(
                        0, 256, int(rng.integers(0, 40)), dtype=np.uint8).tobytes()
            path = folder / f'input{suffix}'
            path.write_bytes(bytes(data))
            try:
                read(path)
                accepted += 1
            except RwaMonitorError:
                refusals += 1
            except Exception as err:  # noqa: BLE001 - the finding this case looks for
                raise AssertionError(f'{name}: {type(err).__name__}: {err}') from None
    return (f'{refusals + accepted} inputs into {len(readers)} readers: {refusals} refused '
            f'with package errors, {accepted} read, 0 other exceptions')


CASES: list[tuple[str, Callable[[pathlib.Path], str]]] = [
    ('1 -o through a symbolic link', symlink_output),
    ('1 -o a FIFO', fifo_output),
    ('1 -o /dev/null', dev_null_output),
    ('1 modes of new outputs', umask_modes),
    ('1 simulate -o a recording folder holding another file', simulate_foreign_folder),
    ('1 calibrate failing mid-way over a previous calibration', calibrate_fails_mid_way),
    ('1 calibrate -o a folder holding another file', calibrate_foreign_folder),
    ('1 identify -o a folder holding another file', identify_foreign_folder),
    ('2 header ../../x_speed,../../x_friction', traversal_header),
    ('3 events_file naming a foreign file', journal_foreign_file),
    ('3 events_file naming a folder', journal_folder),
    ('4 alias bomb in --config', alias_bomb_config),
    ('4 calibration edited to .nan', nan_calibration),
    ('4 friction column of 1e300 into calibrate', huge_friction_column),
    ('4 a 200 KB header cell', huge_header_cell),
    ('7 random and damaged bytes into every reader', random_inputs),
]
