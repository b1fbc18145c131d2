"""Calibration files: commissioning (write), loading (checked) and the calibrated LLR run.

``commission(tele_list)`` calls core/calibrate.py per wheel on the concatenated records;
``write(cal, out_dir)`` writes ``calibration.yaml`` and ``report.md`` with plots;
``load(path)`` returns the checked ``calibration`` mapping (ConfigError naming the file
and the key). The calibrated LLR run (model (1) on the residual against the calibrated
nominal, docs/llr.md "Calibrated") is the wheel runner's (core/wheel_runner.py).
"""

from __future__ import annotations

import pathlib
from typing import Any, Mapping, Sequence

import numpy as np

from rwa_monitor.core import calibrate as core
from rwa_monitor.core.calibration_values import check_values
from rwa_monitor.core.coverage import (Coverage, judge, llr_samples_needed,
                                       MOSTLY_UNTESTED_SHARE, NOT_EXAMINED)
from rwa_monitor.core.identify.model import plain
from rwa_monitor.core.nominal import tested_text
from rwa_monitor.exceptions import ConfigError, NotExaminedError
from rwa_monitor.telemetry import Telemetry
from rwa_monitor.telemetry.atomic import atomic_write, child, FolderOutput, write_text_atomic
from rwa_monitor.telemetry.calibration_file import load

KEY = 'calibration_file'
# What a calibration folder holds (an existing folder with anything else is not replaced).
FILES = ('calibration.yaml', 'report.md', '*_friction.png')


def commission(records: Sequence[Telemetry]
               ) -> tuple[dict[str, Any], list[str], dict[str, dict]]:
    """Return (calibration document, warnings, arrays for the report) from records.

    Records are calibrated wheel by wheel; several records of one spacecraft are
    concatenated per wheel (a time gap between them is harmless: the nominal model is
    static). Every record must have the same wheels (ConfigError naming them). A wheel
    with too few usable samples (:func:`wheel_coverage`) is left out and named in the
    document's ``not_examined``; records without samples add nothing and are left out
    (NotExaminedError if all are empty).
    """
    if not records:
        raise ConfigError('calibrate: no telemetry file given')
    if not any(len(r) for r in records):
        raise NotExaminedError(', '.join(str(r.source) for r in records) + ': no samples; '
                               f'a calibration needs at least {samples_needed()} per wheel')
    records = [r for r in records if len(r)]
    names = list(records[0].wheels)
    for tele in records[1:]:
        if list(tele.wheels) != names:
            raise ConfigError(f'{tele.source}: wheels {", ".join(tele.wheels)} differ from '
                              f'{records[0].source}: {", ".join(names)}')
    wheels: dict[str, Any] = {}
    warnings: list[str] = []
    arrays: dict[str, dict] = {}
    not_examined: dict[str, str] = {}
    for name in names:
        if records[0].wheels[name].friction is None:
            warnings.append(f'{name}: no friction column; not calibrated')
            continue
        t = np.concatenate([np.asarray(r.time, dtype=float) for r in records])
        w = np.concatenate([np.asarray(r.wheels[name].speed, dtype=float) for r in records])
        f = np.concatenate([np.asarray(r.wheels[name].friction, dtype=float)
                            for r in records])
        verdict = wheel_coverage(t, w, f)
        if verdict.verdict == NOT_EXAMINED:
            not_examined[name] = verdict.reason
            warnings.append(f'{name}: not calibrated: {verdict.reason}')
            continue
        block, found = _calibrate_wheel(name, t, w, f)
        wheels[name] = block
        warnings += found
        arrays[name] = {'time': t, 'speed': w, 'friction': f}
    first = records[0]
    gyro_verdict = gyro_coverage(first)
    gyro: dict[str, Any] = {}
    if gyro_verdict is not None and gyro_verdict.verdict == NOT_EXAMINED:
        not_examined['gyro'] = gyro_verdict.reason
        warnings.append(f'gyro: not calibrated: {gyro_verdict.reason}')
    else:
        gyro = core.calibrate_gyro(first.time, _stack(first, 'gyro'), _stack(first, 'q'),
                                   _stack(first, 'ref'))
    sources = [{'file': str(r.source), 'time_s': [float(r.time[0]), float(r.time[-1])],
                'samples': len(r)} for r in records]
    document = {'calibration': {'version': core.VERSION, 'sources': sources,
                                'wheels': wheels, 'gyro': gyro, 'warnings': warnings}}
    if not_examined:
        document['calibration']['not_examined'] = not_examined
    return document, warnings, arrays


