"""Identification parts: residual tests, effect columns, config snippet errors."""

import numpy as np
import pytest

from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.effects import regressor_columns
from rwa_monitor.core.identify.model import aux_channels, regressors_from_config
from rwa_monitor.core.identify.residuals import diagnose
from rwa_monitor.exceptions import ConfigError


def _data(n=6000, seed=0):
    rng = np.random.default_rng(seed)
    t = np.arange(n, dtype=float)
    w = 100 * np.sin(2 * np.pi * t / 900)
    aux = {'rw1_temperature': 20 + 5 * np.sin(2 * np.pi * t / 3000),
           'rw1_bus_voltage': np.full(n, 28.0)}
    return IdentData('rw1', t, w, np.zeros(n), np.ones(n), aux), rng


def test_white_residual_passes_every_test():
    # Bonferroni over the stop tests at alpha = 1e-3: P(a white residual fails) <= 1e-3.
    data, rng = _data()
    diag = diagnose(data, rng.standard_normal(len(data)))
    assert diag['passes'], diag['failing']
    assert 'aux:rw1_bus_voltage' not in diag['binned']     # constant channel: not binned


@pytest.mark.parametrize('make, failing', [
    (lambda d: 0.3 * (d.speed / 100) ** 2, 'speed'),
    (lambda d: 0.3 * (d.aux['rw1_temperature'] - 20) / 5, 'aux:rw1_temperature'),
    (lambda d: 0.3 * np.sign(d.speed), 'direction'),
    (lambda d: 0.3 * np.sin(2 * np.pi * d.time / 97.0), 'spectrum'),
])
def test_structure_of_three_tenths_of_the_noise_is_caught(make, failing):
    # Size 0.3 sigma over 6000 samples: the binned chi^2 exceeds its dof by ~ n 0.3^2 / 2
    # = 270, far above the 1e-3 / 8 critical value (~ 55 on 20 dof).
    data, rng = _data(seed=1)
    diag = diagnose(data, rng.standard_normal(len(data)) + make(data))
    assert failing in diag['failing']


def test_whiteness_uses_every_stride_th_residual_when_friction_was_differentiated():
    data, rng = _data(seed=2)
    e = rng.standard_normal(len(data) + 10)
    correlated = np.convolve(e, np.ones(11) / 11, mode='valid')   # MA(10)
    assert 'whiteness' in diagnose(data, correlated)['failing']
    data.stride = 11
    assert diagnose(data, correlated)['tests']['whiteness']['p_value'] > 1e-3 / 8


def test_effect_columns_follow_the_paper_sign():
    w = np.array([-50.0, -1.0, 0.0, 1.0, 50.0])
    drag = regressor_columns('drag', {'exponent': 2.0})[0][1](w, None, None)
    assert np.allclose(drag, -w * np.abs(w))
    stribeck = regressor_columns('stribeck', {'velocity_rad_s': 1.0})[0][1](w, None, None)
    assert stribeck[3] == pytest.approx(-np.exp(-1.0)) and stribeck[2] == 0.0
    hats = regressor_columns('smooth_speed', {'knots_rad_s': [-50.0, 0.0, 50.0]})
    values = np.column_stack([c(w, None, None) for _, c in hats])
    assert np.allclose(values.sum(axis=1), [1, 1, 0, 1, 1])  # partition of unity, w != 0


def test_snippet_errors_name_the_problem():
    with pytest.raises(ConfigError, match='kind must be one of'):
        regressors_from_config({'friction_model': {'effects': [{'kind': 'magic'}]}})
    with pytest.raises(ConfigError, match='lacks parameter'):
        regressors_from_config({'effects': [{'kind': 'drag', 'params': {}}]})
    cfg = {'effects': [{'name': 'aux:rw1_temperature:dry', 'kind': 'aux',
                        'params': {'column': 'rw1_temperature', 'component': 'dry',
                                   'center': 20.0}}]}
    assert aux_channels(cfg) == ['rw1_temperature']
    regs = regressors_from_config(cfg)
    with pytest.raises(KeyError, match='rw1_temperature'):
        regs.matrix(np.ones(3), np.zeros(3), {})
    assert regressors_from_config({}).names == ('dry', 'viscous')
