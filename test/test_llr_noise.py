"""Noise beyond white in the LLR detector: AR prewhitening and the sliding reference.

Bounds come from the maths (docs/llr.md "Noise beyond white"): seeds are fixed, never
tuned to printed values.
"""

import ast
import pathlib

import numpy as np
import pytest
from scipy import stats

from rwa_monitor.core.llr import detect_batch, LLRDetector
from rwa_monitor.core.llr_noise import fit_noise_model, whiten


def ar1(n: int, rho: float, rng: np.random.Generator) -> np.ndarray:
    """Return a stationary AR(1) series of unit variance."""
    e = rng.standard_normal(n) * np.sqrt(1.0 - rho * rho)
    out = np.empty(n)
    prev = rng.standard_normal()
    for i in range(n):
        prev = rho * prev + e[i]
        out[i] = prev
    return out


def crossing_signal(n: int, noise: np.ndarray, changes=()):
    k = np.arange(n, dtype=float)
    w = 15.0 * np.sin(2.0 * np.pi * k / 3000.0) + 2.0
    fc = np.full(n, 1.0)
    fv = np.full(n, 0.05)
    for at, d_dry, d_visc in changes:
        fc[at:] += d_dry
        fv[at:] += d_visc
    return k * 0.1, w, -fc * np.sign(w) - fv * w + noise


def test_white_noise_fits_order_zero_almost_always():
    """BIC keeps order 0 unless chi2_q exceeds q log m: P(q > 0) ~ 0.011 for m = 798."""
    rng = np.random.default_rng(31)
    runs, chosen = 100, 0
    for _ in range(runs):
        _, w, f = crossing_signal(801, rng.standard_normal(801))
        h = np.column_stack([-np.sign(w), -w])
        chosen += bool(fit_noise_model(h, f, 3).ar)
    # Binomial(100, 0.011 x 2 margin for the estimated x): P(X >= 8) < 1e-3.
    assert chosen < 8


def test_ar1_coefficient_is_recovered_within_its_standard_error():
    rng = np.random.default_rng(32)
    for rho in (0.3, 0.5, 0.8):
        _, w, f = crossing_signal(4000, ar1(4000, rho, rng))
        model = fit_noise_model(np.column_stack([-np.sign(w), -w]), f, 3)
        # sd of the AR(1) estimate sqrt((1 - rho^2) / n) <= 0.016; 5 sd.
        assert abs(model.ar[0] - rho) < 0.08
        assert abs(model.long_run_ratio - (1 + rho) / (1 - rho)) < 0.5 * (1 + rho) / (1 - rho)


def test_false_alarms_under_ar_noise_respect_the_union_bound():
    """AR(1) rho = 0.5: per-run alarm probability <= tests x r = 0.1 once prewhitened.

    Without prewhitening the statistic is ~3 times too large (long-run variance ratio
    (1 + rho) / (1 - rho)) and nearly every run alarms.
    """
    rng = np.random.default_rng(33)
    runs, n, w, r = 100, 1200, 100, 1e-4
    tests = n - 2 * w
    white = whitened = 0
    for _ in range(runs):
        t, sp, f = crossing_signal(n, ar1(n, 0.5, rng))
        whitened += bool(detect_batch(t, sp, f, window=w, false_alarm_rate=r))
        white += bool(detect_batch(t, sp, f, window=w, false_alarm_rate=r,
                                   noise_ar_max_order=0))
    limit = stats.binom.isf(1e-3, runs, tests * r)
    assert whitened <= limit
    assert white > limit


def test_whiten_matches_the_streaming_filter_and_inverts_ar():
    rng = np.random.default_rng(34)
    x = ar1(500, 0.6, rng)
    u = whiten(x, (0.6,))
    assert u[0] == x[0]
    np.testing.assert_allclose(u[1:], x[1:] - 0.6 * x[:-1])