def samples_needed() -> int:
    """Return the finite samples a wheel's calibration needs.

    The calibration checks its own data with the calibrated LLR detector at its default
    parameters (:func:`rwa_monitor.core.calibrate.calibrate_wheel`), whose first test
    needs ``2 window + 1`` samples (core/coverage.py ``llr_samples_needed``); the
    identification needs fewer (core/identify/data.py MIN_SAMPLES).
    """
    from rwa_monitor.core.identify.data import MIN_SAMPLES
    from rwa_monitor.core.schema import LLR
    return max(MIN_SAMPLES, llr_samples_needed(LLR.defaults()))


def wheel_coverage(time: np.ndarray, speed: np.ndarray, friction: np.ndarray) -> Coverage:
    """Return whether a wheel's commissioning data are enough to calibrate it."""
    usable = int(np.count_nonzero(np.isfinite(time) & np.isfinite(speed)
                                  & np.isfinite(friction)))
    return judge(time.size, usable, samples_needed(), 'the calibration (its LLR self-check)')


def gyro_coverage(tele: Telemetry) -> Coverage | None:
    """Return whether the record's gyro is enough to calibrate (None: no gyro to calibrate).

    The gyro calibration (core/gyro_calibration.py) needs ``2 DETREND_BLOCKS`` blocks of
    ``DEFAULT_BLOCK`` gyro/star-tracker steps on every axis; usable rows: time, the
    quaternion and the axis all finite (the worst axis counts).
    """
    gyro, quat = _stack(tele, 'gyro'), _stack(tele, 'q')
    if gyro is None or quat is None:
        return None
    from rwa_monitor.core.gyro_calibration import DEFAULT_BLOCK, DETREND_BLOCKS
    rows = np.isfinite(np.asarray(tele.time, dtype=float)) & np.all(np.isfinite(quat), axis=1)
    usable = int(np.min(np.count_nonzero(rows[:, None] & np.isfinite(gyro), axis=0)))
    needed = 2 * DETREND_BLOCKS * DEFAULT_BLOCK + 1
    return judge(len(tele), usable, needed, 'the gyro calibration')


def untested_shares(document: Mapping[str, Any],
                    share: float = MOSTLY_UNTESTED_SHARE) -> list[str]:
    """Return one message per wheel that would leave more than ``share`` of its data untested.

    The detectors never test a sample inside the band: a band that swallows most of the
    commissioning data makes every later verdict ``unknown``, and is the mark of speeds
    in other units (normalised, or per cent of the top speed), hence the hint. Nor do they
    test a speed where the commissioning did not determine the nominal
    (``tested_speeds_rad_s``): too few samples per speed for the model's parameters.
    """
    messages = []
    for name, block in document['calibration']['wheels'].items():
        band = block['noise']['low_speed_band']
        inside, total = int(band.get('samples', 0)), int(block.get('samples', 0))
        tested = int(block.get('tested_samples', total - inside))
        if total and inside <= share * total and total - tested > share * total:
            messages.append(
                f'{name}: the nominal model is determined well enough to be tested at '
                f'speeds holding only {tested} of {total} samples ({tested / total:.0%}; '
                f'{tested_text([tuple(v) for v in block["tested_speeds_rad_s"]])}): the '
                f'detectors would leave the others untested; commission with more data '
                f'at each speed (docs/calibration.md, "Where the nominal is tested")')
        if total and inside > share * total:
            top = max(abs(v) for v in block['speed_range_rad_s'])
            hint = (f'speeds reach only {top:.3g} rad/s: is the file in rad/s?'
                    if top <= core.MAX_BAND_RAD_S else
                    'commission with data in which the wheels spin')
            messages.append(
                f'{name}: the low-speed band |speed| < {band["speed_abs_below_rad_s"]:g} '
                f'rad/s holds {inside} of {total} samples ({inside / total:.0%}, more than '
                f'{share:.0%}): the detectors would leave them untested; {hint}')
    return messages


