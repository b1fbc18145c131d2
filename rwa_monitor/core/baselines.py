"""Supervised baselines of the vsadc-gyro-drift paper (Table 1): kNN, naive Bayes, SVM.

They classify each sample (0 healthy, 1 drift, 2 bias) from the same per-axis features as
VSADC: the star-tracker and gyro residuals (eqs. (3), (7)) averaged over the last
``window`` valid samples, the evolving centre of Alg. 1 lines 15-18 (the paper smooths
with the same sliding window; raw per-sample residuals drown a 2e-4 rad/s fault in the
1.4e-4 rad/s star-tracker rate noise). Features are standardised on the training set.
Departures, on purpose: the polynomial kernels are inhomogeneous, ``(gamma x.y + 1)^d``
(a homogeneous kernel cannot place a boundary away from the origin); the SVMs are
one-vs-all (paper section 4) and train on a random subsample of at most ``svm_max_train``
samples, so that 15 kernel fits per run stay feasible on two cores.
"""

from __future__ import annotations

from typing import Callable

import numpy as np
from sklearn.multiclass import OneVsRestClassifier
from sklearn.naive_bayes import GaussianNB
from sklearn.neighbors import KNeighborsClassifier
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from sklearn.svm import SVC

from rwa_monitor.core.attitude import star_tracker_rates
from rwa_monitor.core.params import check_int, check_real

KNN_NEIGHBOURS = (1, 2, 3, 4, 5, 10, 15, 20, 50, 100, 200)
SVM_KERNELS = {'svm-linear': dict(kernel='linear'),
               'svm-poly2': dict(kernel='poly', degree=2, coef0=1.0),
               'svm-poly3': dict(kernel='poly', degree=3, coef0=1.0),
               'svm-poly4': dict(kernel='poly', degree=4, coef0=1.0),
               'svm-rbf': dict(kernel='rbf')}
DEFAULT_SVM_MAX_TRAIN = 3000


def methods() -> dict[str, Callable[[], object]]:
    """Return method name -> factory of an unfitted scikit-learn classifier (Table 1)."""
    out: dict[str, Callable[[], object]] = {}
    for k in KNN_NEIGHBOURS:
        out[f'knn-{k}'] = (lambda k=k: make_pipeline(
            StandardScaler(), KNeighborsClassifier(n_neighbors=k)))
    out['naive-bayes'] = lambda: make_pipeline(StandardScaler(), GaussianNB())
    for name, kw in SVM_KERNELS.items():
        out[name] = (lambda kw=kw: make_pipeline(StandardScaler(), OneVsRestClassifier(
            SVC(C=1.0, gamma='scale', max_iter=1_000_000, **kw))))
    return out


def residuals(time: np.ndarray, gyro: np.ndarray, quaternions: np.ndarray,
              reference: np.ndarray | None, axis: int, max_gap: float = 1.0) -> np.ndarray:
    """Return per-row residuals ``[res_sst, res_gyr]`` (eqs. (3), (7)); NaN where unusable.

    ``time`` (n,) s, ``gyro`` (n, 3) rad/s, ``quaternions`` (n, 4) scalar last,
    ``reference`` (n, 3) or (3,) guidance rate in rad/s (None: zero).
    """
    check_int('axis', axis, 0, 2)
    time = np.asarray(time, dtype=float)
    gyro = np.asarray(gyro, dtype=float)
    if gyro.shape != (len(time), 3):
        raise ValueError(f'gyro must be (n, 3) with n = len(time); got {gyro.shape}')
    ref = np.zeros(3) if reference is None else np.asarray(reference, dtype=float)
    ref = np.broadcast_to(ref, (len(time), 3))[:, axis]
    sst = star_tracker_rates(time, quaternions, max_gap)[:, axis]
    out = np.column_stack([ref - sst, ref - gyro[:, axis]])
    out[~np.isfinite(out).all(axis=1)] = np.nan
    return out


def smoothed_features(res: np.ndarray, window: int) -> np.ndarray:
    """Return the mean of the last ``window`` valid residual rows, per row (rad/s).

    Rows without a valid residual repeat the last value (the detector holds there); rows
    before the first full window are NaN.
    """
    window = check_int('window', window, 1)
    valid = np.flatnonzero(np.isfinite(res).all(axis=1))
    out = np.full(res.shape, np.nan)
    if len(valid) < window:
        return out
    csum = np.cumsum(np.vstack([np.zeros((1, 2)), res[valid]]), axis=0)
    means = (csum[window:] - csum[:-window]) / window
    at = np.full(len(res), -1)
    at[valid[window - 1:]] = np.arange(len(means))
    at = np.maximum.accumulate(at)
    ok = at >= 0
    out[ok] = means[at[ok]]
    return out


def fit_predict(name: str, x_train: np.ndarray, y_train: np.ndarray, x_test: np.ndarray,
                seed: int = 0, svm_max_train: int = DEFAULT_SVM_MAX_TRAIN) -> np.ndarray:
    """Fit method ``name`` on the training rows and return its labels for ``x_test``."""
    factories = methods()
    if name not in factories:
        raise ValueError(f'name must be one of {", ".join(factories)}; got {name!r}')
    check_real('svm_max_train', svm_max_train, 10)
    if name.startswith('svm') and len(x_train) > svm_max_train:
        pick = np.random.default_rng(seed).choice(len(x_train), int(svm_max_train),
                                                  replace=False)
        x_train, y_train = x_train[pick], y_train[pick]
    if len(np.unique(y_train)) < 2:
        return np.full(len(x_test), int(y_train[0]) if len(y_train) else 0)
    model = factories[name]()
    model.fit(x_train, y_train)
    return np.asarray(model.predict(x_test), dtype=int)
