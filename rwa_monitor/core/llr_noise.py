"""The noise model of the LLR detector: AR prewhitening and a level growing with speed.

Not in the paper (whose Lemma 1 assumes white noise of known level; docs/llr.md "Noise
beyond white", "Noise growing with speed"): the model is fitted on the first accepted
samples (:func:`fit_noise_model`), which wait in a buffer meanwhile; every sample is then
divided by the modelled level and AR-filtered before it enters the sums (for the paper's
model in the compiled kernel, core/llr_kernel.py). :class:`NoiseFitting` is the buffering
and replay, a base of :class:`rwa_monitor.core.llr_detector.LLRDetector`.
"""

from __future__ import annotations

from itertools import chain
import math
from typing import NamedTuple

import numpy as np

from rwa_monitor.core import llr_kernel as kern, llr_layout as layout, llr_stats
from rwa_monitor.core.events import AnomalyEvent

# Largest autoregressive order of the noise model (docs/llr.md, "Noise beyond white").
AR_ORDER_LIMIT = 10
DEFAULT_AR_ORDER = 3
# Noise growing with speed (docs/llr.md "Noise growing with speed"): the fit segment is
# extended until |w| spans at least this fraction of its largest value, or this many times
# noise_fit_samples; the slope of the noise level is used only if its t value exceeds
# SPEED_SLOPE_Z; the modelled level is floored at its value at the slowest fitted sample
# and at SPEED_FLOOR x its value at the mean |w|.
SPEED_SPREAD = 0.5
SPEED_FIT_CAP = 20
SPEED_SLOPE_Z = 3.2905267314918945
SPEED_FLOOR = 0.1


class NoiseModel(NamedTuple):
    """Autoregressive model of the friction residual fitted on the first reference.

    ``e_l = sum_i ar[i] e_(l-1-i) + u_l``; ``innovation_std`` = std of ``u``,
    ``residual_std`` = std of ``e``, ``long_run_ratio`` = long-run variance of ``e`` over
    its variance (``sigma_u^2 / (1 - sum ar)^2 / sigma_e^2``; 1 for white noise): the factor
    by which the plain statistic would be too large for slowly varying regressors.
    ``speed_std = (a, b, floor)``: the noise level is ``max(a + b |w|, floor)`` (relative
    units; None: constant), each sample is divided by it before the AR filter.
    """

    ar: tuple[float, ...]
    innovation_std: float
    residual_std: float
    long_run_ratio: float
    speed_std: tuple[float, float, float] | None = None


def fit_noise_model(h: np.ndarray, f: np.ndarray, max_order: int,
                    abs_speed: np.ndarray | None = None) -> NoiseModel:
    """Fit the friction model and an AR model of its residual; order by BIC.

    Not in the paper (whose Lemma 1 assumes white noise). ``h``: regressor rows ``(n,
    p)``, ``f``: friction ``(n,)``. Least squares ``x`` (eq. (2)), residual ``e = f - h
    x``, then for each order ``q <= max_order`` the conditional least-squares AR fit of
    ``e[Q:]`` on its ``q`` lags (common targets, ``Q = max_order``) and
    ``BIC_q = (n - Q) log(RSS_q / (n - Q)) + q log(n - Q)``; the order with the smallest
    BIC whose characteristic roots lie inside the unit circle is kept (0: white noise,
    the paper's case). With ``abs_speed`` (``|w|`` of the rows) the noise level is first
    modelled against it (:func:`fit_speed_std`) and rows, friction and residual are divided
    by that level (weighted least squares) before the AR fit. Deterministic for given
    arrays, so the streaming and the batch path fit the same model.
    """
    h = np.asarray(h, dtype=float)
    f = np.asarray(f, dtype=float)
    speed_std = None
    if abs_speed is not None:
        speed_std = fit_speed_std(h, f, np.asarray(abs_speed, dtype=float))
        if speed_std is not None:
            scale = speed_scale(np.asarray(abs_speed, dtype=float), speed_std)
            h = h / scale[:, None]
            f = f / scale
    pi = h.T @ h
    x = llr_stats.solve_scaled(pi, h.T @ f)
    return residual_noise_model(f - h @ x, h.shape[1], max_order, speed_std)


