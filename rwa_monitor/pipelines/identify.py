"""Identification of a telemetry record: the record's channels to the core's arrays.

The core (core/identify/) takes arrays: time, speed, friction, this wheel's auxiliary
channels and every other signal. Here a Telemetry record is split into those for one
wheel (:func:`prepare`), and :func:`identify_wheel` runs the identification with the
output error when friction is derived from speed; :func:`identify_wheels` identifies
sibling wheels declared identical together (core/identify/joint.py). Used by
``rwa-monitor identify`` and the identify benchmark; pipelines/identify_report.py
writes the outputs.
"""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from rwa_monitor.core.identify import data as samples
from rwa_monitor.core.identify.consistency import compare_effects
from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.joint import identify_joint
from rwa_monitor.core.identify.output_error import speed_rmse
from rwa_monitor.core.identify.select import identify, Selection
from rwa_monitor.exceptions import NotIdentifiableError, TooFewSamplesError
from rwa_monitor.telemetry.schema import Telemetry

# BLAS threads during an identification. Its products are thin (n x a few columns): a
# threaded BLAS gains nothing on them, and on a loaded machine its threads wait for
# each other (measured, bench identify: 100k samples 20 s wall with the default threads
# against 8 s with one, for 4 s of CPU time either way).
BLAS_THREADS = 1


def choose_wheel(tele: Telemetry, wheel: str | None) -> str:
    """Return the wheel id to identify: the one asked for, or the file's only/first."""
    if not tele.wheels:
        raise NotIdentifiableError('the file has no <id>_speed column: nothing to identify')
    if wheel is None:
        return next(iter(tele.wheels))
    if wheel not in tele.wheels:
        raise NotIdentifiableError(f'no wheel {wheel!r} in the file; it has: '
                                   f'{", ".join(tele.wheels)}')
    return wheel


def wheel_channels(tele: Telemetry, wheel: str
                   ) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Return (aux, signals) of one wheel: its candidate channels, and everything else.

    ``aux``: the record's auxiliary channels except other wheels' (``<other id>_...``);
    ``signals``: other wheels' speeds, frictions and channels (diagnostics only).
    """
    others = tuple(f'{w}_' for w in tele.wheels if w != wheel)
    aux, signals = {}, {}
    for other, ch in tele.wheels.items():
        if other == wheel:
            continue
        for kind in ('speed', 'friction'):
            values = getattr(ch, kind, None)
            if values is not None:
                signals[f'{other}_{kind}'] = values
    for name, values in tele.aux.items():
        if others and name.startswith(others):
            signals[name] = values
        else:
            aux[name] = values
    return aux, signals


def prepare(tele: Telemetry, wheel: str | None = None, inertia: float | None = None,
            torque_constant: float | None = None, half_width: int | str = 'auto'
            ) -> IdentData:
    """Return the samples of one wheel of a record (core.identify.data.prepare)."""
    wheel = choose_wheel(tele, wheel)
    aux, signals = wheel_channels(tele, wheel)
    channels = tele.wheels[wheel]
    if channels.friction is not None:
        _enough_samples(wheel, tele.time, channels.speed, channels.friction)
    return samples.prepare(tele.time, channels.speed, channels.friction, wheel=wheel,
                           aux=aux, signals=signals, inertia=inertia,
                           torque_constant=torque_constant, half_width=half_width)


def _enough_samples(wheel: str, *columns: np.ndarray) -> None:
    """Raise TooFewSamplesError (exit 3) unless the wheel has MIN_SAMPLES finite rows.

    Checked before the core sees the columns, so that a file with no finite friction
    sample (only a header, or a dead sensor) is "not examined", never taken for a record
    without a friction column.
    """
    finite = np.logical_and.reduce([np.isfinite(np.asarray(c, dtype=float))
                                    for c in columns])
    usable = int(np.count_nonzero(finite))
    if usable < samples.MIN_SAMPLES:
        raise TooFewSamplesError(f'{wheel}: too few usable samples: {usable} of '
                                 f'{finite.size}; the identification needs at least '
                                 f'{samples.MIN_SAMPLES}')


def examinable(tele: Telemetry, wheels: list[str]) -> tuple[list[str], dict[str, str]]:
    """Return (the wheels with enough usable samples, wheel -> why not for the others)."""
    keep, skipped = [], {}
    for wheel in wheels:
        channels = tele.wheels[wheel]
        try:
            if channels.friction is not None:
                _enough_samples(wheel, tele.time, channels.speed, channels.friction)
        except TooFewSamplesError as err:
            skipped[wheel] = str(err)
        else:
            keep.append(wheel)
    return keep, skipped


def identify_wheel(tele: Telemetry, wheel: str | None, inertia: float | None = None,
                   torque_constant: float | None = None, half_width: int | str = 'auto',
                   alpha: float = 1e-3, jumps: bool = True) -> tuple[Selection, dict]:
    """Prepare one wheel, identify it, and add the output error when friction is derived.

    Returns the selection and the ``extra`` of identify_report.write_outputs: with
    friction derived from speed and a known inertia, report.json gains ``speed_rmse``
    (before / after, rad/s) and selection.json its per-segment details and the
    differentiator's choice of width.
    """
    with threadpool_limits(BLAS_THREADS):
        data = prepare(tele, wheel, inertia, torque_constant, half_width)
        selection = identify(data, alpha=alpha, jumps=jumps)
    return selection, _extra(tele, selection, inertia, torque_constant)


def identify_wheels(tele: Telemetry, wheels: list[str], identical: bool = True,
                    inertia: float | None = None, torque_constant: float | None = None,
                    half_width: int | str = 'auto', alpha: float = 1e-3, jumps: bool = True
                    ) -> tuple[dict[str, tuple[Selection, dict]], dict]:
    """Identify several wheels of one record; return per wheel (selection, extra), consistency.

    ``identical``: the wheels are of one design, so the effects are selected on their
    pooled evidence (core/identify/joint.py) and a wheel is flagged when its own data
    contradict its siblings (core/identify/consistency.py); otherwise each wheel is
    identified alone (as with one ``--wheel``) and the sets are compared with the
    majority's.
    """
    if not identical or len(wheels) < 2:
        out = {}
        for wheel in wheels:
            selection, extra = identify_wheel(tele, wheel, inertia, torque_constant,
                                              half_width, alpha, jumps)
            out[selection.data.wheel] = (selection, extra)
        names = {w: [e.name for e in s.effects] for w, (s, _) in out.items()}
        return out, compare_effects(names)
    with threadpool_limits(BLAS_THREADS):
        datas = [prepare(tele, w, inertia, torque_constant, half_width) for w in wheels]
        joint = identify_joint(datas, alpha=alpha, jumps=jumps)
    out = {w: (s, _extra(tele, s, inertia, torque_constant))
           for w, s in joint.selections.items()}
    return out, joint.consistency


def _extra(tele: Telemetry, selection: Selection, inertia: float | None,
           torque_constant: float | None) -> dict:
    """Return the ``extra`` outputs of one wheel (differentiator, output error)."""
    data = selection.data
    extra: dict = {'details': {'differentiator': data.differentiator or
                               {'half_width': data.half_width, 'chosen_from': 'given'}}}
    if data.derived and inertia is not None:
        current = tele.aux.get(f'{data.wheel}_current')
        torque = None if current is None else torque_constant * np.asarray(
            current, dtype=float)[data.rows]
        with threadpool_limits(BLAS_THREADS):
            sr = speed_rmse(selection, inertia, torque)
        extra['report'] = {'speed_rmse': {'before': sr['before'], 'after': sr['after']}}
        extra['details']['speed_rmse'] = sr
    return extra
