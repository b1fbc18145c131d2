"""The LLR friction detector on a file: one detector per wheel that has a friction column.

Parameters are the ``llr_detector`` node's (config/rwa_monitor.yaml), same names:
``window``, ``k_verif`` (0 = window / 2), ``false_alarm_rate`` and ``noise_std`` (N m;
0 = estimate from the data). ``friction_model_file`` names a refined friction model
written by ``rwa-monitor identify`` (its ``friction_model.yaml``); empty = model (1). The
refined model applies to the wheel it names when the file has that wheel, else to every
wheel. ``calibration_file`` names a commissioning calibration (``rwa-monitor calibrate``):
the detector then tests the residual against each wheel's nominal model
(pipelines/calibrated.py; it takes precedence over ``friction_model_file``). Other keys
of the block (node-only ones) are ignored.
"""

from __future__ import annotations

import time as _time
from typing import Any, Mapping

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.params import check_int, check_real
from rwa_monitor.exceptions import ConfigError
from rwa_monitor.telemetry import Telemetry

NODE = 'llr_detector'
DEFAULTS = {'window': 500, 'k_verif': 0, 'false_alarm_rate': 1.0e-5, 'noise_std': 0.0}
MODEL_KEY = 'friction_model_file'
CALIBRATION_KEY = 'calibration_file'


def applies(tele: Telemetry) -> bool:
    """Return True if some wheel of the record has a friction column."""
    return any(w.friction is not None for w in tele.wheels.values())


def detector_kwargs(config: Mapping[str, Any]) -> dict[str, Any]:
    """Return the detector keywords for a parameter block (ValueError names a bad one)."""
    params = {**DEFAULTS, **{k: v for k, v in config.items() if k in DEFAULTS}}
    window = check_int('window', params['window'], 2)
    k_verif = check_int('k_verif', params['k_verif'], 0)
    noise_std = check_real('noise_std', params['noise_std'], 0.0)
    return {'window': window, 'k_verif': k_verif or None,
            'false_alarm_rate': check_real('false_alarm_rate', params['false_alarm_rate'],
                                           0.0, 1.0, low_open=True, high_open=True),
            'noise_std': noise_std or None}


def friction_model(path: str, tele: Telemetry) -> tuple[str | None, Any] | None:
    """Return (wheel or None, RegressorSet) of a refined model file, or None if unset.

    Raise ConfigError if the file cannot be read or the record lacks a channel it reads.
    """
    if not path:
        return None
    import yaml

    from rwa_monitor.core.identify.model import aux_channels, regressors_from_config
    try:
        with open(path) as handle:
            cfg = yaml.safe_load(handle)
    except (OSError, yaml.YAMLError) as err:
        raise ConfigError(f'{MODEL_KEY} {path!r}: cannot read: {err}') from None
    if not isinstance(cfg, Mapping):
        raise ConfigError(f'{MODEL_KEY} {path!r}: expected a friction_model mapping')
    missing = [c for c in aux_channels(cfg) if c not in tele.aux]
    if missing:
        raise ConfigError(f'{MODEL_KEY} {path!r} reads channel(s) the file lacks: '
                          f'{", ".join(missing)}')
    wheel = cfg.get('friction_model', cfg).get('wheel')
    return (wheel if wheel in tele.wheels else None), regressors_from_config(cfg)


def run_with_summary(tele: Telemetry, config: Mapping[str, Any]
                     ) -> tuple[list[AnomalyEvent], dict[str, Any]]:
    """Run one detector per wheel (batch path); return (events, per-wheel summary).

    The summary per wheel holds the number of events, samples, the detector's counters
    of rejected samples and its run time.
    """
    from rwa_monitor.core.llr_batch import detect_batch_with_counters
    kwargs = detector_kwargs(config)
    if config.get(CALIBRATION_KEY):
        from rwa_monitor.pipelines import calibrated
        return calibrated.run_llr(tele, kwargs, str(config[CALIBRATION_KEY]))
    refined = friction_model(config.get(MODEL_KEY) or '', tele)
    events: list[AnomalyEvent] = []
    summary: dict[str, Any] = {}
    for wheel_id, wheel in tele.wheels.items():
        if wheel.friction is None:
            continue
        start = _time.perf_counter()
        model = {}
        if refined and refined[0] in (None, wheel_id):
            model = {'regressors': refined[1], 'aux': tele.aux}
        found, counters = detect_batch_with_counters(
            tele.time, wheel.speed, wheel.friction, component=wheel_id, **kwargs, **model)
        summary[wheel_id] = {'events': len(found), 'samples': len(tele),
                             'rejected': dict(counters),
                             'runtime_s': _time.perf_counter() - start}
        events.extend(found)
    return events, summary


def run(tele: Telemetry, config: Mapping[str, Any]) -> list[AnomalyEvent]:
    """Return the events of one LLR detector per wheel with a friction column."""
    return run_with_summary(tele, config)[0]