def _calibrate_wheel(name: str, t: np.ndarray, w: np.ndarray, f: np.ndarray
                     ) -> tuple[dict[str, Any], list[str]]:
    """Return core.calibrate_wheel's result; ConfigError for values no wheel can have.

    The plausibility limits are the detector's own (max_abs_speed, max_abs_friction of
    the llr_detector schema): a sample beyond them is one the detector would never test,
    so a nominal model fitted on it (or overflowing on it) is refused, naming the column.
    """
    from rwa_monitor.core.schema import LLR
    for column, values, limit, unit in (
            ('speed', w, LLR['max_abs_speed'].default, 'rad/s'),
            ('friction', f, LLR['max_abs_friction'].default, 'N m')):
        with np.errstate(invalid='ignore'):
            top = np.max(np.abs(values), initial=0.0, where=np.isfinite(values))
        if not top < limit:
            raise ConfigError(f'{name}_{column}: values up to {top:g} {unit} are not '
                              f'physical (the detector ignores |{column}| >= {limit:g} '
                              f'{unit}): check the column and its unit')
    try:
        return core.calibrate_wheel(name, t, w, f)
    except OverflowError as err:
        raise ConfigError(f'{name}: the calibration overflows on these values ({err}); '
                          'check the units of the speed and friction columns') from None


def _stack(tele: Telemetry, prefix: str) -> np.ndarray | None:
    value = getattr(tele, {'gyro': 'gyro', 'q': 'attitude', 'ref': 'reference_rate'}[prefix],
                    None)
    return None if value is None else np.asarray(value, dtype=float)


def write(document: Mapping[str, Any], arrays: Mapping[str, dict], out_dir: pathlib.Path
          ) -> list[pathlib.Path]:
    """Write calibration.yaml, report.md and one PNG per wheel; return the paths.

    The folder is built beside ``out_dir`` and swapped in whole (telemetry/atomic.py
    FolderOutput): a failure leaves the previous folder as it was, and a folder holding
    other files than these is refused. A document with a value the loader would refuse
    (non-finite, out of range: core/calibration_values.py) is refused before anything is
    written (ConfigError naming the key).
    """
    import yaml
    check_values(document.get('calibration', {}), 'calibrate: the fitted calibration')
    with FolderOutput(out_dir, FILES, 'calibrate outputs') as work:
        text = yaml.safe_dump(plain(document), sort_keys=False)
        names = _write_files(document, arrays, work, text)
    return [pathlib.Path(out_dir) / name for name in names]