def test_buffered_arrays_are_the_samples_the_streaming_path_buffers():
    # The batch path buffers the samples waiting for the fit as arrays, the streaming
    # path one by one: the same record (row, t, f, speed, (-sign w, -w)), a mix of both
    # too, and the fit of either gives the same model and events.
    rng = np.random.default_rng(36)
    n = 4000
    t, w, f = crossing_signal(n, ar1(n, 0.5, rng), ((2500, 0.8, 0.0),))
    w[:3] = (0.0, -2.0, 3.0)
    det = LLRDetector('rw1', window=200)
    batch = det.process_arrays(t, w, f) + det.finish()
    streamed = LLRDetector('rw1', window=200)   # the fit takes 2 w + 1 = 401 samples
    for a, b, c in zip(t[:400].tolist(), w[:400].tolist(), f[:400].tolist()):
        streamed.update(a, b, c)
    arrays = LLRDetector('rw1', window=200)
    arrays.process_arrays(t[:150], w[:150], f[:150])
    arrays.update(float(t[150]), float(w[150]), float(f[150]))
    arrays.process_arrays(t[151:400], w[151:400], f[151:400])
    expected = streamed.state().fit
    assert expected.rows.tolist() == list(range(400))
    assert expected.regressors[:2].tolist() == [[0.0, -0.0], [1.0, 2.0]]
    for other in (arrays.state().fit,):
        for name in ('rows', 'time', 'friction', 'speed', 'regressors'):
            assert np.array_equal(getattr(other, name), getattr(expected, name)), name
    for one in (streamed, arrays):
        one.update(float(t[400]), float(w[400]), float(f[400]))
    assert det.noise_model == streamed.noise_model == arrays.noise_model == fit_noise_model(
        np.column_stack([-np.sign(w[:401]), -w[:401]]), f[:401], 3)
    for one in (streamed, arrays):
        events = []
        for a, b, c in zip(t[401:].tolist(), w[401:].tolist(), f[401:].tolist()):
            events.extend(one.update(a, b, c))
        events.extend(one.finish())
        assert len(batch) >= 1
        assert [e.to_json() for e in batch] == [e.to_json() for e in events]


def test_streaming_equals_batch_with_ar_noise_and_sliding_reference():
    rng = np.random.default_rng(35)
    n = 9000
    for rho, ref in ((0.5, None), (0.5, 1500), (0.0, 1200), (0.8, 900)):
        noise = ar1(n, rho, rng) if rho else rng.standard_normal(n)
        t, w, f = crossing_signal(n, noise, ((4000, 0.8, 0.0), (7000, 0.0, 0.05)))
        f[100] = np.nan
        kw = dict(window=300, reference_max=ref)
        batch = detect_batch(t, w, f, **kw)
        det = LLRDetector('rw1', **kw)
        streamed = []
        for a, b, c in zip(t.tolist(), w.tolist(), f.tolist()):
            streamed.extend(det.update(a, b, c))
        streamed.extend(det.finish())
        assert [e.to_json() for e in batch] == [e.to_json() for e in streamed]
        assert any(abs(e.index - 4000) < 300 for e in batch)


def test_sliding_reference_follows_a_slow_drift_and_keeps_steps():
    """Dry friction drifting by +-0.4 noise std over 60,000 samples (an orbit at 10 Hz).

    A growing reference compares the window with the mean of the whole past and alarms;
    a sliding reference of 2000 samples sees a bias of ~0.05 std and does not, while a
    step of 1 std is still found.
    """
    n = 60_000
    rng = np.random.default_rng(36)
    k = np.arange(n, dtype=float)
    t, w, f = crossing_signal(n, rng.standard_normal(n))
    drift = 0.4 * np.sin(2.0 * np.pi * k / n)
    f = f - drift * np.sign(w)
    kw = dict(window=400, false_alarm_rate=1e-5)
    assert detect_batch(t, w, f, **kw)
    assert not detect_batch(t, w, f, reference_max=2000, **kw)
    f2 = f - 1.0 * np.sign(w) * (k >= 30_000)
    found = detect_batch(t, w, f2, reference_max=2000, **kw)
    assert any(abs(e.index - 30_000) < 400 for e in found)


