"""The window diagnoser against a calibrated wheel: its nominal reference and its inputs.

:func:`fss_reference` is the diagnoser's part of a wheel's calibration block (``fss``),
fitted at commissioning (core/calibrate.py); :func:`fss_inputs` turns a window's friction
into what the diagnoser compares with that reference, and :func:`diagnose_fss` runs the
diagnosis and the calibrated verdict (docs/fss.md, "Calibrated").
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from rwa_monitor.core.nominal import nominal_prediction


def fss_reference(speed: np.ndarray, friction: np.ndarray, friction_model: Mapping[str, Any],
                  noise: Mapping[str, Any], window_samples: int | None = None
                  ) -> dict[str, Any]:
    """Return the window diagnoser's nominal reference of one wheel.

    The diagnoser knows model (1) and the FSSs (the FSS paper's eq. (4)); what the wheel's
    nominal holds beyond model (1) is removed from its friction first. That part is not
    the nominal model's own extra columns as identification fitted them: identification
    knows no FSS, and on a wheel with FSS jumps it takes them for effects of speed (on
    the paper's Examples 1-2: drag and smooth_speed, a reference base dry 1.6 x the true
    one). So the extra columns are refitted together with the FSS jumps, in the
    diagnoser's own stage 2 (eq. 14: one dry coefficient per interval between the
    changepoints of stages 1-3, one viscous coefficient) plus the columns
    (core/fss/segments.py ``fit_extra_columns``), twice: the changepoints are found
    again once the first fit's extra part is removed. ``extra_weights``: that part as
    weights of the nominal model's columns (``nominal_prediction`` with them is what
    :func:`fss_inputs` removes). ``base_dry_nm``, ``viscous_nms``, ``noise_std_nm``:
    what the diagnoser's extraction (core/fss/pipeline.py, stages 1-3) reports on the
    calibration data given as :func:`fss_inputs` gives a window, so that a nominal window
    is judged against the same estimator's nominal values. ``model1_*``: the plain
    least-squares fit of model (1) outside the low-speed band (for reading only).

    A record of two or more diagnosed windows (``window_samples``, default the node's
    ``window_length``) gets the median of the base dry of each window-long piece
    (``base_dry_windows`` pieces, their std ``base_dry_window_std_nm``) and the mean of
    their viscous coefficients (standard error from theirs): the reference is that of a
    window, as the diagnosed ones are. Algorithm 1's base is a one-window estimate, and
    on a longer record its running sums of jumps drift down with every jump given to the
    wrong FSS (docs/fss.md, "Calibrated": a three-window record read 0.54 x the true
    base dry). When the refitted
    columns leave no positive base dry (they took the dry friction itself), they are
    dropped and ``extra_refit_dropped`` is set: the reference is model (1) alone.
    """
    from rwa_monitor.core.fss.pipeline import extract, FssConfig, normalise
    from rwa_monitor.core.fss.segments import fit_extra_columns
    from rwa_monitor.core.identify.model import regressors_from_config
    from rwa_monitor.core.schema import FSS
    speed = np.asarray(speed, dtype=float)
    friction = np.asarray(friction, dtype=float)
    band = float(noise['low_speed_band']['speed_abs_below_rad_s'])
    with np.errstate(invalid='ignore'):
        out = np.isfinite(speed) & np.isfinite(friction) & (np.abs(speed) >= band)
    h = -np.column_stack([np.sign(speed[out]), speed[out]])
    dry, viscous = np.linalg.lstsq(h, friction[out], rcond=None)[0]
    ref = {'model1_dry_nm': float(dry), 'model1_viscous_nms': float(viscous),
           'speed_abs_below_rad_s': band}
    block = friction_model.get('friction_model', friction_model)
    regs = regressors_from_config(block)
    names = list(regs.names)
    extra = [i for i, n in enumerate(names) if n not in ('dry', 'viscous')]
    config = FssConfig()
    weights = dict.fromkeys(names, 0.0)
    safe = np.where(out, speed, 0.0)
    columns = regs.matrix(safe)[:, extra] if extra else np.zeros((speed.size, 0))
    given = np.where(out, friction, np.nan)
    for _ in range(2 if extra else 0):
        ext = extract(*normalise(speed, given, config), config)
        c, d = fit_extra_columns(friction, np.where(out, speed, np.nan), ext.accepted,
                                 columns, dk_error=config.dk_error)
        # columns @ c + d[0] sign(w) + d[1] w; model (1)'s columns are -sign(w), -w.
        weights = dict.fromkeys(names, 0.0)
        weights.update({names[i]: float(v) for i, v in zip(extra, c)})
        weights['dry'], weights['viscous'] = float(-d[0]), float(-d[1])
        given = np.where(out, friction - nominal_prediction(
            {'effects': block.get('effects') or [], 'weights': weights}, safe), np.nan)
    ext = extract(*normalise(speed, given, config), config)
    if extra and not ext.base_dry > 0.0:
        # The refitted columns took the dry friction itself (nearly collinear with the
        # interval levels when few intervals hold both signs of the speed): a reference
        # with no positive base dry is never right, so the nominal is model (1) alone.
        weights = dict.fromkeys(names, 0.0)
        given = np.where(out, friction, np.nan)
        ext = extract(*normalise(speed, given, config), config)
        ref['extra_refit_dropped'] = True
    tq = config.torque_scale_nm
    base, viscous, viscous_se = ext.base_dry, ext.viscous, ext.viscous_se
    length = int(window_samples or FSS['window_length'].default)
    pieces = speed.size // length
    if pieces >= 2:
        parts = [extract(*normalise(speed[k * length:(k + 1) * length],
                                    given[k * length:(k + 1) * length], config), config)
                 for k in range(pieces)]
        bases = [p.base_dry for p in parts]
        base = float(np.median(bases))
        viscous = float(np.mean([p.viscous for p in parts]))
        viscous_se = float(np.sqrt(np.sum([p.viscous_se ** 2 for p in parts]))) / pieces
        ref.update(base_dry_windows=pieces,
                   base_dry_window_std_nm=float(np.std(bases, ddof=1) * tq))
    ref.update(base_dry_nm=float(base * tq),
               viscous_nms=float(viscous * tq / config.speed_scale_rad_s),
               viscous_se_nms=float(viscous_se * tq / config.speed_scale_rad_s)
               if np.isfinite(viscous_se) else float('nan'),
               noise_std_nm=float(ext.sigma * tq), extra_weights=weights,
               samples=int(np.count_nonzero(out)))
    return ref


def fss_extra(block: Mapping[str, Any], speed: np.ndarray) -> np.ndarray:
    """Return what the wheel's nominal holds beyond model (1), as the FSS reference fitted.

    ``fss.extra_weights`` on the nominal model's columns (:func:`fss_reference`); a
    calibration written before they existed gives the nominal model minus the
    reference's model-(1) fit.
    """
    ref = block['fss']
    model = block['friction_model']
    if 'extra_weights' in ref:
        return nominal_prediction({'effects': model.get('effects') or [],
                                   'weights': ref['extra_weights']}, speed)
    model1 = -ref['model1_dry_nm'] * np.sign(speed) - ref['model1_viscous_nms'] * speed
    return nominal_prediction(model, speed) - model1


def fss_inputs(block: Mapping[str, Any], speed: np.ndarray, friction: np.ndarray
               ) -> tuple[np.ndarray, dict[str, float]]:
    """Return (friction for the diagnoser, its scales) relative to the wheel's nominal.

    The friction loses what the nominal holds beyond model (1) (:func:`fss_extra`),
    samples inside the low-speed band or outside the calibrated speed range become NaN
    (the stages skip them), and the normalising scales are the reference's base dry
    friction and base dry / viscous, so that the nominal wheel is (1, 1) in the
    diagnoser's units, where its classifier was trained (docs/fss.md, "Calibrated").
    """
    speed = np.asarray(speed, dtype=float)
    friction = np.asarray(friction, dtype=float)
    ref = block['fss']
    safe = np.where(np.isfinite(speed), speed, 0.0)
    out = friction - fss_extra(block, safe)
    lo, hi = block['speed_range_rad_s']
    with np.errstate(invalid='ignore'):
        skip = (np.abs(speed) < ref['speed_abs_below_rad_s']) | (speed < lo) | (speed > hi)
    out[skip | ~np.isfinite(speed)] = np.nan
    scales = {}
    if ref['base_dry_nm'] > 0:
        scales['torque_scale_nm'] = float(ref['base_dry_nm'])
        if ref['viscous_nms'] > 0:
            scales['speed_scale_rad_s'] = float(ref['base_dry_nm'] / ref['viscous_nms'])
    return out, scales


def diagnose_fss(block: Mapping[str, Any], time: np.ndarray, speed: np.ndarray,
                 friction: np.ndarray, classifier: Any, config: Any) -> dict[str, Any]:
    """Return the window diagnosis of one wheel relative to its calibrated nominal.

    Samples beyond the plausibility limits are dropped first (core/fss/pipeline.py
    ``plausible``, counted in ``rejected``), then
    :func:`fss_inputs` (nominal's non-model-(1) part removed, band and out-of-range
    samples skipped, scales from the reference), the four stages (core/fss/pipeline.py
    ``diagnose``), then core/fss/classify.py ``relative_verdict`` (``status``: nominal,
    anomalous or unknown, with ``unknown_reason``) with the classifier's noise-ratio
    bound (``noise_ratio_bound`` of its spec's ``noise_ratio``). A viscous flag stands only
    when the window's viscous coefficient is also significantly above the reference's
    (``viscous_z`` > the one-sided quantile at VISCOUS_LEVEL, both standard errors of
    least squares): the classifier's threshold is a size (x1.14 on the shipped model),
    learned where the estimate is ten times more precise than on a 3-hour bus record;
    ``calibration.viscous_z`` keeps the value. A window mostly not tested (band, range)
    is ``unknown`` from ``diagnose`` already (its coverage) and keeps that answer.
    """
    from dataclasses import replace

    from rwa_monitor.core.fss.classify import (noise_ratio_bound, relative_verdict,
                                               viscous_significant, viscous_z)
    from rwa_monitor.core.fss.pipeline import diagnose, plausible
    speed, friction, rejected = plausible(speed, friction, config)
    given, scales = fss_inputs(block, speed, friction)
    result = diagnose(speed, given, time, classifier, replace(config, **scales))
    result['rejected'] = rejected       # the reasons of the samples as given
    skipped = int(np.sum(~np.isfinite(given) & np.isfinite(friction)))
    if result.get('status') == 'unknown':   # mostly not tested: no relative verdict
        result['calibration'] = {**scales, 'samples_not_tested': skipped}
        return result
    spec = getattr(classifier, 'spec', None) or {}
    bound = noise_ratio_bound(spec.get('noise_ratio'))
    est, ref = result['estimates'], block['fss']
    se = est.get('viscous_se_nms')
    z = viscous_z(est['viscous_nms'], float('inf') if se is None else se,
                  ref['viscous_nms'], ref.get('viscous_se_nms', float('nan')))
    if result['anomalies'].get('viscous') and not viscous_significant(z):
        result['anomalies']['viscous'] = False
        result['viscous_not_significant'] = True
    status, flags, reason = relative_verdict(result['anomalies'], est['noise_std_nm'],
                                             ref['noise_std_nm'], bound)
    result['anomalies'] = flags
    result['status'] = status
    if reason:
        result['unknown_reason'] = reason
    result['calibration'] = {**scales, 'samples_not_tested': skipped,
                             'viscous_z': z if np.isfinite(z) else None}
    return result
