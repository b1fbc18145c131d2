"""Fault cases of honest verdicts (issue 24, items 4 and 5): each through the real CLI.

``CASES``: (name, function); each function is given a fresh temporary directory, writes
its input there with ``rwa-monitor simulate`` (or from a simulated file), runs the
commands through :func:`rwa_monitor.cli.main.main` (a subprocess where stderr and the
process exit code matter), and returns a one-line outcome; it raises AssertionError when
the behaviour is wrong. bench/bench_faults.py runs them beside the other fault cases and
test/test_verdicts.py runs each as a test. Exit codes: docs/usage.md, "Exit codes and
verdicts".
"""

from __future__ import annotations

import contextlib
import io
import json
import pathlib
import subprocess
import sys
from typing import Callable

import numpy as np

from rwa_monitor.cli.main import main
from rwa_monitor.telemetry import read_telemetry, write_telemetry

NOTHING_FOUND, ERROR, NOT_EXAMINED = 0, 2, 3


def _run(*argv: str) -> tuple[int, str, str]:
    """Run ``rwa-monitor ARGV`` in this process; return (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def _process(*argv: str) -> subprocess.CompletedProcess:
    """Run ``rwa-monitor ARGV`` as its own process (exit code and stderr as a user sees)."""
    return subprocess.run([sys.executable, '-m', 'rwa_monitor.cli.main', *argv],
                          capture_output=True, text=True, timeout=300)


def _expect(code: int, wanted: int, what: str, err: str = '') -> None:
    assert code == wanted, f'{what}: exit {code}, expected {wanted}; stderr: {err[-300:]}'


def _wheels(folder: pathlib.Path, seconds: int = 240) -> pathlib.Path:
    """Write a fault-free two-wheel friction file (10 Hz) and return its path."""
    path = folder / 'wheels.csv'
    code, _, err = _run('simulate', 'friction', '--wheels', '2', '--seconds', str(seconds),
                        '--rate', '10', '--seed', '24', '-o', str(path))
    _expect(code, 0, 'simulate friction', err)
    return path


def _head(path: pathlib.Path, rows: int, name: str) -> pathlib.Path:
    """Write the header and the first ``rows`` rows of a CSV file to ``name``."""
    lines = path.read_text().splitlines(keepends=True)
    out = path.with_name(name)
    out.write_text(''.join(lines[:1 + rows]))
    return out


def _detect(path: pathlib.Path, *extra: str) -> tuple[int, dict]:
    out = path.with_name(path.stem + '_events.json')
    code, _, err = _run('detect', str(path), *extra, '-o', str(out))
    assert code in (0, 1, 3), f'detect {path.name}: exit {code}: {err[-300:]}'
    return code, json.loads(out.read_text())['summary']


def _diagnose(path: pathlib.Path, *extra: str) -> tuple[int, dict, str]:
    out = path.with_name(path.stem + '_diagnosis.json')
    code, stdout, err = _run('diagnose', str(path), *extra, '-o', str(out))
    assert code in (0, 1, 3), f'diagnose {path.name}: exit {code}: {err[-300:]}'
    return code, json.loads(out.read_text()), stdout


def header_only_detect(folder: pathlib.Path) -> str:
    """Check a header-only file: detect and diagnose exit 3, every wheel not examined."""
    path = _head(_wheels(folder, 60), 0, 'header_only.csv')
    code, summary = _detect(path)
    _expect(code, NOT_EXAMINED, 'detect on a header-only file')
    assert set(summary['not_examined']) == {'rw1', 'rw2'}, summary['not_examined']
    assert '0 usable samples of 0' in summary['not_examined']['rw1']
    code, document, _ = _diagnose(path)
    _expect(code, NOT_EXAMINED, 'diagnose on a header-only file')
    assert set(document['not_examined']) == {'rw1', 'rw2'}
    return 'detect 3, diagnose 3: rw1, rw2 not examined (0 usable samples of 0)'


def too_short_detect(folder: pathlib.Path) -> str:
    """Check 19 rows, fewer than the LLR's first test (2 window + 1 = 1001): exit 3."""
    path = _head(_wheels(folder, 60), 19, 'short.csv')
    code, summary = _detect(path)
    _expect(code, NOT_EXAMINED, 'detect on 19 rows')
    reason = summary['not_examined']['rw1']
    assert 'needs at least 1001' in reason, reason
    entry = summary['pipelines']['llr']['components']['rw1']
    assert (entry['verdict'], entry['usable_samples'], entry['needed_samples']) == \
        ('not_examined', 19, 1001), entry
    code, document, _ = _diagnose(path)
    _expect(code, NOT_EXAMINED, 'diagnose on 19 rows')
    return f'detect 3 ({reason}); diagnose 3'


