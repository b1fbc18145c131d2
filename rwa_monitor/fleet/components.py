"""One component's detector carried through a spacecraft's passes: the fleet's tasks.

A *chain* is a plain dict that holds one component's detector state as data (the tree
and arrays of :mod:`rwa_monitor.fleet.codec`), the spacecraft's last stamp processed and
what this run found so far (events, per-pass facts, trend rows, CPU per worker).
:func:`step` is a pure function of (spec, chain, pass): it builds a fresh detector with
the spec's parameters, restores the state into it, feeds the pass's rows after the last
stamp, and returns a new chain; its inputs are never modified, so a task lost with a
worker is simply run again with the same result.

The detectors and their feeding are those of ``rwa-monitor detect`` (pipelines/llr.py,
pipelines/calibrated.py, pipelines/vsadc.py), in their streaming form: the streaming LLR
detector gives the events of the batch path (test/test_llr.py), and the gyro diagnosis
is streaming in both. Event indices count rows from the spacecraft's first pass, as in
the passes joined into one file.
"""

from __future__ import annotations

from dataclasses import dataclass
import functools
import math
import resource
import time as _time
from typing import Any, Mapping

import numpy as np

from rwa_monitor.core.coverage import EXAMINED
from rwa_monitor.core.schema import VSADC
from rwa_monitor.core.vsadc import STATE_NAMES
from rwa_monitor.fleet import codec
from rwa_monitor.fleet.archive import after, GYRO_COMPONENT
from rwa_monitor.telemetry import Telemetry
from rwa_monitor.telemetry.streams import paired_gyro

NOT_TESTED = ('low_speed_band', 'outside_calibrated_range')


@dataclass(frozen=True)
class ComponentSpec:
    """A spacecraft's component and its detector's checked parameters (node block).

    ``params['calibration_file']`` is the spacecraft's calibration, or empty.
    """

    spacecraft: str
    component: str
    params: Mapping[str, Any]

    @property
    def detector(self) -> str:
        """Return the pipeline name: ``vsadc`` for the gyro, ``llr`` for a wheel."""
        return 'vsadc' if self.component == GYRO_COMPONENT else 'llr'