def _write_files(document: Mapping[str, Any], arrays: Mapping[str, dict],
                 out_dir: pathlib.Path, text: str) -> list[str]:
    cal_path = out_dir / 'calibration.yaml'
    write_text_atomic(cal_path, text)
    written = [cal_path]
    cal = document['calibration']
    lines = ['# Commissioning calibration', '',
             'Sources: ' + ', '.join(f'{s["file"]} ({s["samples"]} samples, '
                                     f'{s["time_s"][0]:.1f}-{s["time_s"][1]:.1f} s)'
                                     for s in cal['sources']), '']
    if cal.get('warnings'):
        lines += ['## Warnings', ''] + [f'- {w}' for w in cal['warnings']] + ['']
    lines += ['| wheel | effects | dry (N m) | viscous (N m s/rad) | noise std (N m) | '
              'low-speed band (rad/s) | band std (N m) | speed range (rad/s) |',
              '|---|---|---|---|---|---|---|---|']
    for name, block in cal['wheels'].items():
        model, noise = block['friction_model'], block['noise']
        band = noise['low_speed_band']
        effects = ', '.join(e['name'] for e in model.get('effects') or []) or 'none'
        lo, hi = block['speed_range_rad_s']
        lines.append(f'| {name} | {effects} | {model["weights"]["dry"]:.3g} | '
                     f'{model["weights"]["viscous"]:.3g} | {noise["std_nm"]:.3g} | '
                     f'{band["speed_abs_below_rad_s"]:g} | {band["std_nm"]:.3g} | '
                     f'{lo:.1f} .. {hi:.1f} |')
        png = child(out_dir, name, '_friction.png')
        _plot(name, block, arrays.get(name), png)
        written.append(png)
    lines += ['', 'The detectors test changes against the nominal model; samples with '
              '|speed| below the band, or outside the speed range, are not tested '
              '(docs/llr.md, section "Calibrated").', '']
    lines += [f'![{n}]({n}_friction.png)' for n in cal['wheels']]
    lines += ['', f'Gyro: {", ".join(cal.get("gyro") or {}) or "not calibrated"}', '']
    report = out_dir / 'report.md'
    write_text_atomic(report, '\n'.join(lines))
    written.append(report)
    return [path.name for path in written]


def _plot(name: str, block: Mapping[str, Any], data: dict | None,
          path: pathlib.Path) -> None:
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(8, 6.5))
    if data is not None:
        ok = np.isfinite(data['speed']) & np.isfinite(data['friction'])
        w, f = data['speed'][ok], data['friction'][ok]
        top.plot(w, f, ',', color='0.6', label='measured')
        band = block['noise']['low_speed_band']['speed_abs_below_rad_s']
        grid = np.linspace(np.min(w), np.max(w), 2000)
        nominal = core.nominal_prediction(block['friction_model'], grid)
        nominal[np.abs(grid) < band] = np.nan   # fitted and used outside the band only
        top.plot(grid, nominal, 'C0', label='nominal model (tested speeds)')
    band = block['noise']['low_speed_band']['speed_abs_below_rad_s']
    for ax in (top, bottom):
        if band > 0:
            ax.axvspan(-band, band, color='C3', alpha=0.15, label='low-speed band')
    top.set_ylabel('friction (N m)')
    top.legend(loc='best', fontsize=8)
    top.set_title(f'{name}: nominal friction and noise profile')
    prof = block['noise']['profile']
    mids = [0.5 * (p['speed_abs_from_rad_s'] + p['speed_abs_to_rad_s']) for p in prof]
    bottom.semilogy(mids, [p['rms_nm'] for p in prof], 'o-', label='residual RMS per |w| bin')
    bottom.axhline(block['noise']['std_nm'], color='k', ls='--', label='reference std')
    bottom.set_xlabel('|speed| (rad/s), bins; speed (rad/s) above')
    bottom.set_ylabel('N m')
    bottom.legend(loc='best', fontsize=8)
    fig.tight_layout()
    with atomic_write(path, 'wb', encoding=None) as handle:
        fig.savefig(handle, format='png', dpi=90)
    plt.close(fig)


def diagnose_wheel(block: Mapping[str, Any], time: np.ndarray, speed: np.ndarray,
                   friction: np.ndarray, classifier: Any, config: Any) -> dict[str, Any]:
    """Return the window diagnosis of one wheel relative to its nominal (core function)."""
    return core.diagnose_fss(block, time, speed, friction, classifier, config)


__all__ = ['commission', 'diagnose_wheel', 'load', 'untested_shares', 'write']
