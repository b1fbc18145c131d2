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
- ``signal:<column>``: the residual binned by every other signal of the file (other
  wheels' channels); reported, not used to stop (through the attitude loop they
  correlate with this wheel's own history).
- ``whiteness``: Ljung-Box Q on the first L autocorrelations, chi^2(L).
- ``spectrum``: Fisher's g test for the largest periodogram ordinate (upper bound
  p <= m (1 - g)^(m - 1)).
- ``variance_vs_speed``: Levene's test (median-centred) across speed bins; reported, not
  used to stop the selection (a change of variance does not change the mean model).

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

STOP_TESTS_EXCLUDED = ('variance_vs_speed',)
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
    """Return every residual diagnostic, the tests, and whether the residual passes."""
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
    spec = fisher_g(data.time[::data.stride], thinned)
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
    out['passes'] = not out['failing']
    out['rmse'] = float(np.sqrt(np.mean(residual ** 2)))
    return out
