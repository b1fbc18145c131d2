"""Stage 4: one linear SVM per anomaly, eq. (24)-(27).

``dry`` and ``viscous`` classify one number each (the base dry friction, the viscous
coefficient: a learned threshold, section IV-D1); ``fss<s>`` classifies normalised
histograms (eq. 27) of system s: of its levels (``use='levels'``, the paper, all
configurations, section IV-D2), of its jump sizes |F_s[j] - F_s[j-1]| (``'jumps'``), or
both concatenated (``'both'``, the default). Jump sizes are a departure: one changepoint
assigned to the wrong system shifts every later level of Algorithm 1's running sum, but
only one jump size (docs/fss.md has the measured effect). Inputs
that are single numbers are standardised with the training mean and std before the
SVM; histograms (fractions in [0, 1]) are used as they are. Departures
(docs/fss.md): the histogram range [r_min, r_max] is the range of the training levels,
and a level outside it counts in the nearest end bin (eq. 27 would drop it). A trained
model is plain JSON (weights, bias, standardisation, bins): inference is
sign(w^T z + b) (eq. 26) without scikit-learn.
"""

from __future__ import annotations

from typing import Mapping, Sequence

import numpy as np

from rwa_monitor.core.params import check_choice, check_int, check_real

MODEL_KIND = 'rwa-monitor-fss-model'
USES = ('levels', 'jumps', 'both')