def test_no_import_cycle_between_streaming_and_batch():
    core = pathlib.Path(__file__).resolve().parents[1] / 'rwa_monitor' / 'core'
    tree = ast.parse((core / 'llr_batch.py').read_text())
    names = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            names.add(node.module)
            names.update(f'{node.module}.{a.name}' for a in node.names)
    assert 'rwa_monitor.core.llr' not in names
    assert 'rwa_monitor.core.llr' not in {n.rsplit('.', 1)[0] for n in names
                                          if n.startswith('rwa_monitor.core.llr.')}


# -- noise growing with speed (docs/llr.md "Noise growing with speed") --------------------
def speed_noise_signal(n: int, seed: int, hold: int = 0, changes=()):
    """Profile 0-300 rad/s with zero crossings; noise std 1 x (0.5 + |w| / 100).

    ``hold``: samples at a constant 200 rad/s first (the fit must wait for the speed to
    vary).
    """
    rng = np.random.default_rng(seed)
    k = np.arange(n, dtype=float)
    w = 150.0 * np.sin(2.0 * np.pi * k / 4000.0) + 120.0
    w[:hold] = 200.0
    fc = np.full(n, 1.0)
    fv = np.full(n, 0.01)
    for at, d_dry, d_visc in changes:
        fc[at:] += d_dry
        fv[at:] += d_visc
    noise = (0.5 + np.abs(w) / 100.0) * rng.standard_normal(n)
    return k * 0.1, w, -fc * np.sign(w) - fv * w + noise


def test_speed_noise_level_is_recovered():
    """|e| on (1, |w|): E|e| = sqrt(2/pi) (0.5 + |w| / 100), so b / a = 0.02.

    With 4000 samples over 0-270 rad/s the relative standard error of b / a is a few
    per cent; 25 % is > 5 standard errors. White noise: the slope's t value exceeds
    3.29 with probability 5e-4 (one-sided), so no model on the fixed seed.
    """
    from rwa_monitor.core.llr_noise import fit_speed_std
    _, w, f = speed_noise_signal(4000, 21)
    h = np.column_stack([-np.sign(w), -w])
    a, b, floor = fit_speed_std(h, f, np.abs(w))
    assert b / a == pytest.approx(0.02, rel=0.25)
    assert floor == pytest.approx(a + b * np.abs(w).min())
    rng = np.random.default_rng(22)
    white = -np.sign(w) - 0.01 * w + rng.standard_normal(w.size)
    assert fit_speed_std(h, white, np.abs(w)) is None


def test_streaming_equals_batch_with_the_speed_noise_model():
    # The hold makes the first fit wait for the speed to vary (speed_fit_ready), then
    # retry (speed_fit_done) until the slope is significant: same schedule on both paths.
    t, w, f = speed_noise_signal(16_000, 23, hold=3000, changes=((11_000, 1.0, 0.0),))
    params = dict(window=300, noise_speed_model=True, false_alarm_rate=1e-5)
    det = LLRDetector('rw1', **params)
    streamed = [e for a, b, c in zip(t, w, f) for e in det.update(a, b, c)] + det.finish()
    assert streamed == detect_batch(t, w, f, **params)
    assert det.noise_model.speed_std is not None
    assert any(abs(e.index - 11_000) <= 300 for e in streamed)


