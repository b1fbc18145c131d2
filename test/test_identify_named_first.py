"""identify names physics first: the catch-all only where no named set reaches the floor."""

import numpy as np
import pytest

from rwa_monitor.core.identify import effects as fx
from rwa_monitor.core.identify import report as rep
from rwa_monitor.core.identify.backfit import prune
from rwa_monitor.core.identify.baseline import Segments
from rwa_monitor.core.identify.effects import FALLBACK
from rwa_monitor.core.identify.fitting import Design, split_rows
from rwa_monitor.core.identify.joint import identify_joint
from rwa_monitor.core.identify.scoring import AddedEffect, score_candidate
from rwa_monitor.core.identify.select import identify
from rwa_monitor.pipelines.identify import prepare
from rwa_monitor.sim.undeclared import DRY_NM, NOISE_NM, SIZES, speed_profile, VISCOUS_NMS
from rwa_monitor.telemetry import Telemetry, Wheel

TRUTH = {'stribeck', 'drag', 'aux:<wheel>_temperature:viscous'}
FLOOR_RATIO = 1.05
# A correct model's held-out RMSE over the floor: n_held = 3,333 rows, so its sampling
# spread is about 1 / sqrt(2 n_held) = 0.012, plus the floor estimate's own error
# (robust local fits, about 1 %): 1.05 is about three combined standard deviations.


def windage_file(seed: int, n: int = 10000, wheel: str = 'rw1') -> Telemetry:
    """Drag (windage) + a temperature-dependent viscous term + a Stribeck term."""
    rng = np.random.default_rng(seed)
    time = np.arange(n) * 1.0
    speed = speed_profile(time)
    t = SIZES['temperature']
    temp = (t['mean_c'] + t['amplitude_c'] * np.sin(2 * np.pi * time / t['period_s'])
            + 0.05 * rng.standard_normal(n))
    s = SIZES['stribeck']
    stribeck = s['static_excess_nm'] * np.exp(-(speed / s['velocity_rad_s']) ** 2)
    clean = (-DRY_NM * np.sign(speed) - VISCOUS_NMS * speed
             - SIZES['drag']['coefficient_nms2'] * speed * np.abs(speed)
             - 0.03 * VISCOUS_NMS * (temp - t['mean_c']) * speed
             - stribeck * np.sign(speed))
    friction = clean + NOISE_NM * rng.standard_normal(n)
    return Telemetry(time=time, wheels={wheel: Wheel(speed=speed, friction=friction)},
                     aux={f'{wheel}_temperature': temp, f'{wheel}_bus_voltage': np.full(n, 28.0)})


def bump_file(seed: int, n: int = 10000, wheel: str = 'rw1') -> tuple[Telemetry, float]:
    """Model (1) + a friction bump around 60 rad/s that no named effect describes.

    Returns the record and the bump's RMS over the rows (N m).
    """
    rng = np.random.default_rng(seed)
    time = np.arange(n) * 1.0
    speed = speed_profile(time)
    bump = 3.0 * NOISE_NM * np.exp(-((np.abs(speed) - 60.0) / 15.0) ** 2)
    friction = (-DRY_NM * np.sign(speed) - VISCOUS_NMS * speed - bump * np.sign(speed)
                + NOISE_NM * rng.standard_normal(n))
    tele = Telemetry(time=time, wheels={wheel: Wheel(speed=speed, friction=friction)})
    return tele, float(np.sqrt(np.mean(bump ** 2)))


def named(sel) -> set[str]:
    """Return the effect names of a selection, the wheel's channel prefix replaced."""
    return {e.name.replace(f'aux:{sel.data.wheel}_', 'aux:<wheel>_') for e in sel.effects}


@pytest.mark.slow
def test_drag_and_temperature_are_named_with_their_parameters_profiled_again():
    # Development seed 2607. Before: presliding + temperature + a Stribeck term at
    # 71 rad/s standing in for the drag + smooth_speed. The Stribeck speed (4 rad/s in
    # the file) and the drag exponent (2) are profiled again once the other effects are in.
    sel = identify(prepare(windage_file(2607)))
    assert named(sel) == TRUTH
    assert sel.diagnostics_after['passes']
    assert sel.final_fit.rmse_test <= FLOOR_RATIO * sel.data.noise_floor
    effects = {e.kind: e for e in sel.effects}
    assert effects['stribeck'].params['velocity_rad_s'] == pytest.approx(4.0, rel=0.1)
    assert effects['drag'].params['exponent'] == 2.0
    # profiled at entry while drag or temperature was missing: 4.35 rad/s, exponent 2.5
    assert effects['drag'].evidence['params_at_entry']['exponent'] != 2.0


def _stribeck_data(seed: int, n: int = 6000):
    """Model (1) + the Stribeck term of the undeclared files, on their speed profile."""
    rng = np.random.default_rng(seed)
    time = np.arange(n) * 1.0
    speed = speed_profile(time)
    s = SIZES['stribeck']
    friction = (-DRY_NM * np.sign(speed) - VISCOUS_NMS * speed
                - s['static_excess_nm'] * np.sign(speed) * np.exp(
                    -(speed / s['velocity_rad_s']) ** 2)
                + NOISE_NM * rng.standard_normal(n))
    return prepare(Telemetry(time=time, wheels={'rw1': Wheel(speed=speed,
                                                             friction=friction)}))