def residual_noise_model(e: np.ndarray, fitted: int, max_order: int,
                         speed_std: tuple[float, float, float] | None = None) -> NoiseModel:
    """Return the AR model of a least-squares residual ``e`` (``fitted`` parameters).

    The order selection of :func:`fit_noise_model`: conditional least squares of
    ``e[Q:]`` on its ``q`` lags for each ``q <= max_order`` (common targets), solved by
    the normal equations of one lag Gram matrix (the lags of a residual are far from
    collinear, so this equals the orthogonal solution to rounding, at a fraction of its
    cost); ``BIC_q`` as there; an order is kept only if its characteristic roots lie inside
    the unit circle (checked only for an order whose BIC would win).
    """
    e = np.asarray(e, dtype=float)
    n = e.size
    top = int(min(max_order, max((n - 10) // 10, 0)))
    m = n - top
    # gram[i, j] = sum over the common targets of e lagged i times e lagged j (i, j <= top).
    lagged = np.column_stack([e[top - i:n - i] for i in range(top + 1)])
    gram = lagged.T @ lagged
    best: tuple[float, tuple[float, ...], float] = (math.inf, (), 0.0)
    for q in range(top + 1):
        if q == 0:
            coef = np.zeros(0)
            rss = float(gram[0, 0])
        else:
            coef = _solve_lags(gram[1:q + 1, 1:q + 1], gram[1:q + 1, 0])
            if coef is None:
                continue
            rss = float(gram[0, 0] - 2.0 * coef @ gram[1:q + 1, 0]
                        + coef @ gram[1:q + 1, 1:q + 1] @ coef)
        s2 = max(rss / m, 1e-300)
        bic = m * math.log(s2) + q * math.log(m)
        if bic < best[0] and (q == 0 or np.all(np.abs(np.roots(
                np.concatenate([[1.0], -coef]))) < 0.999)):
            best = (bic, tuple(float(a) for a in coef), s2)
    _, ar, s2u = best
    s2e = max(float(e @ e) / max(n - fitted, 1), 1e-300)
    ratio = s2u / (1.0 - sum(ar)) ** 2 / s2e
    return NoiseModel(ar, math.sqrt(s2u), math.sqrt(s2e), ratio, speed_std)


def _solve_lags(gram: np.ndarray, right: np.ndarray) -> np.ndarray | None:
    """Return the AR coefficients of the lag normal equations, None if they are singular."""
    try:
        return np.linalg.solve(gram, right)
    except np.linalg.LinAlgError:
        return None


def fit_speed_std(h: np.ndarray, f: np.ndarray, abs_speed: np.ndarray
                  ) -> tuple[float, float, float] | None:
    """Return ``(a, b, floor)`` of a noise level growing with speed, or None if constant.

    Not in the paper. Least-squares residual ``e`` of the model, then ``|e|`` regressed on
    ``(1, |w|)``: ``E|e| = sqrt(2 / pi) (a' + b' |w|)`` for Gaussian noise whose std is
    linear in ``|w|``, so ``a + b |w|`` is proportional to the std (the scale is irrelevant:
    the level itself is estimated by the detector). Kept only if ``b`` is significant
    (``t > SPEED_SLOPE_Z``, one-sided 5e-4) and positive. ``floor``: the level at the
    smallest ``|w|`` of the fit (no extrapolation towards rest, where the intercept is
    least certain: slower samples are weighted as if at that speed, the conservative
    side), at least ``SPEED_FLOOR (a + b mean|w|)`` (positive).
    """
    x = llr_stats.solve_scaled(h.T @ h, h.T @ f)
    y = np.abs(f - h @ x)
    design = np.column_stack([np.ones_like(abs_speed), abs_speed])
    gram = design.T @ design
    if not np.linalg.det(gram) > 1e-12 * gram[0, 0] * gram[1, 1]:
        return None
    coef = np.linalg.solve(gram, design.T @ y)
    resid = y - design @ coef
    dof = max(y.size - 2, 1)
    s2 = float(resid @ resid) / dof
    se_b = math.sqrt(s2 * float(np.linalg.inv(gram)[1, 1]))
    a, b = float(coef[0]), float(coef[1])
    if not (se_b > 0.0 and b / se_b > SPEED_SLOPE_Z):
        return None
    floor = max(a + b * float(np.min(abs_speed)),
                SPEED_FLOOR * (a + b * float(np.mean(abs_speed))))
    return a, b, floor


def speed_scale(abs_speed, speed_std: tuple[float, float, float]):
    """Return the modelled noise level ``max(a + b |w|, floor)`` (scalar or array)."""
    a, b, floor = speed_std
    if isinstance(abs_speed, np.ndarray):
        return np.maximum(a + b * abs_speed, floor)
    level = a + b * abs_speed
    return level if level > floor else floor


def speed_fit_ready(count: int, fit_n: int, low: float, high: float) -> bool:
    """Return True when ``count`` buffered samples may fit a speed-dependent noise model.

    At least ``fit_n`` samples, and ``|w|`` spanning ``[low, high]`` with ``high - low >=
    SPEED_SPREAD high`` (a slope needs speeds), or ``SPEED_FIT_CAP fit_n`` samples.
    """
    return count >= fit_n and (high - low >= SPEED_SPREAD * high
                               or count >= SPEED_FIT_CAP * fit_n)


def speed_fit_done(count: int, fit_n: int, model: NoiseModel) -> bool:
    """Return True if a fit on ``count`` samples is final (else retry ``fit_n`` later).

    Final when the noise level was found to grow with speed, or at ``SPEED_FIT_CAP
    fit_n`` samples (a constant level then, as without the speed model).
    """
    return model.speed_std is not None or count >= SPEED_FIT_CAP * fit_n


def whiten(values: np.ndarray, ar: tuple[float, ...]) -> np.ndarray:
    """Return ``v_l - sum_i ar[i] v_(l-1-i)`` along axis 0 (missing lags omitted).

    The operations and their order are those of the streaming detector's per-sample
    filter (subtract lag 1, then lag 2, ...), so both paths whiten to the same floats.
    """
    values = np.asarray(values, dtype=float)
    out = values.copy()
    for i, a in enumerate(ar):
        out[i + 1:] -= a * values[:values.shape[0] - i - 1]
    return out


class SampleColumns:
    """Accepted samples of the paper's model waiting for the noise fit, held as arrays.

    What :meth:`NoiseFitting._buffer_arrays` takes from the batch path: iterating gives the
    ``(row, t, f, h, speed)`` tuples :meth:`LLRDetector.update` would have buffered (``h =
    (-sign w, -w)``, the same floats), so it stands for the buffer list, and the fit reads
    the arrays without those tuples. A sample appended later (a stream after a batch)
    is kept in a list after them.
    """

    def __init__(self, rows: np.ndarray, t: np.ndarray, f: np.ndarray, speed: np.ndarray
                 ) -> None:
        self.rows, self.t, self.f, self.speed = rows, t, f, speed
        self._later: list[tuple] = []

    def regressors(self) -> tuple[np.ndarray, np.ndarray]:
        """Return the two regressor columns of the arrays (``-sign w``, ``-w``)."""
        w = self.speed
        return np.where(w > 0.0, -1.0, np.where(w < 0.0, 1.0, 0.0)), -w

    def complete(self) -> bool:
        """Return True if no sample was appended after the arrays."""
        return not self._later

    def __len__(self) -> int:
        return self.rows.size + len(self._later)

    def __iter__(self):
        h1, h2 = self.regressors()
        yield from zip(self.rows.tolist(), self.t.tolist(), self.f.tolist(),
                       zip(h1.tolist(), h2.tolist()), self.speed.tolist())
        yield from self._later

    def append(self, item: tuple) -> None:
        self._later.append(item)

    def extend(self, items) -> None:
        self._later.extend(items)


class NoiseFitting:
    """Buffer the first samples, fit the noise model on them, then prewhiten every sample."""

    def ingest_row(self, row: int, t: float, f: float, h, speed: float) -> list[AnomalyEvent]:
        """Process an accepted sample whose regressor row ``h`` is already computed.

        For :func:`detect_batch` with a model other than eq. (1): the rows are computed
        once for the whole file and validated there (finite, increasing time). While the
        noise model is being fitted the sample is buffered; once fitted the buffer is
        replayed, and every sample is prewhitened (divided by the modelled noise level at
        ``|speed|``, then AR-filtered) before it enters the sums.
        """
        if self._fitting:
            self._buffer.append((row, t, f, h, speed))
            if self._speed_model:
                aw = abs(speed)
                self._wlow = min(self._wlow, aw)
                self._whigh = max(self._whigh, aw)
                if self._next_fit is None:
                    if not speed_fit_ready(len(self._buffer), self._fit_n, self._wlow,
                                           self._whigh):
                        return []
                elif len(self._buffer) < self._next_fit:
                    return []
            elif len(self._buffer) < self._fit_n:
                return []
            return self._fit_and_replay()
        return self._ingest_fitted(row, t, f, h, speed)

    def _buffer_arrays(self, t: np.ndarray, w: np.ndarray, f: np.ndarray, start: int) -> int:
        """Buffer the samples from ``start`` on (paper's model) up to the fit; return the next.

        The acceptance loop compiled (core/llr_kernel.py ``accept_run``); the buffer holds
        what :meth:`update` would have put in it, sample by sample (the regressors ``(-sign
        w, -w)`` formed with numpy: the same floats).
        """
        rows = np.full(self._fit_n - len(self._buffer), -1, dtype=np.int64)
        row0 = int(self._ints[layout.I_ROWS])
        end = kern.accept_run(self._fs, self._ints, t, w, f, start, rows)
        rows = rows[rows >= 0]
        at = start + rows - row0
        samples = SampleColumns(rows, t[at], f[at], w[at])
        if not self._buffer and rows.size == self._fit_n:
            self._buffer = samples   # the whole buffer at once: kept as arrays
        else:
            self._buffer.extend(samples)
        return end

    def _fit_and_replay(self) -> list[AnomalyEvent]:
        """Fit the noise model on the buffered samples, then process them."""
        buffer = self._buffer
        if isinstance(buffer, SampleColumns) and buffer.complete():
            rows, times, friction, speed = buffer.rows, buffer.t, buffer.f, buffer.speed
            h = np.column_stack(buffer.regressors())
        else:
            rows, times, friction, regressors, speed = zip(*buffer)
            h = np.fromiter(chain.from_iterable(regressors), float,
                            len(buffer) * self._p).reshape(len(buffer), self._p)
            friction = np.array(friction, dtype=float)
            speed = np.array(speed, dtype=float)
        speeds = np.abs(speed) if self._speed_model else None
        model = fit_noise_model(h, friction, self._ar_max, speeds)
        if self._speed_model and not speed_fit_done(len(buffer), self._fit_n, model):
            self._next_fit = len(buffer) + self._fit_n
            return []
        self._buffer = []
        self._fitting = False
        self._noise = model
        self._ar = model.ar
        self._speed_std = model.speed_std
        if self._p != 2:
            events: list[AnomalyEvent] = []
            for row, t, f, h_row, w in buffer:
                events.extend(self._ingest_fitted(row, t, f, h_row, w))
            return events
        fs, ints = self._fs, self._ints
        ints[layout.I_AR_ORDER] = len(model.ar)
        fs[ints[layout.I_O_AR]:ints[layout.I_O_AR] + len(model.ar)] = model.ar
        if model.speed_std is not None:
            ints[layout.I_SPEED_MODEL] = 1
            fs[layout.F_SPEED_A:layout.F_SPEED_FLOOR + 1] = model.speed_std
            level = speed_scale(np.abs(speed), model.speed_std)
            friction = friction / level
            h = h / level[:, None]
        self._fast = self._default
        return self._replay(np.array(rows, dtype=np.int64), np.array(times, dtype=float),
                            friction, np.ascontiguousarray(h[:, 0]),
                            np.ascontiguousarray(h[:, 1]))

    def _replay(self, rows: np.ndarray, t: np.ndarray, f: np.ndarray, h1: np.ndarray,
                h2: np.ndarray) -> list[AnomalyEvent]:
        """Feed the buffered samples of the paper's model, already scaled, to the kernel.

        The loop compiled (core/llr_kernel.py ``ingest_run``: the AR filter, the sums and
        the test of each sample in turn), Python at the samples whose flags need it: the
        per-sample path of :meth:`_ingest_fitted`, over arrays.
        """
        events: list[AnomalyEvent] = []
        i, n = 0, rows.size
        while i < n:
            i = kern.ingest_run(self._fs, self._ints, rows, t, f, h1, h2, i)
            if i < n:
                events.extend(self._after(int(self._ints[layout.I_FLAGS])))
            i += 1
        return events

    def _ingest_fitted(self, row: int, t: float, f: float, h, speed: float
                       ) -> list[AnomalyEvent]:
        if self._speed_std is not None:
            level = speed_scale(abs(speed), self._speed_std)
            f = f / level
            if self._p == 2:
                h = (float(h[0]) / level, float(h[1]) / level)
            else:
                h = np.asarray(h, dtype=float) / level
        if self._p == 2:
            flags = kern.ingest(self._fs, self._ints, row, t, f, float(h[0]), float(h[1]))
            return self._after(flags) if flags else []
        if self._ar:
            f, h = self._whiten(f, h)
        return self._update_general(row, t, f, np.asarray(h, dtype=float))
