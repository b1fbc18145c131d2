"""The paper's model, Coulomb + viscous, with friction jumps segmented out.

Model (1) of the llr-realtime paper: f = h x + e, h = -[sign(w), w], x = [dry, viscous].
A friction jump (the anomalies the detectors look for) would otherwise be taken for model
error, so the baseline gives each segment between detected jumps its own dry and viscous
coefficients, as stage 2 of the physics-informed paper does for the dry coefficient
(eq. 12-16; here both coefficients, since a jump may be viscous).

Jumps are found in two stages. First a flexible global fit (model (1) plus a
piecewise-linear function of speed, dense near zero) removes whatever friction does as a
function of speed, so that a Stribeck peak or a drag term, which model (1) lacks, cannot
pass for a jump. Then, at each candidate row k, a local test on the 2w samples around k
asks whether a step of the dry and viscous coefficients at k is needed beyond a smooth
(quadratic in time) variation of both coefficients and of an additive offset: twice the
log-likelihood gain of the step, with the noise known, is chi^2 with 2 degrees of
freedom under "no jump" (nested models). A slow effect (drift, temperature, a thermal
cycle) is absorbed by the quadratic; a jump is not. A row is a jump when the gain is the
largest within +-w and exceeds the Bonferroni threshold (level alpha over n / w windows).
This follows the windowed GLR of the physics-informed paper (eq. 10-11) in spirit, with
the smooth background in place of its prior on the viscous coefficient.

**Decision (rows):** unlike the selection, the jump search uses every row, the held-out
test rows (fitting.held_out_mask) included. A jump is an event of the record, found by a
local test whose level is Bonferroni over the whole record, not a fit to the test rows;
with the test blocks cut out of its windows the test lost nearly all its power (a dry
step of 10 noise std on the drag file: chi^2 590 -> 1, because a test block right before
the step leaves the step confounded with the local time trend).

**Decision (model error is not white noise):** the step test takes the noise as known
and white. Where the background cannot follow the friction (a joint that sticks at
every stop, friction that depends on the position), its residual carries structure
that is correlated over many samples, and a step fits a piece of it: on the robot-joint
records every scan found the cap of 20 "jumps", one at a stop, none a change of the
friction law. So the step statistic is divided by the residual's long-run variance
ratio kappa (:func:`long_run_ratio`): the variance of block means of the standardised
residual, blocks of the scan's stride, over that of white noise (a batch-means estimate
of the spectrum at low frequency, the quantity a step's estimate depends on), the
median over the blocks so that one real jump does not inflate it, and never below 1.
White noise: kappa about 1 (0.79-0.84 on the simulated files, so the test is unchanged);
the robot-joint records: 148-198, no jump left.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from rwa_monitor.core.identify.data import IdentData
from rwa_monitor.core.identify.effects import regressor_columns, spectral_peaks
from rwa_monitor.exceptions import NotIdentifiableError

RIDGE = 1e-9
PEAKS = 3
LOW_SPEED_QUANTILE = 0.1
MAX_ABS_SPEED = 1e5  # rad/s: the LLR detector's max_abs_speed default
FLEX_ROWS = 10000  # the flexible background is fitted on at most about this many rows


def baseline_columns(speed: np.ndarray) -> np.ndarray:
    """Return the regressors of model (1): h = -[sign(w), w] as an (n, 2) array."""
    speed = np.asarray(speed, dtype=float)
    return np.column_stack([-np.sign(speed), -speed])


def check_identifiable(speed: np.ndarray) -> None:
    """Raise NotIdentifiableError naming the parameters the speeds cannot determine."""
    speed = np.asarray(speed, dtype=float)
    top = float(np.max(np.abs(speed))) if speed.size else 0.0
    if not top < MAX_ABS_SPEED:
        raise NotIdentifiableError(
            f'speeds up to {top:g} rad/s are not physical (plausibility limit '
            f'{MAX_ABS_SPEED:g} rad/s): check the speed column and its unit')
    if np.all(speed == 0):
        raise NotIdentifiableError(
            'the wheel never spins (speed always 0): neither dry nor viscous friction is '
            'identifiable')
    spread = np.std(speed) / max(np.max(np.abs(speed)), 1e-300)
    both_signs = np.any(speed > 0) and np.any(speed < 0)
    if spread < 1e-6 and not both_signs:
        raise NotIdentifiableError(
            f'dry and viscous friction are not separable: the speed never varies (always '
            f'{np.median(speed):g} rad/s); use a record in which the speed changes')


@dataclass
class Segments:
    """Segments between friction jumps: start rows (first is 0) and the evidence."""

    starts: list[int] = field(default_factory=lambda: [0])
    evidence: list[dict] = field(default_factory=list)

    def columns(self, speed: np.ndarray) -> np.ndarray:
        """Return the baseline columns, one dry/viscous pair per segment."""
        base = baseline_columns(speed)
        n = len(speed)
        bounds = list(self.starts) + [n]
        cols = []
        for a, b in zip(bounds[:-1], bounds[1:]):
            part = np.zeros((n, 2))
            part[a:b] = base[a:b]
            cols.append(part)
        return np.hstack(cols)

    def names(self) -> list[str]:
        """Return the column names: dry, viscous, then dry@1, viscous@1, ..."""
        out = ['dry', 'viscous']
        for i in range(1, len(self.starts)):
            out += [f'dry@{i}', f'viscous@{i}']
        return out


def flexible_residual(data: IdentData, spacing: int,
                      extra: np.ndarray | None = None) -> np.ndarray:
    """Return the residual of a flexible fit: smooth in speed and slowly varying in time.

    Model (1) plus a piecewise-linear function of speed on each side of zero (the
    fallback effect's columns, free to jump at w = 0) plus dry, viscous and offset terms
    that are piecewise linear in time (knots every ``spacing`` rows): without the time
    terms a slow effect would bend the fitted function of speed and leave a residual that
    is not smooth in time. When the speed passes through zero, a second piecewise-linear
    function of speed on the branch that left zero (history.py ``left_zero``) joins, so
    that friction with hysteresis cannot pass for a string of jumps. ``extra`` columns
    (effects already identified) join the fit. Then sinusoids at the residual's three
    largest spectral peaks are added and the fit repeated, so that a periodic torque does
    not pass for a string of jumps (a step has a broad spectrum that three sinusoids
    hardly absorb). The coefficients are fitted on
    at most about FLEX_ROWS evenly spaced rows; the residual is evaluated on all rows.
    """
    w = data.speed
    n = len(w)
    aw = np.abs(w[w != 0])
    near = [float(np.quantile(aw, q)) for q in (0.005, 0.01, 0.02, 0.04)] if len(aw) else []
    knots = np.unique(np.concatenate([np.quantile(w, np.linspace(0.0, 1.0, 25)),
                                      near, [-x for x in near], [0.0]]))
    knots = knots[(knots >= w.min()) & (knots <= w.max())]
    if w.min() < 0 < w.max() and 0.0 not in knots:
        knots = np.sort(np.append(knots, 0.0))
    count = int(np.clip(n // spacing + 1, 2, 17))
    tknots = np.unique(np.linspace(0, n - 1, count).astype(int)).astype(float)
    t = data.time - data.time[0]

    def design(rows: np.ndarray, freqs: list[float]) -> np.ndarray:
        wr = w[rows]
        hats = [col(wr, None, None) for _, col in
                regressor_columns('smooth_speed', {'knots_rad_s': knots})]
        teye = np.eye(len(tknots))
        thats = np.column_stack([np.interp(rows.astype(float), tknots, teye[j])
                                 for j in range(len(tknots))])
        h = baseline_columns(wr)
        cols = [h, np.column_stack(hats), h[:, :1] * thats, h[:, 1:] * thats, thats]
        if branch is not None:
            cols.append(np.column_stack(hats) * branch[rows, None])
        if extra is not None:
            cols.append(extra.reshape(n, -1)[rows])
        cols += [f(2 * np.pi * fr * t[rows])[:, None] for fr in freqs
                 for f in (np.cos, np.sin)]
        return np.hstack(cols)

    past = data.past
    branch = past.left_zero.astype(float) if past is not None and past.passages and \
        past.left_zero.any() else None
    fit_rows = np.arange(0, n, max(1, n // FLEX_ROWS))
    resid = _residual(design, fit_rows, data, [])
    freqs, _ = spectral_peaks(data.time, resid, PEAKS, refine=False)
    return _residual(design, fit_rows, data, freqs) if freqs else resid


def _residual(design, fit_rows: np.ndarray, data: IdentData, freqs: list[float]
              ) -> np.ndarray:
    s = data.noise_std
    X = design(fit_rows, freqs) / s[fit_rows, None]
    y = data.friction[fit_rows] / s[fit_rows]
    scale = 1.0 / np.maximum(np.sqrt(np.sum(X * X, axis=0)), 1e-300)
    Xs = X * scale
    coef = np.linalg.solve(Xs.T @ Xs + RIDGE * np.eye(X.shape[1]), Xs.T @ y) * scale
    out = np.empty(len(data))
    for start in range(0, len(data), FLEX_ROWS):
        rows = np.arange(start, min(start + FLEX_ROWS, len(data)))
        out[rows] = data.friction[rows] - design(rows, freqs) @ coef
    return out


def _solve_rss(gram: np.ndarray, xy: np.ndarray, yy: np.ndarray) -> np.ndarray:
    """Return the least-squares RSS of a batch of normal equations (scaled, ridged)."""
    d = np.sqrt(np.maximum(np.einsum('...ii->...i', gram), 1e-300))
    g = gram / d[..., :, None] / d[..., None, :]
    g = g + RIDGE * np.eye(g.shape[-1])
    b = xy / d
    coef = np.linalg.solve(g, b[..., None])[..., 0]
    return yy - np.sum(coef * b, axis=-1)


def step_gains(data: IdentData, resid: np.ndarray, ks: np.ndarray, window: int,
               chunk: int = 64) -> np.ndarray:
    """Return the chi^2(2) gain of a coefficient step at each k over a smooth background.

    Normal equations of all windows at once (batches of ``chunk`` windows). Samples in
    the low-speed region (abs(w) below its LOW_SPEED_QUANTILE quantile) are left out:
    friction there may depend on more than the sampled speed (pre-sliding, breakaway,
    the crossing's direction), which would pass for a jump at every zero crossing; a
    real jump shows at every other speed. When friction was differentiated from speed its
    noise is correlated over ``data.stride`` samples, so only every stride-th sample
    enters the test (as the whiteness test does); the chi^2 then holds.
    """
    low_speed = float(np.quantile(np.abs(data.speed), LOW_SPEED_QUANTILE))
    n2 = 2 * window
    tau = np.linspace(-1.0, 1.0, n2)
    poly = np.stack([np.ones(n2), tau, tau ** 2], axis=1)
    after = (np.arange(n2) >= window).astype(float)
    out = np.empty(len(ks))
    for start in range(0, len(ks), chunk):
        kk = ks[start:start + chunk]
        idx = kk[:, None] - window + np.arange(n2)[None, :]
        s = data.noise_std[idx]
        w = data.speed[idx]
        h = np.stack([-np.sign(w), -w], axis=-1)
        smooth = np.concatenate([h[..., :1] * poly, h[..., 1:] * poly,
                                 np.broadcast_to(poly, h.shape[:2] + (3,))], axis=-1)
        keep = (np.abs(w) >= low_speed) * (idx % data.stride == 0) / s
        X = np.concatenate([smooth, h * after[None, :, None]], axis=-1) * keep[..., None]
        y = resid[idx] * keep
        Xt = X.transpose(0, 2, 1)
        gram = np.matmul(Xt, X)             # stacked small products: 7x einsum's speed
        xy = np.matmul(Xt, y[..., None])[..., 0]
        yy = np.einsum('ki,ki->k', y, y)
        full = _solve_rss(gram, xy, yy)
        reduced = _solve_rss(gram[:, :9, :9], xy[:, :9], yy)
        out[start:start + chunk] = reduced - full
    return out


def long_run_ratio(data: IdentData, resid: np.ndarray, block: int) -> float:
    """Return kappa >= 1: the long-run over the white variance of the standardised residual.

    Batch means: the residual over its noise std is cut into blocks of ``block`` rows;
    for white noise block * mean^2 is chi^2(1), median 0.4549. kappa is the median of
    block * mean^2 over that value (robust to the few blocks a real jump spoils). With
    friction derived from speed only every stride-th residual is used (the derivative's
    own correlation is accounted for by the step test's thinning), blocks of at least 5.
    """
    z = (resid / data.noise_std)[::data.stride]
    block = max(5, block // data.stride) if data.stride > 1 else block
    count = len(z) // max(block, 1)
    if count < 5 or block < 2:
        return 1.0
    means = z[:count * block].reshape(count, block).mean(axis=1)
    return max(1.0, float(np.median(block * means * means)) / float(stats.chi2.ppf(0.5, 1)))


def find_jumps(data: IdentData, window: int | None = None, alpha: float = 1e-3,
               max_jumps: int = 20, extra: np.ndarray | None = None) -> Segments:
    """Return the segments between abrupt friction jumps (see the module docstring).

    Greedy: the strongest jump is taken, its step joins the flexible background, and the
    record is scanned again for the next one, so that a large jump's imprint on the
    background fit cannot pass for further jumps.
    """
    n = len(data)
    if window is None:
        window = int(np.clip(n // 40, 30, 500))
        window = max(window, 6 * data.stride)
    segments = Segments()
    if n < 4 * window:
        return segments
    threshold = float(stats.chi2.isf(alpha * window / n, 2))
    stride = max(1, window // 5)
    coarse = np.arange(window, n - window + 1, stride)
    base = baseline_columns(data.speed)
    found: list[int] = []
    while len(found) < max_jumps:
        cols = [] if extra is None else [extra.reshape(n, -1)]
        cols += [base * (np.arange(n) >= k)[:, None] for k in found]
        resid = flexible_residual(data, 4 * window, np.hstack(cols) if cols else None)
        kappa = long_run_ratio(data, resid, stride)
        gains = step_gains(data, resid, coarse, window) / kappa
        for k in found:
            gains[np.abs(coarse - k) < window] = -np.inf
        i = int(np.argmax(gains))
        if gains[i] <= threshold:
            break
        k0 = int(coarse[i])
        fine = np.arange(max(window, k0 - stride), min(n - window, k0 + stride) + 1)
        fine_gains = step_gains(data, resid, fine, window) / kappa
        k = int(fine[int(np.argmax(fine_gains))])
        found.append(k)
        segments.evidence.append({'index': k, 'time': float(data.time[k]),
                                  'step_chi2': float(max(fine_gains)),
                                  'long_run_ratio': kappa,
                                  'threshold': threshold, 'window': window})
    segments.starts = [0] + sorted(found)
    segments.evidence.sort(key=lambda e: e['index'])
    return segments