def _design_with(data, effects):
    """Return a design of model (1) + the given (kind, params) effects, and AddedEffects."""
    design = Design(data.friction, Segments().columns(data.speed), split_rows(len(data)))
    added = []
    for kind, params in effects:
        start = design.X.shape[1]
        design.add(fx.evaluate(kind, params, data))
        # entered at a step of level 1e-5 with one weight and one searched parameter
        evidence = {'level': 1e-5, 'dof': 1, 'parameters': 2}
        added.append(AddedEffect(kind, kind, params, slice(start, design.X.shape[1]),
                                 evidence))
    return design, added


def test_an_effect_made_redundant_by_a_later_one_is_removed():
    # A pre-sliding band next to the file's own Stribeck term explains nothing more: its
    # held-out LR is chi^2(1) under "absent", so it fails the entry tests (keeping it
    # needs p < 1e-5 and a held-out LR above 6.6: chance below 1e-5).
    data = _stribeck_data(3330)
    design, added = _design_with(data, [('presliding', {'band_rad_s': 1.0,
                                                        'shape': 'linear'}),
                                        ('stribeck', {'velocity_rad_s': 4.0, 'shape': 2.0})])
    design, removed = prune(design, added, 1e-2)
    assert [r['name'] for r in removed] == ['presliding']
    assert [e.name for e in added] == ['stribeck'] and added[0].columns == slice(2, 3)
    assert design.X.shape[1] == 3


def test_a_named_effect_is_not_fitted_with_its_unphysical_sign():
    # A pre-sliding band can mimic a Stribeck curve only with a negative weight (friction
    # rising inside the band); that fit is not admissible, so on a Stribeck file the band
    # either fits with a positive weight or not at all.
    data = _stribeck_data(3331)
    design = Design(data.friction, Segments().columns(data.speed), split_rows(len(data)))
    scored = score_candidate(design, design.fit(), fx.presliding_candidate(data), data)
    assert scored is None or scored['fit'].coef[-1] > 0
    free = Design(data.friction, np.hstack([Segments().columns(data.speed),
                                            fx.evaluate('presliding', {'band_rad_s': 5.0,
                                                                       'shape': 'tanh'},
                                                        data)]), split_rows(len(data)))
    assert free.fit().coef[-1] < 0   # unconstrained, the band takes the Stribeck curve
    assert not fx.physical_weights('presliding', free.fit().coef[-1:])
    # after a full selection the band is absent and the Stribeck term named
    assert [e.name for e in identify(data).effects] == ['stribeck']


@pytest.mark.slow
@pytest.mark.parametrize('seed', [3300, 3301, 3302, 3303])
def test_no_spurious_effect_on_fresh_seeds(seed):
    # Seeds not used in development (docs/results.md "Issue 26: identify on fresh
    # seeds"): the three effects of the file, no hysteresis term, no catch-all.
    sel = identify(prepare(windage_file(seed)))
    assert named(sel) == TRUTH
    assert sel.final_fit.rmse_test <= FLOOR_RATIO * sel.data.noise_floor


@pytest.mark.slow
def test_the_catch_all_enters_only_when_no_named_set_reaches_the_floor():
    tele, bump_rms = bump_file(3320)
    sel = identify(prepare(tele))
    assert [e.name for e in sel.effects][-1] == FALLBACK
    assert sel.alternatives and not any(a['reaches_floor'] for a in sel.alternatives)
    out = rep.report(sel)
    (catch,) = [e for e in out['effects'] if e['name'] == FALLBACK]
    assert catch['parameters']['meaning'] == rep.UNEXPLAINED
    # What the catch-all adds beyond the named columns is part of the bump: positive,
    # and at most the bump plus what 22 weights can fit of the noise (sqrt(22 / n_train)
    # noise std, about 0.06 of it).
    size = catch['parameters']['size_rms_nm']
    assert 0.0 < size <= bump_rms + 0.06 * NOISE_NM
    assert 'Unexplained speed dependence' in rep.markdown(sel, out, 'test')
    # the same rule without jump segmentation
    plain = identify(prepare(tele), jumps=False)
    assert [e.name for e in plain.effects][-1] == FALLBACK


def _wheels(make, seeds) -> list:
    datas = []
    for k, seed in enumerate(seeds, start=1):
        tele = make(seed, wheel=f'rw{k}')
        datas.append(prepare(tele[0] if isinstance(tele, tuple) else tele, f'rw{k}'))
    return datas


@pytest.mark.slow
@pytest.mark.parametrize('seeds', [(2620, 2621, 2622, 2623), (3304, 3305, 3306, 3307)])
def test_identical_wheels_share_one_named_set_at_the_floor(seeds):
    # 2620-2623: before, the joint selection ended on presliding + temperature +
    # stribeck + stribeck_hysteresis + smooth_speed; 3304-3307: fresh seeds.
    joint = identify_joint(_wheels(windage_file, seeds))
    assert set(joint.effects) == TRUTH
    assert joint.consistency['consistent']
    for sel in joint.selections.values():
        assert named(sel) == TRUTH
        assert sel.final_fit.rmse_test <= FLOOR_RATIO * sel.data.noise_floor


@pytest.mark.slow
def test_identical_wheels_get_the_catch_all_only_when_no_named_set_reaches_the_floor():
    joint = identify_joint(_wheels(bump_file, (3321, 3322, 3323, 3324)))
    assert joint.effects[-1] == FALLBACK
    assert joint.alternatives and not any(a['reaches_floor'] for a in joint.alternatives)
    for sel in joint.selections.values():
        assert [e.name for e in sel.effects][-1] == FALLBACK