def test_speed_noise_model_keeps_the_false_alarm_promise():
    """Holds at 30 and 250 rad/s (noise std 0.8 and 3.0) alternating every 5000 samples.

    Without the model the reference's pooled noise level is too small for a window at
    250 rad/s after a long slow hold (alarms on every seed here). With it, union bound:
    P(any alarm) <= n r = 4e4 x 1e-6 = 0.04 per run, so more than 1 alarm over 3 runs has
    probability < 1e-2.
    """
    with_model = without = 0
    for seed in (31, 32, 33):
        t, w, f = speed_noise_signal(40_000, seed)
        w = np.where((np.arange(w.size) // 5000) % 2 == 0, 30.0, 250.0)
        rng = np.random.default_rng(seed)
        f = -np.sign(w) - 0.01 * w + (0.5 + w / 100.0) * rng.standard_normal(w.size)
        with_model += sum(e.revision == 0 for e in detect_batch(
            t, w, f, window=300, false_alarm_rate=1e-6, noise_speed_model=True))
        without += sum(e.revision == 0 for e in detect_batch(
            t, w, f, window=300, false_alarm_rate=1e-6))
    assert with_model <= 1
    assert without >= 3


def test_speed_noise_model_needs_an_estimated_noise_level():
    with pytest.raises(ValueError, match='noise_speed_model'):
        LLRDetector('rw1', noise_std=1.0, noise_speed_model=True)
    with pytest.raises(ValueError, match='noise_speed_model'):
        LLRDetector('rw1', noise_speed_model='yes')


def test_inline_whitened_path_equals_the_generic_two_column_path():
    # The paper's model with an AR noise model is whitened inline in update(); the same
    # columns as another RegressorSet take _ingest_fitted / _whiten / _add2: same events.
    from rwa_monitor.core.friction import dry_column, RegressorSet, viscous_column
    reg = RegressorSet(('dry', 'viscous'), (lambda w, t, a: dry_column(w),
                                            lambda w, t, a: viscous_column(w)))
    rng = np.random.default_rng(36)
    n = 9000
    t, w, f = crossing_signal(n, ar1(n, 0.7, rng), ((3000, 0.8, 0.0), (6500, 0.0, 0.05)))
    f[[100, 2000, 5000]] = np.nan
    t[4000] = t[3999]
    runs = []
    for extra in ({}, {'regressors': reg}):
        det = LLRDetector('rw1', window=300, **extra)
        events = []
        for a, b, c in zip(t.tolist(), w.tolist(), f.tolist()):
            events.extend(det.update(a, b, c))
        assert det.noise_model is not None and len(det.noise_model.ar) >= 1
        runs.append(([e.to_json() for e in events], det.counters))
    assert runs[0] == runs[1] and len(runs[0][0]) >= 2


def _joined_records(seed: int, join: str):
    """Two records of AR(1) noise (rho 0.7), the second slower, its dry level 0.3 higher.

    ``join``: 'gap' (60 s between them), or 'rejected' (time runs on, 100 samples of
    non-finite friction between them: speeds a calibration did not test).
    """
    rng = np.random.default_rng(seed)
    n = 3000
    k = np.arange(n) * 0.1
    w = np.concatenate([30.0 + 10.0 * np.sin(k / 20.0), 6.0 + 2.0 * np.sin(k / 20.0)])
    noise = 0.02 * ar1(2 * n, 0.7, rng)
    f = -(1.0 + 0.3 * (np.arange(2 * n) >= n)) * np.sign(w) - 0.05 * w + noise
    if join == 'gap':
        return np.concatenate([k, k[-1] + 60.0 + k]), w, f, n
    gap = np.full(100, np.nan)
    t = np.arange(2 * n + 100) * 0.1
    return (t, np.concatenate([w[:n], gap + 20.0, w[n:]]),
            np.concatenate([f[:n], gap, f[n:]]), n + 100)


@pytest.mark.parametrize('join', ['gap', 'rejected'])
def test_a_dry_step_across_a_break_is_named_dry(join):
    # The AR filter's memory is cleared where the sequence breaks (docs/llr.md "Noise beyond
    # white", *Breaks*). Before that rule the lags of the first samples after the join came
    # from before it: the whitened friction carried the step times sum(a) and the whitened
    # speed column the jump of the speed, and every one of these 20 seeds ended `both` or
    # `undecided` with z_viscous near -7. Filtered as at a start, the step is a dry step in
    # the whitened model: its viscous z is standard normal, |z| <= 1.96 with probability
    # 0.95, so at least 16 of 20 (binomial: P(fewer) < 0.003) end `dry` with it.
    right = 0
    for seed in range(20):
        t, w, f, after = _joined_records(seed, join)
        events = detect_batch(t, w, f, window=500)
        first = [e for e in events if e.index >= after]
        assert first and first[0].index == after
        last = max((e for e in events if e.index == after), key=lambda e: e.revision)
        right += last.kind == 'dry' and abs(last.details['z_viscous']) <= 1.96
    assert right >= 16


def test_the_filter_breaks_only_where_the_sequence_does():
    from rwa_monitor.core import llr_kernel as kern
    from rwa_monitor.core import llr_layout as layout
    # A wheel sampled once a revolution: the time step grows smoothly as it slows down.
    step = 0.05 * 1.002 ** np.arange(400)
    t = np.cumsum(step)
    det = LLRDetector('rw1', window=50, noise_ar_max_order=2, noise_fit_samples=120)
    for ti, wi in zip(t, np.linspace(60.0, 20.0, t.size)):
        det.update(float(ti), float(wi), -0.2 - 0.01 * wi)
    live = det._live
    j, row = int(live.ints[layout.I_POS]), int(live.ints[layout.I_ROWS])
    last = float(t[-1])
    assert not kern.sequence_breaks(live.floats, live.ints, j, row, last + step[-1] * 1.01)
    assert not kern.sequence_breaks(live.floats, live.ints, j, row, last + step[-1] * 3.9)
    assert kern.sequence_breaks(live.floats, live.ints, j, row, last + step[-1] * 4.1)
    assert kern.sequence_breaks(live.floats, live.ints, j, row + 1, last + step[-1])


def _reference_order(e: np.ndarray, top: int) -> tuple[int, np.ndarray, float]:
    """BIC order by least squares on the lagged columns (numpy's lstsq, roots by np.roots)."""
    n = e.size
    m = n - top
    target = e[top:]
    best = (np.inf, 0, np.zeros(0), 0.0)
    for q in range(top + 1):
        if q:
            lagged = np.column_stack([e[top - i:n - i] for i in range(1, q + 1)])
            coef = np.linalg.lstsq(lagged, target, rcond=None)[0]
            rss = float(np.sum((target - lagged @ coef) ** 2))
        else:
            coef, rss = np.zeros(0), float(target @ target)
        bic = m * np.log(rss / m) + q * np.log(m)
        stationary = q == 0 or np.all(np.abs(np.roots(np.r_[1.0, -coef])) < 0.999)
        if bic < best[0] and stationary:
            best = (bic, q, coef, rss / m)
    return best[1:]


@pytest.mark.parametrize('seed', range(5))
def test_compiled_order_selection_equals_least_squares_on_the_lags(seed):
    from rwa_monitor.core.llr_noise import lag_gram, select_ar_order
    rng = np.random.default_rng(4100 + seed)
    n, top = 3000, 3
    e = ar1(n, (-0.6, 0.0, 0.3, 0.8, 0.95)[seed], rng)
    ar, s2u = select_ar_order(lag_gram(e, top), n)
    order, coef, s2 = _reference_order(e, top)
    assert ar.size == order
    assert np.allclose(ar, coef, rtol=1e-9, atol=1e-12)
    assert s2u == pytest.approx(s2, rel=1e-9)


def test_order_selection_skips_singular_and_explosive_orders():
    from rwa_monitor.core.llr_noise import lag_gram, select_ar_order
    # An explosive AR(1) (root 1.005) fits best but is not stationary: order 0 stays.
    u = np.random.default_rng(4110).standard_normal(2000)
    series = np.empty(u.size)
    series[0] = u[0]
    for i in range(1, u.size):
        series[i] = 1.005 * series[i - 1] + u[i]
    ar, _ = select_ar_order(lag_gram(series, 1), series.size)
    assert ar.size == 0
    # Lags that are all zero: every order above 0 is singular.
    gram = np.zeros((4, 4))
    gram[0, 0] = 5.0
    ar, s2u = select_ar_order(gram, 100)
    assert ar.size == 0 and s2u == pytest.approx(5.0 / 97)