def histogram(levels: Sequence[float], bins: int, lo: float, hi: float) -> np.ndarray:
    """Return the normalised histogram of eq. (27): fraction of levels per bin."""
    z = np.zeros(bins)
    values = np.asarray(levels, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0 or hi <= lo:
        return z
    idx = np.clip(((values - lo) / (hi - lo) * bins).astype(int), 0, bins - 1)
    np.add.at(z, idx, 1.0)
    return z / values.size


def anomaly_names(n_systems: int) -> tuple[str, ...]:
    """Return the anomaly names: dry, viscous, fss1 .. fssS."""
    return ('dry', 'viscous') + tuple(f'fss{s + 1}' for s in range(n_systems))


def _vector(features: dict, name: str, spec: dict) -> np.ndarray:
    if name == 'dry':
        return np.array([features['base_dry']])
    if name == 'viscous':
        return np.array([features['viscous']])
    s = int(name[3:]) - 1
    parts = []
    if spec.get('use', 'both') in ('levels', 'both'):
        parts.append(histogram(features['levels'][s], spec['bins'], *spec['range']))
    if spec.get('use', 'both') in ('jumps', 'both'):
        parts.append(histogram(jumps(features['levels'][s]), spec['bins'],
                               *spec['jump_range']))
    return np.concatenate(parts)


def jumps(levels: Sequence[float]) -> np.ndarray:
    """Return the jump sizes |F_s[j] - F_s[j-1]| of one FSS's level sequence."""
    return np.abs(np.diff(np.asarray(levels, dtype=float)))


class WindowClassifier:
    """The trained SVMs of every anomaly; ``predict`` gives one boolean per anomaly."""

    def __init__(self, spec: dict) -> None:
        if spec.get('kind') != MODEL_KIND:
            raise ValueError('not an FSS model: kind must be ' + MODEL_KIND)
        self.spec = spec
        self.names = tuple(spec['anomalies'])

    @classmethod
    def fit(cls, features: Sequence[dict], labels: Sequence[str], *, bins: int = 20,
            c: float = 1.0, n_systems: int = 2, seed: int = 0,
            use: str = 'both') -> 'WindowClassifier':
        """Train one linear SVM per anomaly on window features and status labels.

        ``features``: per window {'base_dry', 'viscous', 'levels': [[...] per system]};
        ``labels``: the window's status ('nominal' or an anomaly name).
        """
        from sklearn.svm import LinearSVC
        bins = check_int('bins', bins, 1, 10_000)
        c = check_real('c', c, 0.0, low_open=True)
        check_choice('use', use, USES)
        labels = list(labels)
        if len(labels) != len(features) or not labels:
            raise ValueError('features and labels must be non-empty and of equal length')
        names = anomaly_names(n_systems)
        spec = {'kind': MODEL_KIND, 'version': 1, 'anomalies': list(names), 'models': {},
                'bins': bins, 'c': c, 'n_train': len(labels)}
        for name in names:
            y = np.array([lab == name for lab in labels])
            if y.all() or not y.any():
                raise ValueError(f'training labels must include windows with and without '
                                 f'the {name} anomaly')
            entry: dict = {'bins': bins, 'use': use}
            if name.startswith('fss'):
                s = int(name[3:]) - 1
                values = np.concatenate([np.asarray(f['levels'][s], dtype=float)
                                         for f in features])
                values = values[np.isfinite(values)]
                entry['range'] = [float(values.min()), float(values.max())]
                steps = np.concatenate([jumps(f['levels'][s]) for f in features])
                steps = steps[np.isfinite(steps)]
                entry['jump_range'] = [0.0, float(steps.max()) if steps.size else 1.0]
            z = np.array([_vector(f, name, entry) for f in features])
            if name.startswith('fss'):  # fractions already in [0, 1]
                mean, scale = np.zeros(z.shape[1]), np.ones(z.shape[1])
            else:
                mean, scale = z.mean(axis=0), z.std(axis=0)
                scale = np.where(scale > 1e-12, scale, 1.0)
            svm = LinearSVC(C=c, class_weight='balanced', random_state=seed, max_iter=20000,
                            dual='auto')
            svm.fit((z - mean) / scale, y)
            entry.update(mean=mean.tolist(), scale=scale.tolist(),
                         coef=svm.coef_[0].tolist(), intercept=float(svm.intercept_[0]))
            spec['models'][name] = entry
        return cls(spec)

    def decision(self, features: dict) -> dict[str, float]:
        """Return w^T z + b per anomaly (eq. 26); > 0 means detected."""
        out = {}
        for name in self.names:
            entry = self.spec['models'][name]
            z = _vector(features, name, entry)
            z = (z - np.asarray(entry['mean'])) / np.asarray(entry['scale'])
            out[name] = float(np.dot(entry['coef'], z) + entry['intercept'])
        return out

    def predict(self, features: dict) -> dict[str, bool]:
        """Return one boolean per anomaly.

        An FSS with no assigned jump in the window (a single level) has no level
        distribution to judge: its anomaly is reported False (docs/fss.md).
        """
        out = {name: value > 0.0 for name, value in self.decision(features).items()}
        for name in out:
            if name.startswith('fss') and len(features['levels'][int(name[3:]) - 1]) < 2:
                out[name] = False
        return out


def relative_features(features: dict, reference: dict) -> dict:
    """Return window features in units of the wheel's nominal reference.

    Dividing the torque by the reference's base dry friction and the speed by base dry /
    viscous makes the reference (1, 1), as :func:`rwa_monitor.core.calibrate.fss_inputs`
    does on telemetry: base dry and levels are divided by the reference's base dry, the
    viscous coefficient by the reference's viscous coefficient.
    """
    base, visc = float(reference['base_dry']), float(reference['viscous'])
    if not (base > 0 and visc > 0):
        raise ValueError('the reference needs a positive base dry friction and viscous '
                         'coefficient')
    return {'base_dry': features['base_dry'] / base, 'viscous': features['viscous'] / visc,
            'levels': [[v / base for v in levels] for levels in features['levels']]}


def item_features(item: dict, relative: bool) -> dict:
    """Return an extraction item's features, relative to its reference when asked."""
    if not relative:
        return item['features']
    if 'reference' not in item:
        raise ValueError('relative features need windows with a nominal reference '
                         '(a data set built with realistic anomalies)')
    return relative_features(item['features'], item['reference']['features'])


def train_model(items: Sequence[dict], *, bins: int = 20, c: float = 1.0, seed: int = 0,
                use: str = 'both', relative: bool = False) -> WindowClassifier:
    """Return a WindowClassifier trained on labelled extractions (``features``, ``status``).

    ``relative``: on features relative to each window's nominal reference
    (:func:`relative_features`), the way a calibrated wheel is judged; the spec then
    keeps the training windows' :func:`noise_ratio_stats` (the "unknown" bound; without
    them the measured NOISE_RATIO applies).
    """
    model = WindowClassifier.fit([item_features(it, relative) for it in items],
                                 [it['status'] for it in items], bins=bins, c=c, seed=seed,
                                 use=use)
    model.spec['relative'] = bool(relative)
    noise = noise_ratio_stats(items) if relative else {}
    if noise:
        model.spec['noise_ratio'] = noise
    return model


def detection_matrix(classifier: WindowClassifier, items: Sequence[dict],
                     relative: bool | None = None) -> dict[str, dict[str, float]]:
    """Return status -> anomaly -> fraction of that status's windows flagged.

    ``relative`` None: as the classifier was trained (its spec's ``relative``).
    """
    if relative is None:
        relative = bool(classifier.spec.get('relative', False))
    out: dict[str, dict[str, list[bool]]] = {}
    for it in items:
        flags = classifier.predict(item_features(it, relative))
        row = out.setdefault(it['status'], {k: [] for k in flags})
        for k, v in flags.items():
            row[k].append(v)
    return {st: {k: float(np.mean(v)) for k, v in row.items()} for st, row in out.items()}


# "Unknown" (docs/fss.md, "Calibrated"). The residual noise of stages 1-3 on a window the
# model explains (nominal, or one of the known anomalies) scatters around its reference
# window's: the undetected part of short FSS jumps and the noise estimates. Per status,
# the mean and std of log(window noise / reference noise), measured on development
# windows (bench/fss_sizes.py training pairs, seed 12, 8 windows per status, sizes drawn
# in x1.1-x3). A model trained on relative features keeps its own training set's values
# (spec ``noise_ratio``).
NOISE_RATIO = {'nominal': (-0.0048, 0.052), 'dry': (0.0014, 0.0165),
               'viscous': (0.0024, 0.0199), 'fss1': (0.0618, 0.0645),
               'fss2': (-0.0026, 0.021)}
# Least windows of a status for its (mean, std) in a trained model's spec.
MIN_NOISE_WINDOWS = 5
# Level of the one-sided test "this window's noise is larger than an explained one's".
UNKNOWN_LEVEL = 1.0e-3


def noise_ratio_stats(items: Sequence[dict]) -> dict[str, tuple[float, float]]:
    """Return per status (mean, std) of log(window noise / reference noise).

    ``items``: extraction items with ``status``, ``stats.sigma`` and ``reference.sigma``
    (bench/fss_sizes.py); every status of the simulator is one the model explains. A
    status with fewer than MIN_NOISE_WINDOWS such windows is left out.
    """
    logs: dict[str, list[float]] = {}
    for it in items:
        ref = it.get('reference', {}).get('sigma', 0.0)
        if ref > 0 and it['stats']['sigma'] > 0:
            logs.setdefault(it['status'], []).append(np.log(it['stats']['sigma'] / ref))
    return {k: (float(np.mean(v)), float(np.std(v, ddof=1))) for k, v in logs.items()
            if len(v) >= MIN_NOISE_WINDOWS}


def noise_ratio_bound(stats_by_status: Mapping[str, Sequence[float]] | None = None,
                      level: float = UNKNOWN_LEVEL) -> float:
    """Return the largest window / calibrated noise ratio of an explained window.

    Per status, log(ratio) of its windows is taken as normal with the given (mean, std);
    its one-sided quantile at ``level`` is exp(mean + z_(1 - level) std). The bound is
    the largest over the statuses: a window above it is outside every class's support
    (an explained window of the most scattered class exceeds it with probability
    ``level``).
    """
    from scipy import stats
    check_real('level', level, 0.0, 1.0, low_open=True, high_open=True)
    table = NOISE_RATIO if stats_by_status is None else stats_by_status
    if not table:
        raise ValueError('noise_ratio_bound needs (mean, std) of at least one status')
    z = stats.norm.isf(level)
    return float(max(np.exp(float(m) + z * float(sd)) for m, sd in table.values()))


def relative_verdict(flags: dict[str, bool], window_noise: float, nominal_noise: float,
                     bound: float | None = None
                     ) -> tuple[str, dict[str, bool], str | None]:
    """Return (status, flags, reason) of a window judged against its calibrated nominal.

    ``flags`` come from the SVMs on features normalised by the wheel's calibrated nominal
    (its base dry friction and viscous coefficient are 1 there). Status ``unknown`` (every
    flag False, with the reason) when the window's residual noise after stages 1-3 is
    more than ``bound`` (default :func:`noise_ratio_bound`) times the calibrated
    nominal's: the nominal wheel with the known anomalies does not explain the window,
    and any class would be a guess. Else ``anomalous`` if a flag is set, ``nominal``
    otherwise.
    """
    bound = noise_ratio_bound() if bound is None else check_real('bound', bound, 1.0)
    if not np.isfinite(window_noise) or window_noise > bound * nominal_noise:
        reason = (f'residual noise {window_noise:.3g} N m is more than {bound:.3g} x the '
                  f'calibrated {nominal_noise:.3g} N m (level {UNKNOWN_LEVEL:g}): the window '
                  'is not explained')
        return 'unknown', {k: False for k in flags}, reason
    return ('anomalous' if any(flags.values()) else 'nominal'), dict(flags), None


# Level of the one-sided test "the window's viscous coefficient is above the reference's"
# that a viscous flag must also pass (docs/fss.md, "Calibrated").
VISCOUS_LEVEL = 1.0e-3


def viscous_z(window: float, window_se: float, reference: float, reference_se: float
              ) -> float:
    """Return (window - reference) / sqrt(se_window^2 + se_reference^2).

    Both coefficients are least-squares estimates with standard errors from their own
    windows (core/fss/segments.py); under "no change" the difference is normal with that
    variance. A reference without a standard error (an older calibration) counts as
    exact.
    """
    ref_se = reference_se if np.isfinite(reference_se) else 0.0
    var = window_se ** 2 + ref_se ** 2
    if not np.isfinite(var) or var <= 0:
        return float('nan')
    return float((window - reference) / np.sqrt(var))


def viscous_significant(z: float, level: float = VISCOUS_LEVEL) -> bool:
    """Return whether z exceeds the one-sided normal quantile at ``level`` (NaN: True).

    NaN (no standard error) leaves the classifier's answer alone.
    """
    from scipy import stats
    check_real('level', level, 0.0, 1.0, low_open=True, high_open=True)
    return bool(not np.isfinite(z) or z > stats.norm.isf(level))
