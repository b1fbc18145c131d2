"""Residual diagnostics: tests for anything the friction model does not explain.

Each test gives a statistic, its degrees of freedom and a p-value under "the residual is
zero-mean noise, independent of everything":

- ``speed`` / ``time`` / ``aux:<column>``: the residual binned by quantiles of the
  variable; each bin mean divided by its standard error is N(0, 1), so the sum of their
  squares is chi^2 with one degree of freedom per bin (conservative: fitting the model
  removes a few of them).
- ``direction``: mean residual with w > 0 against w < 0 (Welch t, squared, chi^2(1)).
- ``approach``: the direction of the speed's change (history.py): in each abs(w) bin,
  the mean residual while abs(w) rises minus the mean while it falls, over its standard
  error; the sum of squares is chi^2 (one per bin with both). A friction that depends
  on the direction of approach (hysteresis, lag) shows here and nowhere else.
- ``since_zero``: the residual binned by the time since the last zero passage (a memory
  of the last reversal: breakaway, warm-up of the lubricant film).
- ``acceleration``: binned by dw/dt (an inertia between the torque measurement and the
  contact, a load that depends on the acceleration); not when friction was derived from
  dw/dt (the residual then carries dw/dt's own noise).
- ``position``: binned by the integral of the speed (gravity load, gear ripple), when
  the joint moves back and forth within a turn (candidates_motion.reciprocating).
- ``since_reversal``: binned by the distance travelled since the direction last changed
  (pre-sliding builds up over a displacement, not a time).
- ``sign_history``: the mean residual of each (direction before the last reversal,
  direction now) group over its standard error, squares summed, chi^2 with one degree
  of freedom per group (a friction that remembers the path: stops that continue differ
  from stops that reverse).
- ``signal:<column>``: the residual binned by every other signal of the file (other
  wheels' channels); reported, not used to stop (through the attitude loop they
  correlate with this wheel's own history).
- ``whiteness``: Ljung-Box Q on the first L autocorrelations, chi^2(L).
- ``spectrum``: Fisher's g test for the largest periodogram ordinate (upper bound
  p <= m (1 - g)^(m - 1)).
- ``variance_vs_speed``: Levene's test (median-centred) across speed bins; reported, not
  used to stop the selection (a change of variance does not change the mean model).

The tests are decisions of the selection (when to stop, whether a named set reaches the
floor), so they use the rows a decision may look at: never the held-out test rows
(fitting.held_out_mask), whose residual is only reported.
When friction was differentiated from speed the noise is correlated over ``stride``
samples, so every test uses every stride-th residual (binned means of correlated
residuals would have a standard error unlike sd / sqrt(count)).
The residual passes when every mean-structure, whiteness and spectrum test has
p > alpha / (number of those tests).
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.effects import uniform_resample
from rwa_monitor.core.identify.fitting import held_out_mask

STOP_TESTS_EXCLUDED = ('variance_vs_speed',)
# Fewest independent residuals (every stride-th, test rows left out) for "the residual
# passes" to stop the selection: with fewer, two bins of a dozen samples each cannot see
# the curvature an unmodelled drag leaves (a coast of 566 revolutions differentiated over
# 41 samples keeps 9 independent residuals), and the selection goes on with its entry
# tests alone.
MIN_TESTED = 60
REPORT_ONLY_PREFIX = 'signal:'
MIN_PASSAGES = 2


def _bins(values: np.ndarray, count: int) -> np.ndarray:
    edges = np.unique(np.quantile(values, np.linspace(0.0, 1.0, count + 1)))
    if len(edges) < 2:
        return np.zeros(len(values), dtype=int)
    return np.clip(np.searchsorted(edges, values, side='right') - 1, 0, len(edges) - 2)


def binned(x: np.ndarray, residual: np.ndarray, count: int = 20) -> dict:
    """Return the residual binned by ``x``: centres, means, 95 % half-widths, test."""
    labels = _bins(x, count)
    n_bins = int(labels.max()) + 1
    size = np.bincount(labels, minlength=n_bins).astype(float)
    mean = np.bincount(labels, residual, n_bins) / np.maximum(size, 1)
    second = np.bincount(labels, residual ** 2, n_bins) / np.maximum(size, 1)
    sd = np.sqrt(np.maximum(second - mean ** 2, 0.0) * size / np.maximum(size - 1, 1))
    centre = np.bincount(labels, x, n_bins) / np.maximum(size, 1)
    ok = size >= 2
    se = sd[ok] / np.sqrt(size[ok])
    z = mean[ok] / np.where(se > 0, se, np.inf)
    chi2 = float(np.sum(z ** 2))
    dof = int(np.sum(ok))
    return {'centre': centre[ok], 'mean': mean[ok], 'band': 1.96 * se, 'count': size[ok],
            'statistic': chi2, 'dof': dof,
            'p_value': float(stats.chi2.sf(chi2, dof)) if dof else 1.0}


def approach_test(speed: np.ndarray, receding: np.ndarray, approaching: np.ndarray,
                  residual: np.ndarray, count: int = 20) -> dict:
    """Return the rising-minus-falling residual per abs(w) bin and its chi^2 test."""
    aw = np.abs(speed)
    labels = _bins(aw, count)
    centre, diff, band, z = [], [], [], []
    for k in np.unique(labels):
        a = residual[(labels == k) & receding]
        b = residual[(labels == k) & approaching]
        if len(a) < 3 or len(b) < 3:
            continue
        se = np.sqrt(np.var(a, ddof=1) / len(a) + np.var(b, ddof=1) / len(b))
        d = float(np.mean(a) - np.mean(b))
        centre.append(float(np.mean(aw[labels == k])))
        diff.append(d)
        band.append(1.96 * se)
        z.append(d / se if se > 0 else 0.0)
    chi2 = float(np.sum(np.square(z)))
    dof = len(z)
    return {'centre': np.array(centre), 'mean': np.array(diff), 'band': np.array(band),
            'statistic': chi2, 'dof': dof,
            'p_value': float(stats.chi2.sf(chi2, dof)) if dof else 1.0}


def _motion_tests(data: IdentData, residual: np.ndarray, by, out: dict, k: int,
                  bins: int) -> None:
    """Add the acceleration, position, since-reversal and sign-history diagnostics."""
    past = data.past
    if not data.derived and np.ptp(past.rate) > 0:
        out['binned']['acceleration'] = by(past.rate)
    span = float(np.ptp(past.position))
    travel = float(np.sum(np.abs(np.diff(past.position))))
    if 0 < span < 2 * np.pi and travel >= 4.0 * span:
        out['binned']['position'] = by(past.position)
    finite = np.isfinite(past.distance_since_reversal)
    if np.sum(finite[::k]) >= 2 * bins:
        out['binned']['since_reversal'] = by(past.distance_since_reversal, finite)
    groups = []
    sign = np.sign(data.speed)
    for before in (-1.0, 1.0):
        for now in (-1.0, 1.0):
            r = residual[::k][((past.previous_direction == before) & (sign == now))[::k]]
            if len(r) >= 10:
                groups.append(float(np.mean(r) / (np.std(r, ddof=1) / np.sqrt(len(r)))))
    if len(groups) >= 2:
        chi2 = float(np.sum(np.square(groups)))
        out['tests']['sign_history'] = {'statistic': chi2, 'dof': len(groups),
                                        'p_value': float(stats.chi2.sf(chi2, len(groups)))}


def autocorrelation(residual: np.ndarray, max_lag: int) -> np.ndarray:
    """Return the sample autocorrelation at lags 1..max_lag."""
    r = residual - np.mean(residual)
    n = len(r)
    spec = np.fft.rfft(r, 2 * n)
    acov = np.fft.irfft(spec * np.conj(spec))[:max_lag + 1]
    return acov[1:] / acov[0] if acov[0] > 0 else np.zeros(max_lag)


def ljung_box(residual: np.ndarray, max_lag: int) -> dict:
    """Return the Ljung-Box test on the first ``max_lag`` autocorrelations."""
    n = len(residual)
    rho = autocorrelation(residual, max_lag)
    q = float(n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, max_lag + 1))))
    return {'statistic': q, 'dof': max_lag, 'p_value': float(stats.chi2.sf(q, max_lag)),
            'acf': rho}


def fisher_g(time: np.ndarray, residual: np.ndarray) -> dict:
    """Return Fisher's g test for a periodic component, and the periodogram."""
    values, step = uniform_resample(time, residual - np.mean(residual))
    power = np.abs(np.fft.rfft(values)) ** 2
    freqs = np.fft.rfftfreq(len(values), step)
    inner = power[1:-1] if len(power) > 2 else power
    m = len(inner)
    total = float(np.sum(inner))
    g = float(np.max(inner) / total) if total > 0 else 0.0
    p = float(min(1.0, m * (1.0 - g) ** (m - 1))) if m > 1 else 1.0
    return {'statistic': g, 'dof': m, 'p_value': p, 'frequency_hz': freqs,
            'power': power}