def rejected_wheel_diagnose(folder: pathlib.Path) -> str:
    """Check rw2 with its friction all NaN: diagnose says not examined, not "none"."""
    path = folder / 'fss.csv'
    code, _, err = _run('simulate', 'fss', '--status', 'nominal,nominal', '--samples',
                        '3000', '--seed', '24', '-o', str(path))
    _expect(code, 0, 'simulate fss', err)
    tele = read_telemetry(path)
    tele.wheels['rw2'].friction[:] = np.nan
    write_telemetry(path, tele)
    code, document, stdout = _diagnose(path)
    _expect(code, NOT_EXAMINED, 'diagnose with rw2 all NaN')
    rw2 = document['wheels']['rw2']
    assert rw2['status'] == 'unknown' and not any(rw2['anomalies'].values()), rw2
    assert 'rw2: anomalies none' not in stdout and 'rw2: not examined' in stdout, stdout
    assert 'rw1' not in document['not_examined']
    return f'diagnose 3; rw2 {rw2["status"]}: {document["not_examined"]["rw2"]}'


def mostly_rejected_wheel_detect(folder: pathlib.Path) -> str:
    """Check rw1 with friction NaN on 80 % of its rows: detect says unknown, exit 3."""
    path = _wheels(folder, 600)
    tele = read_telemetry(path)
    tele.wheels['rw1'].friction[len(tele) // 5:] = np.nan
    write_telemetry(path, tele)
    code, summary = _detect(path)
    _expect(code, NOT_EXAMINED, 'detect with rw1 80 % NaN')
    entry = summary['pipelines']['llr']['components']['rw1']
    assert entry['verdict'] == 'unknown' and entry['usable_samples'] == 1200, entry
    assert summary['pipelines']['llr']['components']['rw2']['verdict'] == 'examined'
    return f'detect 3; rw1 unknown ({entry["usable_samples"]} of {entry["samples"]} usable)'


def nan_gyro_axis(folder: pathlib.Path) -> str:
    """Check gyro_y NaN after 300 s of 2400 s (1,199 of 9,600 used): unknown."""
    path = folder / 'aocs.csv'
    code, _, err = _run('simulate', 'aocs', '--seconds', '2400', '--seed', '7', '-o',
                        str(path))
    _expect(code, 0, 'simulate aocs', err)
    tele = read_telemetry(path)
    tele.gyro[tele.time >= 300.0, 1] = np.nan
    write_telemetry(path, tele)
    code, summary = _detect(path)
    _expect(code, NOT_EXAMINED, 'detect with gyro_y mostly NaN')
    axis = summary['pipelines']['vsadc']['components']['gyro_y']
    assert axis['final_state'] == 'unknown' and axis['verdict'] == 'unknown', axis
    assert summary['pipelines']['vsadc']['components']['gyro_x']['verdict'] == 'examined'
    return (f'detect 3; gyro_y unknown ({axis["usable_samples"]} of {axis["samples"]} '
            'samples usable)')


def _normalised(folder: pathlib.Path) -> pathlib.Path:
    """Write a nominal FSS record in normalised units (speed / 400, friction / 2e-4)."""
    path = folder / 'commissioning.csv'
    code, _, err = _run('simulate', 'fss', '--status', 'nominal', '--samples', '20000',
                        '--seed', '24', '-o', str(path))
    _expect(code, 0, 'simulate fss', err)
    tele = read_telemetry(path)
    wheel = tele.wheels['rw1']
    wheel.speed[:] = wheel.speed / 400.0
    wheel.friction[:] = wheel.friction / 2.0e-4
    write_telemetry(path, tele)
    return path


def normalised_units_calibrate(folder: pathlib.Path) -> str:
    """Check speeds in normalised units: calibrate refuses (exit 2) with a units hint."""
    path = _normalised(folder)
    out = folder / 'calibration'
    code, _, err = _run('calibrate', str(path), '-o', str(out))
    _expect(code, ERROR, 'calibrate on normalised speeds', err)
    assert 'is the file in rad/s?' in err and not out.exists(), err
    return 'calibrate 2, nothing written: ' + err.strip().split(': error: ', 1)[-1][:120]


def untested_window_diagnose(folder: pathlib.Path) -> str:
    """Force the calibration through: diagnose answers unknown, never nominal (exit 3)."""
    path = _normalised(folder)
    out = folder / 'calibration'
    code, _, err = _run('calibrate', str(path), '-o', str(out), '--allow-untested')
    _expect(code, NOTHING_FOUND, 'calibrate --allow-untested', err)
    assert 'WARNING' in err and 'is the file in rad/s?' in err, err
    code, document, _ = _diagnose(path, '--calibration', str(out / 'calibration.yaml'))
    _expect(code, NOT_EXAMINED, 'diagnose against the band that swallows everything')
    rw1 = document['wheels']['rw1']
    assert rw1['status'] == 'unknown', rw1['status']
    untested = rw1['calibration']['samples_not_tested']
    code, summary = _detect(path, '--calibration', str(out / 'calibration.yaml'))
    _expect(code, NOT_EXAMINED, 'detect against the band that swallows everything')
    return (f'calibrate --allow-untested warns; diagnose 3 (rw1 unknown, {untested} of '
            f'{rw1["coverage"]["samples"]} not tested); detect 3')


def too_short_identify_calibrate(folder: pathlib.Path) -> str:
    """Check 19 rows: identify and calibrate exit 3 (not examined), nothing written."""
    path = _head(_wheels(folder, 60), 19, 'short.csv')
    code, _, err = _run('identify', str(path), '-o', str(folder / 'id'))
    _expect(code, NOT_EXAMINED, 'identify on 19 rows', err)
    assert 'not examined' in err and not (folder / 'id').exists(), err
    code, _, err = _run('calibrate', str(path), '-o', str(folder / 'cal'))
    _expect(code, NOT_EXAMINED, 'calibrate on 19 rows', err)
    assert not (folder / 'cal').exists(), err
    header = _head(path, 0, 'header_only.csv')
    code, _, err = _run('calibrate', str(header), '-o', str(folder / 'cal'))
    _expect(code, NOT_EXAMINED, 'calibrate on a header-only file', err)
    return 'identify 3, calibrate 3 (19 rows and header only), nothing written'


def rejected_wheel_identify(folder: pathlib.Path) -> str:
    """Check identify --wheel all with rw2 all NaN: rw1 identified, rw2 named, exit 3."""
    path = _wheels(folder, 240)
    tele = read_telemetry(path)
    tele.wheels['rw2'].friction[:] = np.nan
    write_telemetry(path, tele)
    out = folder / 'id'
    code, _, err = _run('identify', str(path), '--wheel', 'all', '-o', str(out))
    _expect(code, NOT_EXAMINED, 'identify --wheel all with rw2 all NaN', err)
    summary = json.loads((out / 'wheels.json').read_text())
    assert set(summary['not_examined']) == {'rw2'} and (out / 'rw1' / 'report.json').exists()
    assert not (out / 'rw2').exists() and 'NOT EXAMINED rw2' in (out / 'wheels.md').read_text()
    return 'identify --wheel all 3: rw1 identified; ' + summary['not_examined']['rw2'][:80]


def too_short_gyro_calibrate(folder: pathlib.Path) -> str:
    """Check 30 s of gyro (fewer steps than the gyro calibration needs): exit 3."""
    path = folder / 'aocs.csv'
    code, _, err = _run('simulate', 'aocs', '--seconds', '30', '--seed', '7', '-o', str(path))
    _expect(code, 0, 'simulate aocs', err)
    code, _, err = _run('calibrate', str(path), '-o', str(folder / 'cal'))
    _expect(code, NOT_EXAMINED, 'calibrate on 30 s of gyro', err)
    assert 'gyro calibration needs at least' in err and not (folder / 'cal').exists(), err
    return 'calibrate 3: ' + err.strip().splitlines()[-1].split('not examined: ')[-1][:100]


def huge_header_cell(folder: pathlib.Path) -> str:
    """Check a 200 KB header cell: exit 2 and one line on stderr (never 1, "anomaly")."""
    source = _wheels(folder, 30).read_text().splitlines()
    cells = source[0].split(',')
    cells[1] += 'x' * 200_000
    path = folder / 'huge_header.csv'
    path.write_text('\n'.join([','.join(cells)] + source[1:]) + '\n')
    result = _process('detect', str(path))
    _expect(result.returncode, ERROR, 'detect with a 200 KB header cell', result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in result.stderr, result.stderr[-500:]
    return f'exit 2, one line: {lines[0][:110]}'


# A command whose reader fails in a way the package does not expect (a RuntimeError from
# inside read_telemetry), run through the real entry point in its own process.
_FAILING_READER = (
    'import sys\n'
    'import rwa_monitor.cli.cmd_detect as detect\n'
    'from rwa_monitor.cli.main import main\n'
    'def broken(*args, **kwargs):\n'
    '    raise RuntimeError("reader failed")\n'
    'detect.read_input = broken\n'
    'sys.exit(main(sys.argv[1:]))\n')


def unexpected_exception(folder: pathlib.Path) -> str:
    """Check an unexpected exception: exit 2 and one line; --debug adds the traceback."""
    path = _wheels(folder, 30)
    run = [sys.executable, '-c', _FAILING_READER]
    result = subprocess.run([*run, 'detect', str(path)], capture_output=True, text=True,
                            timeout=300)
    _expect(result.returncode, ERROR, 'detect with a failing reader', result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and 'Traceback' not in result.stderr, result.stderr[-500:]
    assert 'unexpected error: RuntimeError: reader failed' in lines[0], lines[0]
    debug = subprocess.run([*run, '--debug', 'detect', str(path)], capture_output=True,
                           text=True, timeout=300)
    _expect(debug.returncode, ERROR, '--debug detect', debug.stderr)
    assert 'Traceback' in debug.stderr
    return f'exit 2, one line: {lines[0][:110]}'


def package_error(folder: pathlib.Path) -> str:
    """Check that the package's own error (a missing file) stays exit 2, its message."""
    result = _process('detect', str(folder / 'missing.csv'))
    _expect(result.returncode, ERROR, 'detect on a missing file', result.stderr)
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and 'missing.csv' in lines[0], result.stderr
    return f'exit 2: {lines[0][:110]}'


CASES: list[tuple[str, Callable[[pathlib.Path], str]]] = [
    ('header-only file (detect, diagnose)', header_only_detect),
    ('too-short file (detect, diagnose)', too_short_detect),
    ('all-rejected wheel in diagnose', rejected_wheel_diagnose),
    ('mostly rejected wheel in detect', mostly_rejected_wheel_detect),
    ('NaN gyro axis for most of a file', nan_gyro_axis),
    ('normalised-units commissioning file (calibrate)', normalised_units_calibrate),
    ('window mostly untested (diagnose, detect)', untested_window_diagnose),
    ('too-short file (identify, calibrate)', too_short_identify_calibrate),
    ('all-rejected wheel in identify --wheel all', rejected_wheel_identify),
    ('too-short gyro record (calibrate)', too_short_gyro_calibrate),
    ('200 KB header cell', huge_header_cell),
    ('unexpected exception (a failing reader)', unexpected_exception),
    ('package error (missing file)', package_error),
]
