"""VSADC state machine (vsadc-gyro-drift paper, Algorithm 1) on crafted feature sequences."""

import numpy as np
import pytest

from rwa_monitor.core.vsadc import BIAS, DRIFT, HEALTHY, VsadcAxis

# Small windows so that every index below can be derived by hand: window means over 10
# samples, sigmas over 10 distances, 20 reference sigmas, distance threshold 1. With noise
# 0.05 the window means have std 0.016 and the healthy sigmas stay near 0.01-0.02; limits
# at 3 times their max (about 0.06) are far from both the noise and the crafted changes.
SMALL = dict(window=10, sigma_window=10, reference_window=20, distance_threshold=1.0,
             margin=3.0, exit_limit='max', exit_margin=3.0)
NOISE = 0.05


def _features(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, NOISE, size=(n, 2))


def _run(axis, feats):
    out = []
    for k, (x1, x2) in enumerate(feats):
        tr = axis.update(x1, x2, (float(k), k))
        if tr is not None:
            out.append((tr.declared[1], tr.previous, tr.state, tr.onset[1]))
    return out


def test_start_up_is_healthy_until_the_reference_is_learnt():
    # Learning starts at sample 2*10 + 10 = 30 and needs 20 sigmas: ready after sample 49.
    ax = VsadcAxis(**SMALL)
    feats = _features(60)
    for k in range(48):
        assert ax.update(*feats[k]) is None and ax.state == HEALTHY
    assert not ax.ready
    ax.update(*feats[48])
    assert ax.ready and ax.samples == 49


def test_bias_step_then_recovery_by_hand():
    # Step of 4 on the gyro residual at index 100: the window mean gains 0.4 a sample, so d
    # passes 1 at the third step sample (102; 0.8 at 101). Its sigma (distances 0, 0.4,
    # 0.8, 1.2 in the window) is far above the healthy sigmas (~0.02): drift, onset at 100,
    # the first sample above the quiet level. d is flat from 109 on, so the sigma window
    # holds only flat values from 118: bias at 118. Step removed at 200: d falls 0.4 a
    # sample, the first falling distance (200) lifts sigma above the bias's own limit:
    # drift; d < 0.75 (recovery_fraction x threshold) once 9 samples are back (208; 0.8 at
    # 207): healthy.
    feats = _features(260)
    feats[100:200, 1] += 4.0
    got = _run(VsadcAxis(**SMALL), feats)
    assert got == [(102, HEALTHY, DRIFT, 100), (118, DRIFT, BIAS, 108),
                   (200, BIAS, DRIFT, 190), (208, DRIFT, HEALTHY, 208)]


def test_hold_delays_every_change_by_hold_minus_one_samples():
    feats = _features(160)
    feats[100:, 1] += 4.0
    got = _run(VsadcAxis(**SMALL, hold=3), feats)
    assert [g[:3] for g in got] == [(104, HEALTHY, DRIFT), (120, DRIFT, BIAS)]


def test_a_ramp_stays_drift_until_it_stops():
    # Ramp of 0.05 a sample from 100 to 299: the window mean trails the ramp, its sigma
    # over 10 distances is 0.05 * sqrt(99/12) = 0.14, far above the healthy limits, for as
    # long as the ramp lasts; the distances are flat 10 + 10 samples after it stops.
    feats = _features(400, seed=1)
    feats[100:300, 1] += 0.05 * np.arange(1, 201)
    feats[300:, 1] += 10.0
    got = _run(VsadcAxis(**SMALL), feats)
    assert [g[1:3] for g in got] == [(HEALTHY, DRIFT), (DRIFT, BIAS)]
    declared_drift, declared_bias = got[0][0], got[1][0]
    # Sample 99 + j carries 0.05 j; the window mean at 99 + j (j >= 10) is 0.05 (j - 4.5),
    # above 1 first at j = 25: index 124. The ramp ends at 299 (value 10, as after it):
    # d is flat from 309, the sigma window from 318.
    assert declared_drift == 124
    assert 309 <= declared_bias <= 318


def test_a_bias_with_the_same_noise_does_not_flicker():
    feats = _features(3000, seed=2)
    feats[100:, 1] += 4.0
    got = _run(VsadcAxis(**SMALL), feats)
    assert [g[2] for g in got] == [DRIFT, BIAS]


def test_reset_gives_the_same_answer_again():
    feats = _features(260)
    feats[100:200, 1] += 4.0
    ax = VsadcAxis(**SMALL)
    first = _run(ax, feats)
    ax.reset()
    assert ax.samples == 0 and ax.state == HEALTHY
    assert _run(ax, feats) == first


def test_nominal_tracking_follows_a_wander_but_not_a_drift():
    # A wander of 5e-4 a sample reaches the threshold 1 after 2000 samples: a fixed nominal
    # alarms. A tracked nominal (running mean over 200 samples) lags the wander by
    # 5e-4 * 200 = 0.1, below freeze_fraction * threshold = 0.5: no alarm. A drift of 0.05
    # a sample lags by 10: d passes 0.5 in about 10 samples and freezes the nominal, so it
    # is detected all the same.
    feats = _features(4000, seed=3)
    feats[:, 1] += 5e-4 * np.arange(4000)
    assert _run(VsadcAxis(**SMALL), feats)
    assert _run(VsadcAxis(**SMALL, nominal_tracking=200), feats) == []
    drift = feats.copy()
    drift[3000:, 1] += 0.05 * np.arange(1000)
    got = _run(VsadcAxis(**SMALL, nominal_tracking=200), drift)
    assert got and got[0][2] == DRIFT and 3000 <= got[0][0] <= 3030


def test_paper_literal_settings_are_accepted():
    ax = VsadcAxis(window=10, sigma_window=10, reference_window=10, margin=1.0,
                   exit_limit='mean', exit_margin=1.0, adaptive=False, distance_threshold=1.0)
    feats = _features(200)
    feats[100:, 1] += 4.0
    got = _run(ax, feats)
    assert got and got[0][:3] == (102, HEALTHY, DRIFT)


@pytest.mark.parametrize('name,value', [
    ('window', 1), ('sigma_window', 1), ('distance_threshold', 0.0), ('margin', 0.0),
    ('exit_limit', 'median'), ('exit_margin', -1.0), ('hold', 0), ('nominal_tracking', -1),
    ('freeze_fraction', 1.5), ('reference_window', 0), ('adaptive', 'yes'),
    ('recovery_fraction', 0.0)])
def test_bad_parameters_name_themselves(name, value):
    with pytest.raises(ValueError, match=name):
        VsadcAxis(**{name: value})