def diagnose(data: IdentData, residual: np.ndarray, alpha: float = 1e-3,
             bins: int = 20) -> dict:
    """Return every residual diagnostic, the tests, and whether the residual passes.

    Computed on the rows a decision may use (all but the held-out test rows).
    """
    rows = ~held_out_mask(len(data))
    residual = np.asarray(residual, dtype=float)
    # The spectrum test keeps the time axis: the test rows are set to zero, not cut out
    # (cutting every third block out makes the sampling periodic, a peak at the block
    # rate; white noise times a fixed gate keeps a flat expected periodogram).
    gated = (data.time[::data.stride], np.where(rows, residual, 0.0)[::data.stride])
    return _diagnose(_restricted(data, rows), residual[rows], alpha, bins, gated)


def _restricted(data: IdentData, rows: np.ndarray) -> IdentData:
    """Return the samples of ``data`` on ``rows`` (history features carried over)."""
    past = data.past
    if past is not None:
        past = type(past)(**{f: getattr(past, f)[rows] for f in past.__dataclass_fields__})
    return IdentData(wheel=data.wheel, time=data.time[rows], speed=data.speed[rows],
                     friction=data.friction[rows], noise_std=data.noise_std[rows],
                     aux={c: v[rows] for c, v in data.aux.items()}, derived=data.derived,
                     stride=data.stride,
                     signals={c: v[rows] for c, v in data.signals.items()}, past=past,
                     half_width=data.half_width)


