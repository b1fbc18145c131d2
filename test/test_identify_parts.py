"""Identification parts: residual tests, effect columns, config snippet errors."""

from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

from rwa_monitor.core.identify.data import IdentData, prepare as prepare_samples
from rwa_monitor.core.identify.effects import regressor_columns
from rwa_monitor.core.identify.model import aux_channels, regressors_from_config
from rwa_monitor.core.identify.residuals import diagnose
from rwa_monitor.core.identify.select import identify
from rwa_monitor.exceptions import ConfigError, RwaMonitorError


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


@st.composite
def shuffled_records(draw):
    """Draw a record whose times come in any order, repeat, or are not finite."""
    n = draw(st.integers(60, 500))
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 16)))
    t = np.cumsum(rng.uniform(0.05, 0.15, n))
    order = draw(st.sampled_from(['shuffled', 'reversed', 'duplicates', 'step_back',
                                  'sorted']))
    if order == 'shuffled':
        t = rng.permutation(t)
    elif order == 'reversed':
        t = t[::-1].copy()
    elif order == 'duplicates':
        t = np.repeat(t[: (n + 1) // 2], 2)[:n]
    elif order == 'step_back':
        k = draw(st.integers(1, n - 1))
        t[k:] -= draw(st.floats(0.0, 2.0 * float(t[-1])))
    w = 20.0 * np.sin(2 * np.pi * np.arange(n) / draw(st.integers(5, 200)))
    f = -(2e-4 * np.sign(w) + 5e-7 * w) + 1e-5 * rng.standard_normal(n)
    for _ in range(draw(st.integers(0, 8))):
        column = draw(st.sampled_from([t, w, f]))
        column[draw(st.integers(0, n - 1))] = draw(st.sampled_from([np.nan, np.inf,
                                                                    -np.inf]))
    return t, w, f, draw(st.booleans())


@settings(max_examples=25, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(shuffled_records())
def test_any_time_order_is_dropped_counted_or_refused_in_one_line(record):
    t, w, f, derived = record
    try:
        with np.errstate(all='ignore'):
            data = prepare_samples(t, w, None if derived else f, inertia=1.0)
            identify(data, max_effects=1)
    except RwaMonitorError as err:
        assert str(err) and '\n' not in str(err)
        return
    assert np.all(np.diff(data.time) > 0)
    assert np.array_equal(data.time, t[data.rows])
    finite = np.isfinite(t) & np.isfinite(w) & (True if derived else np.isfinite(f))
    last, late = -np.inf, 0
    for stamp in t[finite]:      # the rule, one row at a time
        if stamp > last:
            last = stamp
        else:
            late += 1
    c = data.counts
    assert c['non_finite_rows'] == int(np.sum(~finite))
    assert c['time_not_increasing_rows'] == late
    dropped = c['non_finite_rows'] + c['time_not_increasing_rows'] + c.get(
        'dropped_short_run_rows', 0) + c.get('dropped_run_edge_rows', 0)
    assert len(data) == c['rows'] - dropped


def test_repeated_and_backward_stamps_are_dropped_and_counted():
    n = 400
    t = np.arange(n, dtype=float)
    t[100] = t[99]                  # a repeated stamp
    t[200:210] = t[200:210] - 50.0  # ten stamps stepping back into the past
    w = 30.0 * np.sin(2 * np.pi * np.arange(n) / 97.0)
    f = -(2e-4 * np.sign(w) + 5e-7 * w)
    data = prepare_samples(t, w, f)
    assert data.counts['time_not_increasing_rows'] == 11
    assert data.counts['non_finite_rows'] == 0
    assert len(data) == n - 11 and np.all(np.diff(data.time) > 0)
    assert 100 not in data.rows and not set(range(200, 210)) & set(data.rows)


def test_identify_schema_bounds_are_the_core_bounds(tmp_path):
    from rwa_monitor.cli.main import main
    from rwa_monitor.core.schema import IDENTIFY
    data, _ = _data(n=200)
    IDENTIFY.validate({'alpha': 0.5, 'half_width': 1000})
    for name, value in (('alpha', 0.51), ('alpha', 0.0), ('half_width', 0),
                        ('half_width', 1001), ('inertia', 0.0)):
        with pytest.raises(ConfigError):
            IDENTIFY.validate({name: value})
    with pytest.raises(ValueError, match='alpha'):
        identify(data, alpha=0.51)
    for h in (0, 1001):
        with pytest.raises(ValueError, match='half_width'):
            prepare_samples(data.time, data.speed, data.speed, half_width=h)
    with pytest.raises(SystemExit):
        main(['identify', 'x.csv', '--alpha', '0.6', '-o', str(tmp_path)])


def test_reversals_held_out_only_are_noted():
    from types import SimpleNamespace

    from rwa_monitor.core.identify.fitting import held_out_mask
    from rwa_monitor.core.identify.report import reversals
    n = 6000
    test = held_out_mask(n)
    speed = np.full(n, 5.0)
    held = np.flatnonzero(test)
    speed[held[150]:held[150] + 10] = -5.0         # two sign changes, both held out
    found = reversals(SimpleNamespace(data=SimpleNamespace(speed=speed)))
    assert found['total'] == 2 and found['held_out'] == 2 and found['training'] == 0
    assert 'held-out rows' in found['note']
    train = np.flatnonzero(~test)
    speed[train[150]:train[150] + 10] = -5.0       # two more, in training rows
    found = reversals(SimpleNamespace(data=SimpleNamespace(speed=speed)))
    assert found == {'total': 4, 'held_out': 2, 'training': 2, 'note': None}