def new_chain(saved: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Return the chain before the first pass of this run (from a saved state or empty)."""
    chain: dict[str, Any] = {'detector': None, 'last_time': -math.inf, 'offset': 0,
                             'last_ref': None, 'not_tested': dict.fromkeys(NOT_TESTED, 0)}
    if saved:
        chain.update({k: v for k, v in saved.items() if k != 'history'})
    chain.update(events=[], passes=[], trend=[], facts={}, work={})
    return chain


def persistent(chain: Mapping[str, Any], history: list[dict[str, Any]]) -> dict[str, Any]:
    """Return what a state file keeps: detector, last stamp, offsets, trend rows so far."""
    kept = {k: chain[k] for k in ('detector', 'last_time', 'offset', 'last_ref',
                                  'not_tested')}
    kept['history'] = list(history) + list(chain['trend'])
    return kept


def build(spec: ComponentSpec) -> tuple[Any, Any]:
    """Return a fresh detector of the spec and the wheel's nominal model (or None)."""
    path = spec.params.get('calibration_file')
    if spec.detector == 'vsadc':
        from rwa_monitor.pipelines import vsadc
        return vsadc.make_detector(spec.params, _gyro_calibration(path) if path
                                   else None), None
    from rwa_monitor.core.llr import LLRDetector
    from rwa_monitor.pipelines import llr
    detector = LLRDetector(spec.component, **llr.detector_kwargs(spec.params))
    return detector, _nominal(path, spec.component) if path else None


@functools.lru_cache(maxsize=64)
def _nominal(path: str, wheel: str) -> Any:
    """Return a wheel's nominal model of a calibration file (read once per worker)."""
    from rwa_monitor.core.calibrate import NominalWheel
    from rwa_monitor.telemetry.calibration_file import load
    return NominalWheel(load(path)['wheels'][wheel])


@functools.lru_cache(maxsize=64)
def _gyro_calibration(path: str) -> Any:
    """Return the gyro block of a calibration file (read once per worker)."""
    from rwa_monitor.telemetry.calibration_file import load_gyro_calibration
    return load_gyro_calibration(path)


def step(spec: ComponentSpec, chain: Mapping[str, Any], reads: list[tuple[Any, dict]],
         names: list[str], count_read: bool = False, last: bool = False) -> dict[str, Any]:
    """Return the chain after passes ``names`` (``reads``: telemetry or reason, facts).

    ``count_read``: add the reads' CPU time to this chain's (one component per pass).
    ``last``: these are the run's last passes: the archive ends here, so an open
    declaration gets its end-of-record categorisation (``finish``, as ``detect`` gives at
    the end of a file; docs/llr.md "End of record"). The state kept is the one before it,
    so that a later run with new passes continues the open declaration as a full run
    would, and that run's own final word supersedes this one.
    """
    start = _time.process_time()
    out = dict(chain)
    out['events'] = list(chain['events'])
    out['passes'] = list(chain['passes'])
    out['trend'] = list(chain['trend'])
    out['not_tested'] = dict(chain['not_tested'])
    detector = nominal = None
    for (tele, _), name in zip(reads, names):
        if isinstance(tele, str):
            out['passes'].append({'pass': name, 'error': tele})
            continue
        if detector is None:
            detector, nominal = build(spec)
            if chain['detector'] is not None:
                codec.restore(detector, *chain['detector'])
        kept, dropped = after(tele, out['last_time'])
        out['last_time'] = max(out['last_time'], float(tele.time[-1]))
        feed = _feed_gyro if spec.detector == 'vsadc' else _feed_wheel
        fact = feed(spec, detector, nominal, kept, out, name)
        out['passes'].append({'pass': name, 'rows_dropped': dropped, **fact})
    if detector is not None:
        out['detector'] = codec.encode(detector)
        out['facts'] = _facts(spec, detector, out)
    if last and out['detector'] is not None:
        if detector is None:
            detector, _ = build(spec)
            codec.restore(detector, *out['detector'])
        if hasattr(detector, 'finish'):
            out['events'].extend(detector.finish())
    own = worker_facts(_time.process_time() - start)
    read_work = [work for _, work in reads if work is not None] if count_read else []
    out['work'] = _account(chain['work'], read_work + [own])
    return out


def _feed_wheel(spec: ComponentSpec, det: Any, nominal: Any, kept: Telemetry,
                out: dict[str, Any], name: str) -> dict[str, Any]:
    """Feed one wheel's samples of a pass (pipelines/llr.py, calibrated.py run_llr)."""
    wheels = kept.only('wheels')
    wheel = wheels.wheels.get(spec.component)
    if wheel is None or wheel.friction is None:
        return {'samples': 0, 'error': f'no {spec.component} speed and friction columns'}
    t, w, f = wheels.time, wheel.speed, wheel.friction
    residual = f
    if nominal is not None:
        residual, skipped = nominal.residual(t, w, f)
        for reason in NOT_TESTED:
            out['not_tested'][reason] += int(skipped[reason])
    out['events'].extend(det.process_arrays(t, w, residual))
    if len(t):
        out['trend'].append(_trend_row(spec, name, t, w, residual, nominal is not None))
    return {'samples': len(t)}


def _trend_row(spec: ComponentSpec, name: str, t: np.ndarray, w: np.ndarray,
               residual: np.ndarray, calibrated: bool) -> dict[str, Any]:
    """Return the pass's friction levels of the wheel (core/trend.py pass_levels).

    ``residual``: what the detector was fed, friction minus the nominal with a calibration
    (NaN where the detector does not test: the low-speed band and speeds outside the
    calibrated range, NominalWheel.residual), so the levels use the detector's samples
    only; pass_levels drops and counts the NaN (``nonfinite``).
    """
    from rwa_monitor.core.trend import pass_levels
    levels = pass_levels(t, w, residual)
    return {'spacecraft': spec.spacecraft, 'wheel': spec.component, 'pass': name,
            't_start': levels.t_start, 't_end': levels.t_end, 'samples': levels.samples,
            'dry': levels.dry, 'dry_se': levels.dry_se, 'viscous': levels.viscous,
            'viscous_se': levels.viscous_se,
            'relative_to': 'nominal' if calibrated else 'zero'}


def _feed_gyro(spec: ComponentSpec, det: Any, nominal: Any, kept: Telemetry,
               out: dict[str, Any], name: str) -> dict[str, Any]:
    """Feed a pass's gyro rows (pipelines/vsadc.py label_series), indices continued."""
    from rwa_monitor.pipelines import vsadc
    if not len(kept) or not vsadc.applies(kept):
        return {'samples': 0} if not len(kept) else {
            'samples': 0, 'error': 'no gyro_x/y/z and q_x/y/z/w columns'}
    tolerance = float(spec.params.get('pair_tolerance', VSADC['pair_tolerance'].default))
    fixed = out['last_ref'] if out['last_ref'] is not None else vsadc.reference_of(
        spec.params)
    rows, quats, refs = paired_gyro(kept, np.asarray(fixed, dtype=float), tolerance)
    time, gyro = kept.time.tolist(), kept.gyro.tolist()
    offset = out['offset']
    events = out['events']
    for index, (k, q, ref) in enumerate(zip(rows, quats, refs)):
        found = det.update(time[k], gyro[k], q, ref, offset + index)
        if found:
            events.extend(found)
    out['offset'] = offset + len(rows)
    if kept.reference_rate is not None:
        present = kept.rows('reference_rate')
        if len(present):
            out['last_ref'] = kept.reference_rate[present[-1]].tolist()
    return {'samples': len(rows)}


def _facts(spec: ComponentSpec, det: Any, chain: Mapping[str, Any]) -> dict[str, Any]:
    """Return the detector's facts after the pass (detect's per-component summary).

    With each wheel's and axis's verdict of detect (core/coverage.py ``judge`` through
    pipelines/llr.py ``judge_wheels`` and pipelines/vsadc.py ``axis_coverage``) on the
    samples so far.
    """
    if spec.detector == 'vsadc':
        from rwa_monitor.pipelines.vsadc import axis_coverage, rows_offered
        axes = {}
        for axis, ch in zip(det.axes, det.channels):
            verdict = axis_coverage(rows_offered(det.counters), ch)
            axes[f'gyro_{axis}'] = {'final_state': STATE_NAMES[ch.state] if ch.ready
                                    and verdict.examined else 'unknown', 'ready': ch.ready,
                                    'samples_used': ch.samples, **verdict.fields()}
        return {'axes': axes, 'counters': det.counters}
    from rwa_monitor.core.coverage import llr_samples_needed
    from rwa_monitor.pipelines.llr import judge_wheels
    counters = det.counters
    facts: dict[str, Any] = {'rows_seen': det.n_samples, 'rejected': counters}
    if spec.params.get('calibration_file'):
        # Samples not tested were fed as NaN: not counted as non-finite (calibrated.py).
        key = 'non_finite' if 'non_finite' in counters else 'nonfinite'
        counters[key] -= sum(chain['not_tested'].values())
        facts['not_tested'] = dict(chain['not_tested'])
    entry = {'samples': det.n_samples, 'rejected': counters,
             'not_tested': facts.get('not_tested', {})}
    judge_wheels({spec.component: entry}, llr_samples_needed(spec.params))
    facts.update({k: v for k, v in entry.items()
                  if k not in ('samples', 'rejected', 'not_tested')})
    return facts


def not_examined(spec: ComponentSpec, facts: Mapping[str, Any]) -> str | None:
    """Return why a component was not examined (detect's coverage rule), or None.

    A wheel or gyro axis whose verdict is ``not_examined`` or ``unknown`` (too few usable
    samples, or most rejected or not tested) is named with the verdict and its reason.
    """
    if not facts:
        return 'no pass could be processed'
    verdicts = facts['axes'] if spec.detector == 'vsadc' else {spec.component: facts}
    missing = [f'{name} {entry["verdict"]}: {entry["verdict_reason"]}'
               for name, entry in verdicts.items() if entry['verdict'] != EXAMINED]
    return f'{spec.detector}: {"; ".join(missing)}' if missing else None


def _account(work: Mapping[str, Any], tasks: list[Mapping[str, Any]]) -> dict[str, Any]:
    """Return the per-worker CPU seconds and peak memory with these tasks' added."""
    out = {k: dict(v) for k, v in work.items()}
    for facts in tasks:
        entry = out.setdefault(facts['worker'], {'cpu_s': 0.0, 'peak_rss_mb': 0.0,
                                                 'tasks': 0})
        entry['cpu_s'] += facts['cpu_s']
        entry['peak_rss_mb'] = max(entry['peak_rss_mb'], facts['peak_rss_mb'])
        entry['tasks'] += 1
    return out


def worker_facts(cpu_s: float) -> dict[str, Any]:
    """Return this process's worker address, the CPU seconds given and its peak RSS."""
    try:
        from distributed import get_worker
        worker = get_worker().address
    except (ImportError, ValueError):
        worker = 'client'
    peak_kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return {'worker': worker, 'cpu_s': cpu_s, 'peak_rss_mb': peak_kb / 1024.0}


def read(paths: list[str]) -> list[tuple[Any, dict[str, Any] | None]]:
    """Read consecutive passes on a worker: per pass (telemetry or reason, facts).

    One task per group of passes (a task costs about a millisecond of the engine's own);
    the worker facts (the group's CPU time) ride on the first pass, None on the others.
    """
    from rwa_monitor.fleet.archive import read_pass
    start = _time.process_time()
    teles = [read_pass(path) for path in paths]
    facts = worker_facts(_time.process_time() - start)
    return [(tele, facts if i == 0 else None) for i, tele in enumerate(teles)]