def _diagnose(data: IdentData, residual: np.ndarray, alpha: float, bins: int,
              gated: tuple[np.ndarray, np.ndarray]) -> dict:
    k = max(1, data.stride)
    n = len(residual[::k])
    bins = int(max(2, min(bins, n // 30)))
    out: dict = {'binned': {}, 'tests': {}}

    def by(values: np.ndarray, mask: np.ndarray | None = None) -> dict:
        if mask is None:
            return binned(values[::k], residual[::k], bins)
        return binned(values[::k][mask[::k]], residual[::k][mask[::k]], bins)
    out['binned']['speed'] = by(data.speed)
    out['binned']['time'] = by(data.time)
    for column, values in data.aux.items():
        if np.std(values) > 1e-9 * (1.0 + abs(np.mean(values))):
            out['binned'][f'aux:{column}'] = by(values)
    past = data.past
    if past is not None:
        out['approach'] = approach_test(data.speed[::k], past.receding[::k],
                                        past.approaching[::k], residual[::k], bins)
        if out['approach']['dof']:
            out['tests']['approach'] = {k: out['approach'][k]
                                        for k in ('statistic', 'dof', 'p_value')}
        finite = np.isfinite(past.since_zero_s)
        if past.passages >= MIN_PASSAGES and np.sum(finite[::k]) >= 2 * bins:
            out['binned']['since_zero'] = by(past.since_zero_s, finite)
        _motion_tests(data, residual, by, out, k, bins)
    for column, values in data.signals.items():
        if np.std(values) > 1e-9 * (1.0 + abs(np.mean(values))):
            out['binned'][REPORT_ONLY_PREFIX + column] = by(values)
    for name, b in out['binned'].items():
        out['tests'][name] = {k: b[k] for k in ('statistic', 'dof', 'p_value')}
    pos, neg = residual[data.speed > 0], residual[data.speed < 0]
    if len(pos) > 2 and len(neg) > 2:
        t = stats.ttest_ind(pos, neg, equal_var=False)
        out['tests']['direction'] = {'statistic': float(t.statistic ** 2), 'dof': 1,
                                     'p_value': float(t.pvalue),
                                     'mean_positive': float(np.mean(pos)),
                                     'mean_negative': float(np.mean(neg))}
    thinned = residual[::data.stride]
    lags = int(max(1, min(20, len(thinned) // 5)))
    lb = ljung_box(thinned, lags)
    out['acf'] = lb.pop('acf')
    out['acf_stride'] = data.stride
    out['tests']['whiteness'] = lb
    spec = fisher_g(*gated)
    out['spectrum'] = {'frequency_hz': spec.pop('frequency_hz'), 'power': spec.pop('power')}
    out['tests']['spectrum'] = spec
    labels = _bins(data.speed, bins)
    groups = [residual[labels == k] for k in np.unique(labels)]
    groups = [g for g in groups if len(g) >= 3]
    variance = {'centre': np.array([np.mean(data.speed[labels == k])
                                    for k in np.unique(labels)]),
                'std': np.array([np.std(residual[labels == k]) for k in np.unique(labels)])}
    out['binned_std'] = variance
    if len(groups) >= 2 and all(np.ptp(g) > 0 for g in groups):
        lev = stats.levene(*groups, center='median')
        out['tests']['variance_vs_speed'] = {'statistic': float(lev.statistic),
                                             'dof': len(groups) - 1,
                                             'p_value': float(lev.pvalue)}
    stop = [k for k in out['tests'] if k not in STOP_TESTS_EXCLUDED
            and not k.startswith(REPORT_ONLY_PREFIX)]
    level = alpha / max(len(stop), 1)
    out['level'] = level
    out['failing'] = [k for k in stop if out['tests'][k]['p_value'] <= level]
    out['tested_samples'] = n
    out['passes'] = not out['failing'] and n >= MIN_TESTED
    out['rmse'] = float(np.sqrt(np.mean(residual ** 2)))
    return out
