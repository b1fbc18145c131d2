"""The nominal friction of a calibrated wheel: its model and the table the detectors read.

:func:`nominal_prediction` evaluates a ``friction_model`` block of calibration.yaml (the
identification's regressors times the block's weights); :class:`NominalWheel` is one
wheel's calibration in force, tabled once so that the calibrated LLR path (batch and
per sample, core/llr_calibrated_step.py) subtracts the nominal in about a microsecond. Written by
core/calibrate.py (the commissioning), read by the pipelines and the detector nodes.
"""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from rwa_monitor.core import llr_calibrated_step
from rwa_monitor.exceptions import ConfigError

# Speed step (rad/s) of the nominal model's table (NominalWheel); knots are added to it.
TABLE_STEP_RAD_S = 0.01
# Reasons of a sample not tested, by the code of llr_calibrated_step.nominal_residual.
_REASONS = (None, 'low_speed_band', 'outside_calibrated_range')
_nominal_residual = llr_calibrated_step.nominal_residual


def nominal_prediction(friction_model: Mapping[str, Any], speed: np.ndarray,
                       time: np.ndarray | None = None,
                       aux: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
    """Return the nominal friction (N m, project sign) of a ``friction_model`` block.

    The regressor columns are identify's (model.regressors_from_config, eq. (1) sign:
    ``h = -[sign(w), w, ...]``) times the block's weights. Raise ConfigError naming a
    missing weight.
    """
    from rwa_monitor.core.identify.model import regressors_from_config
    block = friction_model.get('friction_model', friction_model)
    regs = regressors_from_config(block)
    weights = block.get('weights') or {}
    missing = [n for n in regs.names if n not in weights]
    if missing:
        raise ConfigError(f'friction_model.weights lacks {", ".join(missing)}')
    x = np.array([float(weights[n]) for n in regs.names])
    return regs.matrix(np.asarray(speed, dtype=float), time, aux) @ x


class NominalWheel:
    """One wheel's calibration in force: nominal prediction, low-speed band, speed range.

    The calibrated LLR path (docs/llr.md, section "Calibrated") feeds the unchanged
    model-(1) detector with ``friction - nominal(speed)``; samples inside the low-speed
    band or outside the calibrated speed range are given as NaN (the detector drops and
    counts them as non-finite, and the row index of every event stays the file's row) and
    counted here by reason.

    The nominal model is evaluated from a table built once per calibration: on each side
    of zero, the tested speeds (band edge to the end of the calibrated range) at every
    TABLE_STEP_RAD_S plus the knots of a piecewise-linear effect, interpolated linearly.
    The batch path (:meth:`residual`) and the streaming path (:meth:`residual_one`, a
    node's per-sample call) do the same floating-point operations, so a node and
    ``detect --calibration`` give the same events; a per-sample evaluation of the
    regressors costs milliseconds, the table about a microsecond. ``table_error_nm`` is
    the largest difference from the exact model at the midpoints of the table.
    """

    def __init__(self, block: Mapping[str, Any]) -> None:
        self.block = block
        self.friction_model = block['friction_model']
        band = (block.get('noise') or {}).get('low_speed_band') or {}
        self.band_rad_s = float(band.get('speed_abs_below_rad_s', 0.0))
        lo, hi = block['speed_range_rad_s']
        self.speed_range = (float(lo), float(hi))
        self.tested = self._tested(block.get('tested_speeds_rad_s'))
        knots = [float(k) for e in self.friction_model.get('effects') or []
                 for k in (e.get('params') or {}).get('knots_rad_s', [])]
        self._tables = {side: self._table(side, knots) for side in (1.0, -1.0)}
        self.at_zero = (float(nominal_prediction(self.friction_model, np.zeros(1))[0])
                        if any(a <= 0.0 <= b for a, b in self.tested) else np.nan)
        # Both sides packed for the compiled lookup (also LLRDetector.update_nominal's).
        self.table = llr_calibrated_step.pack_table(
            self.band_rad_s, self.speed_range, self.at_zero, 1.0 / TABLE_STEP_RAD_S,
            _lookup(*self._tables[1.0]), _lookup(*self._tables[-1.0]))

    def _tested(self, intervals: Any) -> tuple[tuple[float, float], ...]:
        """Return the signed speed intervals where the nominal is tested.

        A calibration's ``tested_speeds_rad_s`` (core/calibrate.py ``tested_speeds``);
        one written before it: the calibrated range outside the low-speed band on each
        side (zero speed included when there is no band).
        """
        lo, hi = self.speed_range
        if intervals is not None:
            return tuple((max(float(a), lo), min(float(b), hi)) for a, b in intervals
                         if max(float(a), lo) <= min(float(b), hi))
        if self.band_rad_s == 0.0:
            return ((lo, hi),)
        return tuple((a, b) for a, b in ((lo, min(hi, -self.band_rad_s)),
                                         (max(lo, self.band_rad_s), hi)) if a <= b)

    def _table(self, side: float, knots: list[float]
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Return (|w| grid, nominal, slope to the next point) of one side of zero.

        The grid spans the side's tested speeds (:attr:`tested`); between two tested
        intervals its points are NaN, so that the interpolation there is NaN (not
        tested).
        """
        floor = max(self.band_rad_s, TABLE_STEP_RAD_S * 1e-3)
        parts = []
        for a, b in self.tested:
            near, far = (max(a, 0.0), b) if side > 0 else (max(-b, 0.0), -a)
            if far >= max(near, floor):
                parts.append((max(near, floor), far))
        parts.sort()
        if not parts:
            grid = np.array([floor, floor])
            return grid, np.full(2, np.nan), np.array([np.nan, 0.0])
        start, end = parts[0][0], parts[-1][1]
        gaps = [0.5 * (b0 + a1) for (_, b0), (a1, _) in zip(parts[:-1], parts[1:])]
        if end <= start:
            grid = np.array([start, start])
        else:
            grid = np.unique(np.concatenate([
                np.arange(start, end, TABLE_STEP_RAD_S), [end],
                [abs(k) for k in knots if start < abs(k) < end and k * side > 0],
                [v for part in parts for v in part], gaps]))
        values = nominal_prediction(self.friction_model, side * grid)
        inside = np.zeros(grid.size, dtype=bool)
        for a, b in parts:
            inside |= (grid >= a) & (grid <= b)
        values[~inside] = np.nan
        step = np.diff(grid)
        with np.errstate(invalid='ignore'):
            slope = np.append(np.divide(np.diff(values), step, out=np.zeros_like(step),
                                        where=step > 0), 0.0)
        return grid, values, slope

    @property
    def table_error_nm(self) -> float:
        """Return the largest |table - exact model| at the table's midpoints (N m)."""
        worst = 0.0
        for side, (grid, _, _) in self._tables.items():
            if len(grid) > 1:
                mid = 0.5 * (grid[1:] + grid[:-1]) * side
                exact = nominal_prediction(self.friction_model, mid)
                worst = max(worst, float(np.max(np.abs(self.nominal(mid) - exact))))
        return worst

    def nominal(self, speed: np.ndarray) -> np.ndarray:
        """Return the tabled nominal friction (NaN outside the tables' speeds, except 0)."""
        speed = np.asarray(speed, dtype=float)
        out = np.full(speed.shape, np.nan)
        out[speed == 0.0] = self.at_zero
        for side, (grid, values, slope) in self._tables.items():
            with np.errstate(invalid='ignore'):
                mag = speed * side
                on = (mag >= grid[0]) & (mag <= grid[-1])
            j = np.searchsorted(grid, mag[on], side='right') - 1
            j = np.minimum(j, len(grid) - 1)
            with np.errstate(invalid='ignore'):
                out[on] = np.where(mag[on] == grid[j], values[j],
                                   values[j] + (mag[on] - grid[j]) * slope[j])
        return out

    def residual(self, time: np.ndarray, speed: np.ndarray, friction: np.ndarray
                 ) -> tuple[np.ndarray, dict[str, int]]:
        """Return (friction - nominal, NaN where not tested) and the counts by reason.

        Each side's table is evaluated by ``numpy.interp`` (NaN off the table), which forms
        ``slope_j (|w| - grid_j) + nominal_j`` with the slope computed as in the table: the
        floats of :meth:`residual_one` (test_calibrate checks it point by point); few
        temporaries, as fresh large arrays cost page faults.
        """
        speed = np.asarray(speed, dtype=float)
        friction = np.asarray(friction, dtype=float)
        time = np.asarray(time, dtype=float)
        finite = np.isfinite(speed)
        valid = finite & np.isfinite(friction) & np.isfinite(time)
        mag = np.abs(speed)
        with np.errstate(invalid='ignore'):
            low = valid & (mag < self.band_rad_s)
        (grid, values, _), (grid_below, values_below, _) = (self._tables[1.0],
                                                            self._tables[-1.0])
        out = np.interp(mag, grid, values, np.nan, np.nan)
        np.copyto(out, np.interp(mag, grid_below, values_below, np.nan, np.nan),
                  where=~(speed > 0.0))
        out[speed == 0.0] = self.at_zero
        # Off the tables, or between tested intervals (NaN points): not tested.
        outside = valid & ~low & np.isnan(out)
        np.subtract(friction, out, out=out)
        out[low | ~finite] = np.nan
        return out, {'low_speed_band': int(np.count_nonzero(low)),
                     'outside_calibrated_range': int(np.count_nonzero(outside))}

    def residual_one(self, time: float, speed: float, friction: float
                     ) -> tuple[float, str | None]:
        """Return (friction - nominal, reason not tested or None) of one sample.

        The same arithmetic as :meth:`residual` on one sample (a node's per-sample call):
        core/llr_calibrated_step.py ``nominal_residual`` on :attr:`table`, which also counts the
        samples not tested by reason (:attr:`not_tested`).
        """
        table = self.table
        try:
            out = _nominal_residual(table, time, speed, friction)
        except TypeError:
            out = _nominal_residual(table, float(time), float(speed), float(friction))
        code = table[0]
        return out, (None if code == 0.0 else _REASONS[int(code)])

    @property
    def not_tested(self) -> dict[str, int]:
        """Samples not tested since construction, by reason, through :attr:`table`."""
        return {name: int(self.table[llr_calibrated_step.T_COUNTS + code - 1])
                for code, name in enumerate(_REASONS) if code}


def tested_text(intervals: Any) -> str:
    """Return tested speed intervals as text: ``tested at -250.0..-3.0, 3.0..240.0 rad/s``."""
    if not intervals:
        return 'no speed tested'
    return 'tested at ' + ', '.join(f'{a:.1f}..{b:.1f}' for a, b in intervals) + ' rad/s'


def _lookup(grid: np.ndarray, values: np.ndarray, slope: np.ndarray) -> tuple:
    """Return one side's table with a bucket index for the binary search.

    ``first[b]`` counts the grid points at or below ``grid[0] + (b - 1) h`` (``h`` =
    TABLE_STEP_RAD_S); a speed ``m`` on the table falls in bucket ``b = int((m - grid[0]) /
    h)`` (within one bucket after rounding), so its interval lies between ``first[b]`` and
    ``first[b + 3]``: the search sees a few points, with the answer of a full one.
    """
    count = int((grid[-1] - grid[0]) / TABLE_STEP_RAD_S) + 6   # b + 3 < count on the table
    edges = grid[0] + (np.arange(count) - 1.0) * TABLE_STEP_RAD_S
    first = np.searchsorted(grid, edges, side='right')
    return grid, values, slope, first
