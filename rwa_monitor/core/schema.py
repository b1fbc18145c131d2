"""The parameters of every detector and tool, defined once: name, type, default, range, unit.

Each :class:`Schema` is the block of one node in config/rwa_monitor.yaml, and the same
names configure the file commands (``rwa-monitor detect``/``diagnose``). From these
definitions come the ROS ParameterDescriptors (nodes/common.py), the YAML loading of every
command (telemetry/parameters_file.py), the ``--help`` texts and the tables of
docs/parameters.md (:func:`markdown_table`). :meth:`Param.check` is the one validation of
a value; its bounds are the algorithm's own (test/test_schema.py checks that they agree).

An automatic value is spelled :data:`AUTO` (``'auto'``) in Python, YAML and ROS alike.
Numbers written without a dot (``1e-5``, which YAML 1.1 reads as a string) are accepted for
float parameters everywhere. A parameter's ``scope`` says where it applies: ``all``
(nodes and file commands), ``node`` (the ROS node only: topics, QoS, health) or ``file``
(file commands only). ``required`` parameters have no default and are never written in
the shipped parameters file.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import difflib
import math
import textwrap
from typing import Any, Callable, Iterator, Mapping, Sequence

from rwa_monitor.core import gyro_calibration as gc
from rwa_monitor.core.params import AUTO, check_choice, check_int, check_real
from rwa_monitor.exceptions import ConfigError

__all__ = ['AUTO', 'FLEET', 'FSS', 'IDENTIFY', 'LLR', 'Param', 'REPLAY', 'SCHEMAS', 'Schema',
           'VSADC', 'help_text', 'markdown_table', 'parameters_document', 'yaml_block']

SCOPES = ('all', 'node', 'file')


@dataclass(frozen=True)
class Param:
    """One parameter: default, one-line meaning, allowed values, unit, where it applies.

    The value type is ``kind`` (default: the type of ``default``): bool, int, float, str or
    list (of the element type of ``default``). Numbers lie in ``[low, high]``
    (``low_open``/``high_open`` exclude an end point); strings may be limited to
    ``choices``; ``auto`` parameters also take :data:`AUTO`; ``validate`` adds a check of
    its own (ValueError naming the parameter). ``read_only`` parameters of a node are set
    at start-up only.
    """

    name: str
    default: Any
    description: str
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    choices: tuple[str, ...] | None = None
    read_only: bool = False
    validate: Callable[[Any], Any] | None = None
    unit: str = ''
    auto: bool = False
    required: bool = False
    scope: str = 'all'
    kind: type | None = None

    def __post_init__(self) -> None:
        if self.scope not in SCOPES:
            raise ValueError(f'{self.name}: scope must be one of {SCOPES}')

    @property
    def type(self) -> type:
        """The value type: bool, int, float, str or list."""
        return self.kind or type(self.default)

    def check(self, value: Any) -> Any:
        """Return ``value`` normalised if allowed, else raise ValueError naming the parameter."""
        if self.auto and value == AUTO:
            return AUTO
        kind = self.type
        if kind is bool:
            if not isinstance(value, bool):
                raise ValueError(f'{self.name} must be true or false, got {value!r}')
        elif kind is int:
            value = check_int(self.name, value,
                              None if self.low is None else int(self.low),
                              None if self.high is None else int(self.high))
        elif kind is float:
            value = check_real(self.name, _number(value),
                               -math.inf if self.low is None else self.low,
                               math.inf if self.high is None else self.high,
                               self.low_open or self.low is None,
                               self.high_open or self.high is None)
        elif kind is str:
            if not isinstance(value, str):
                raise ValueError(f'{self.name} must be a string, got {value!r}')
            if self.choices is not None:
                check_choice(self.name, value, self.choices)
        elif kind is list:
            value = self._check_list(value)
        if self.validate is not None:
            self.validate(value)
        return value

    def _check_list(self, value: Any) -> list:
        if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
            try:
                value = list(value)  # ROS arrays (array.array)
            except TypeError:
                raise ValueError(f'{self.name} must be a list, got {value!r}') from None
        items = list(value)
        if self.default and isinstance(self.default[0], float):
            return [check_real(self.name, _number(v)) for v in items]
        if not all(isinstance(v, str) for v in items):
            raise ValueError(f'{self.name} must be a list of strings, got {value!r}')
        return items

    def allowed(self) -> str:
        """Return the allowed values in words (for help texts and docs)."""
        parts = []
        if self.low is not None or self.high is not None:
            low = '-inf' if self.low is None else f'{self.low:g}'
            high = 'inf' if self.high is None else f'{self.high:g}'
            parts.append(f'{"(" if self.low_open or self.low is None else "["}{low}, '
                         f'{high}{")" if self.high_open or self.high is None else "]"}')
        if self.choices:
            parts.append(', '.join(self.choices))
        elif self.type is bool:
            parts.append('true, false')
        if self.auto:
            parts.append(AUTO)
        return ' or '.join(parts)


def _number(value: Any) -> Any:
    """Return a float for a numeric string (``1e-5`` in YAML 1.1 and ROS), else ``value``."""
    if isinstance(value, str):
        try:
            return float(value)
        except ValueError:
            return value
    return value


@dataclass(frozen=True)
class Schema:
    """The parameters of one detector or tool: the block ``name`` of the parameters file."""

    name: str
    params: tuple[Param, ...]
    summary: str = ''
    relations: Callable[[dict[str, Any]], None] | None = None

    def __iter__(self) -> Iterator[Param]:
        return iter(self.params)

    def __getitem__(self, name: str) -> Param:
        for p in self.params:
            if p.name == name:
                return p
        raise KeyError(name)

    def names(self, scopes: Sequence[str] = SCOPES) -> tuple[str, ...]:
        """Return the parameter names of the given scopes, in order."""
        return tuple(p.name for p in self.params if p.scope in scopes)

    def for_node(self) -> tuple[Param, ...]:
        """Return the parameters a node declares (every scope but ``file``)."""
        return tuple(p for p in self.params if p.scope != 'file')

    def defaults(self) -> dict[str, Any]:
        """Return name -> default of every parameter that has one (not ``required``)."""
        return {p.name: p.default for p in self.params if not p.required}

    def nearest(self, name: str) -> str:
        """Return ``"; did you mean 'x'?"`` for the closest known name, or ``''``."""
        close = difflib.get_close_matches(name, [p.name for p in self.params], n=1)
        return f"; did you mean '{close[0]}'?" if close else ''

    def unknown(self, names: Sequence[str]) -> None:
        """Raise ConfigError for the first name that is not a parameter of this schema."""
        known = {p.name for p in self.params} | SHARED_NAMES
        for name in names:
            if name not in known:
                raise ConfigError(f'{self.name}: unknown parameter {name!r}'
                                  f'{self.nearest(name)}')

    def validate(self, values: Mapping[str, Any], *, strict: bool = True) -> dict[str, Any]:
        """Return every parameter's checked value: ``values`` over the defaults.

        Unknown names raise ConfigError naming the nearest known one (``strict``), or are
        dropped; a bad value raises ConfigError naming the parameter; then the schema's
        ``relations`` (rules between parameters, the algorithm's own) are checked.
        """
        if strict:
            self.unknown(list(values))
        out: dict[str, Any] = {}
        for p in self.params:
            if p.name in values:
                value = values[p.name]
            elif p.required:
                raise ConfigError(f'{self.name}: parameter {p.name} is required')
            else:
                value = p.default
            try:
                out[p.name] = p.check(value)
            except ValueError as err:
                raise ConfigError(f'{self.name}: {err}') from None
        if self.relations is not None:
            try:
                self.relations(out)
            except ValueError as err:
                raise ConfigError(f'{self.name}: {err}') from None
        return out


# ------------------------------------------------------------------- shared parameters

# The commissioning calibration, the same for every detector (docs/contracts.md). Read by
# the file pipelines and the nodes (not a detector keyword: scope node, accepted in files).
CALIBRATION_FILE = Param('calibration_file', '', 'Commissioning calibration (`rwa-monitor '
                         'calibrate` DIR/calibration.yaml): wheels are judged against their '
                         'nominal; empty = none. A missing or malformed file is refused '
                         'naming the key; a node keeps its last good one.', scope='node')

# Plausibility limits of a wheel's samples: the LLR detector's and the window diagnoser's
# (one definition, two blocks: a sample no wheel can produce is never tested by either).
MAX_ABS_SPEED = Param('max_abs_speed', 1.0e5, 'Samples at or beyond this speed are dropped '
                      'and counted out_of_range.', low=0.0, low_open=True, unit='rad/s')
MAX_ABS_FRICTION = Param('max_abs_friction', 1.0e3, 'Samples at or beyond this friction are '
                         'dropped and counted out_of_range.', low=0.0, low_open=True,
                         unit='N m')

# Names every node has or ROS adds: accepted in any block, used by none of the algorithms.
SHARED_NAMES = frozenset({'use_sim_time'})


def _wheels(scope: str = 'node') -> Param:
    return Param('wheels', '', 'Comma-separated wheel ids to monitor; empty = every wheel '
                 'seen (up to max_wheels).', scope=scope)


MAX_WHEELS = Param('max_wheels', 16, 'Most wheels monitored at once (bounds memory).', low=1,
                   high=256, read_only=True, scope='node')
STALE_TIMEOUT = Param('stale_timeout', 3.0, 'Seconds without input before health is '
                      'STALE.', low=0.0, low_open=True, read_only=True, unit='s',
                      scope='node')
DIAGNOSTIC_PERIOD = Param('diagnostic_period', 1.0, 'Seconds between /diagnostics '
                          'messages.', low=0.01, high=60.0, read_only=True, unit='s',
                          scope='node')


EVENTS_FILE = Param('events_file', '', 'JSON Lines journal of every event and '
                    'acknowledgement, flushed and fsynced per line; its unacknowledged '
                    'anomalies are reloaded at start. Empty = none (anomalies are latched '
                    'in memory only).', read_only=True, scope='node')
WHEEL_TIMEOUT = Param('wheel_timeout', 600.0, 'Seconds of wall time without input after '
                      'which a wheel is freed (its detector and state; latched anomalies '
                      'stay); 0 = never.', low=0.0, unit='s', scope='node')


def _time_jump(what: str) -> Param:
    return Param('time_jump', 1.0, f'A stamp more than this before the last one restarts '
                 f'{what} (replay loop); smaller steps back are dropped.', low=0.0,
                 low_open=True, unit='s', scope='node')


# ---------------------------------------------------------------------------------- LLR

#: ``noise_ar_max_order`` ``auto`` with an estimated noise level (docs/llr.md "Noise beyond
#: white"); with ``noise_std`` given, 0 (white noise, the paper).
LLR_AUTO_AR_ORDER = 3


def llr_resolve(values: Mapping[str, Any], p: int = 2) -> dict[str, Any]:
    """Return the LLR detector's parameters with ``auto`` resolved (ValueError if they conflict).

    ``values``: the detector parameters (scope ``all``), each checked by its
    :meth:`Param.check`; ``p``: the friction model's number of columns (2: eq. (1)). The
    rules between them are the algorithm's (llr-realtime paper, Algorithm 1, and
    docs/llr.md): ``window >= max(10, p + 2)``; ``k_verif`` in ``[0, window - 1]``
    (``auto``: ``window // 2``, the paper's experiments); ``noise_std`` ``auto`` -> None
    (estimated on the reference); ``noise_ar_max_order`` ``auto`` -> 3, or 0 with a given
    ``noise_std`` (then it must be 0); ``noise_fit_samples`` ``auto`` -> ``2 window + 1``,
    at least ``max(p + 2 noise_ar_max_order + 10, 20)``; ``noise_speed_model`` needs an
    estimated noise level; ``reference_max`` 0 -> None (growing reference), else at least
    ``window + 1``.
    """
    out = {name: values[name] for name in LLR.names(('all',))}
    window = check_int('window', out['window'], max(10, p + 2))
    k_verif = window // 2 if out['k_verif'] == AUTO else out['k_verif']
    out['k_verif'] = check_int('k_verif', k_verif, 0, window - 1)
    noise_std = None if out['noise_std'] == AUTO else out['noise_std']
    out['noise_std'] = noise_std
    order = out['noise_ar_max_order']
    if order == AUTO:
        order = LLR_AUTO_AR_ORDER if noise_std is None else 0
    elif noise_std is not None and order > 0:
        raise ValueError('noise_ar_max_order must be 0 when noise_std is given (a known noise '
                         f'level means white noise), got {order}')
    out['noise_ar_max_order'] = order
    fit = 2 * window + 1 if out['noise_fit_samples'] == AUTO else out['noise_fit_samples']
    high = int(LLR['noise_fit_samples'].high)
    out['noise_fit_samples'] = check_int('noise_fit_samples', fit, max(p + 2 * order + 10, 20),
                                         high)
    if out['noise_speed_model'] and noise_std is not None:
        raise ValueError('noise_speed_model needs an estimated noise level (noise_std auto), '
                         f'got noise_std={noise_std}')
    reference_max = out['reference_max'] or None
    if reference_max is not None:
        reference_max = check_int('reference_max', reference_max, window + 1,
                                  int(LLR['reference_max'].high))
    out['reference_max'] = reference_max
    return out


LLR = Schema('llr_detector', (
    Param('window', 500, 'w: samples after a candidate change used by the LLR test '
          '(llr-realtime paper, Algorithm 1).', low=10, unit='samples'),
    Param('k_verif', AUTO, 'Verification samples before a declaration, below window; '
          'auto = window / 2 (the paper).', low=0, auto=True, kind=int, unit='samples'),
    Param('false_alarm_rate', 1.0e-5, 'r: declare when the nominal p-value is at most this '
          '(per test).', low=0.0, high=1.0, low_open=True, high_open=True),
    Param('noise_std', AUTO, 'Friction noise standard deviation; auto = estimate it from '
          'the reference fit.', low=0.0, low_open=True, auto=True, kind=float, unit='N m'),
    Param('category_level', 1.0e-3, 'Level of each dry / viscous test that names the kind '
          'of a change.', low=0.0, high=1.0, low_open=True, high_open=True),
    Param('category_revisions', 3, 'Re-checks of the kind of a change as data arrive.',
          low=0, high=60),
    Param('refine_change', True, 'Refine the change time by maximum likelihood.'),
    Param('min_excitation', 1.0e-6, 'Smallest det(corr(Pi_P)): below it a test is skipped '
          'and counted ill_conditioned.', low=0.0, high=1.0, high_open=True),
    MAX_ABS_SPEED,
    MAX_ABS_FRICTION,
    Param('noise_ar_max_order', AUTO, 'Largest order of the AR noise model fitted on the '
          'first samples and used to prewhiten them (docs/llr.md); auto = 3 with an '
          'estimated noise level, 0 with noise_std given (white noise, the paper).', low=0,
          high=10, auto=True, kind=int),
    Param('noise_fit_samples', AUTO, 'Samples that fit the AR noise model; auto = '
          '2 window + 1.', low=20, high=10_000_000, auto=True, kind=int, unit='samples'),
    Param('reference_max', 0, 'Longest reference segment (sliding reference that follows '
          'slow drifts, docs/llr.md); 0 = growing reference (the paper).', low=0,
          high=10_000_000, unit='samples'),
    Param('noise_speed_model', False, 'Model the noise level against |w| on the fit segment '
          'and weight the samples by it (noise growing with speed, docs/llr.md); needs '
          'noise_std auto.'),
    Param('friction_model_file', '', 'Refined friction model written by `rwa-monitor '
          'identify` (friction_model.yaml); empty = model (1).', scope='file'),
    CALIBRATION_FILE,
    _wheels(),
    MAX_WHEELS,
    _time_jump("the wheel's detector"),
    STALE_TIMEOUT,
    DIAGNOSTIC_PERIOD,
    EVENTS_FILE,
    WHEEL_TIMEOUT,
    Param('telemetry_reliability', 'reliable', 'QoS of the telemetry/wheels subscription: '
          'reliable (keep all, no loss) or best_effort (hears a sensor-data publisher; '
          'samples may be lost).', choices=('reliable', 'best_effort'), read_only=True,
          scope='node'),
), 'Online LLR friction-change detector (llr-realtime paper, Algorithm 1); docs/llr.md.',
    llr_resolve)

# ---------------------------------------------------------------------------------- FSS

FSS = Schema('fss_diagnoser', (
    Param('window_length', 80_000, 'Samples per diagnosed window (the paper: ~80,000, a few '
          'hours).', low=200, high=10_000_000, read_only=True, unit='samples', scope='node'),
    Param('window_period', 20_000, 'Samples between two diagnoses of a wheel.', low=1,
          high=10_000_000, unit='samples', scope='node'),
    Param('wglr_window', 20, 'w: half-window of the changepoint statistic.', low=2,
          high=100_000, unit='samples'),
    Param('w_bias', 1.0e-4, 'W_b: weight of the viscous prior, eq. (11b).', low=0.0),
    Param('viscous_prior', 1.0, 'f~v: prior viscous coefficient (normalised units).'),
    Param('p_false', 1.0e-9, 'False-positive probability per sample of the changepoint '
          'threshold.', low=0.0, high=1.0, low_open=True, high_open=True),
    Param('dk_error', 10, 'Samples left out each side of a changepoint in the least squares '
          '(w / 2).', low=0, high=100_000, unit='samples'),
    Param('beam', 256, 'Most DP states kept per changepoint (assignment bound).', low=1,
          high=1_000_000),
    Param('torque_scale_nm', 2.0e-4, 'One normalised torque unit.', low=0.0, low_open=True,
          unit='N m'),
    Param('speed_scale_rad_s', 400.0, 'One normalised speed unit.', low=0.0, low_open=True,
          unit='rad/s'),
    MAX_ABS_SPEED,
    MAX_ABS_FRICTION,
    Param('model', '', 'Classifier model file (JSON from `rwa-monitor fss train`); empty = '
          'the shipped model.', read_only=True),
    CALIBRATION_FILE,
    _wheels(),
    MAX_WHEELS,
    STALE_TIMEOUT,
    DIAGNOSTIC_PERIOD,
    EVENTS_FILE,
    WHEEL_TIMEOUT,
), 'FSS window diagnoser (physics-informed FSS paper); docs/fss.md.',
    lambda values: fss_config(values))

# -------------------------------------------------------------------------------- VSADC


def _axes(value: str) -> None:
    names = [a.strip() for a in value.split(',') if a.strip()]
    if not names:
        raise ValueError(f'axes must name at least one of x, y, z; got {value!r}')
    for a in names:
        check_choice('axes', a, ('x', 'y', 'z'))


def _three(value: list) -> None:
    if len(value) != 3:
        raise ValueError(f'reference_rate must be 3 numbers (rad/s), got {value!r}')


#: Parameters of the residual gyro diagnosis (core/gyro_diagnosis.py), not VsadcDetector's.
RESIDUAL_PARAMETERS = ('feature', 'calibration_file', 'saturation_rad_s', 'residual_block',
                       'residual_nominal_blocks', 'residual_tracking_blocks',
                       'residual_guard_blocks', 'residual_fit_blocks',
                       'residual_decide_blocks', 'residual_confirm_blocks',
                       'residual_max_wait_blocks', 'residual_decide_chi2',
                       'residual_freeze_fraction', 'residual_recovery_fraction',
                       'residual_cusum_threshold', 'residual_cusum_allowance')

VSADC = Schema('vsadc_detector', (
    Param('feature', 'residual', 'residual: gyro minus star-tracker rate, the true rate '
          'cancels (works under guidance); paper: the two residuals of Algorithm 1 '
          '(docs/vsadc.md).', choices=('residual', 'paper')),
    # The shared calibration file; here a detector keyword (its gyro block sets the
    # residual thresholds), so the same parameter with the detector's scope.
    replace(CALIBRATION_FILE, scope='all', description=CALIBRATION_FILE.description.replace(
        'wheels are judged against their nominal', 'its gyro block sets the residual '
        'thresholds')),
    Param('saturation_rad_s', 0.35, 'A gyro rate at or above this is saturated: held and '
          'reported, never diagnosed.', low=0.0, low_open=True, unit='rad/s'),
    Param('residual_block', gc.DEFAULT_BLOCK, 'Residual steps per block mean (the '
          'statistic).', low=2, high=100_000, unit='samples'),
    Param('residual_nominal_blocks', 6, 'Blocks of the first nominal level.', low=1,
          high=100_000),
    Param('residual_tracking_blocks', 30, 'Running-mean length of the tracked nominal; 0 = '
          'fixed.', low=0, high=1_000_000),
    Param('residual_guard_blocks', 3, 'Blocks between the newest one and the one that '
          'teaches the nominal.', low=0, high=1000),
    Param('residual_fit_blocks', gc.DEFAULT_FIT_BLOCKS, 'Blocks of the slope that turns a '
          'drift into a bias and back.', low=3, high=10_000),
    Param('residual_decide_blocks', 24, 'Blocks of the step-or-ramp decision.', low=3,
          high=10_000),
    Param('residual_confirm_blocks', 2, 'Successive blocks that confirm a change.', low=1,
          high=1000),
    Param('residual_max_wait_blocks', 2, 'Blocks after which an undecided kind is the '
          'better fit.', low=0, high=1000),
    Param('residual_decide_chi2', 6.0, 'Margin (block variances) by which step or ramp '
          'must fit better.', low=0.0),
    Param('residual_freeze_fraction', 0.5, 'The nominal stops learning beyond this '
          'fraction of the level threshold.', low=0.0, high=1.0),
    Param('residual_recovery_fraction', 0.5, 'A fault ends below this fraction of the '
          'level threshold.', low=0.0, high=1.0, low_open=True),
    Param('residual_cusum_threshold', 6.0, 'CUSUM of the block distances (block standard '
          'deviations) that starts the kind decision; 0 = level test only.', low=0.0),
    Param('residual_cusum_allowance', 1.5, 'CUSUM reference value (block standard '
          'deviations): the lag of the tracked nominal under a slow wander.', low=0.0),
    Param('window', 200, 'SW: samples of the nominal batch and of the evolving window '
          '(vsadc paper, Algorithm 1).', low=2, high=100_000, unit='samples'),
    Param('sigma_window', AUTO, 'Distances in the sigma of line 22; auto = window (the '
          'paper).', low=2, high=100_000, auto=True, kind=int, unit='samples'),
    Param('distance_threshold', 1.5e-5, 'thr_dis: a distance between class centres above '
          'it is a fault.', low=0.0, low_open=True, unit='rad/s'),
    Param('reference_window', 1200, 'Healthy sigmas behind the sigma limits; auto = '
          'window.', low=1, high=1_000_000, auto=True, unit='samples'),
    Param('margin', 1.5, 'sigma_lim1 = margin x max reference sigma: enter drift above it.',
          low=0.0, low_open=True),
    Param('exit_limit', 'max', 'Reference statistic of sigma_lim2 (stay in drift above it).',
          choices=('max', 'mean')),
    Param('exit_margin', 1.25, 'Factor of sigma_lim2.', low=0.0, low_open=True),
    Param('hold', 1, 'Samples a new label must persist before it is adopted (1 = at once).',
          low=1, high=100_000, unit='samples'),
    Param('nominal_tracking', 0, 'Samples of the running mean that tracks the nominal centre '
          'while healthy; 0 = fixed centre (the paper).', low=0, unit='samples'),
    Param('freeze_fraction', 0.5, 'Learning stops while the distance exceeds this fraction '
          'of distance_threshold.', low=0.0, high=1.0),
    Param('adaptive', True, 'Enter drift from a lasting bias above the sigmas of that bias '
          '(self-adaptive limit).'),
    Param('recovery_fraction', 0.75, 'A fault ends when the distance falls below this '
          'fraction of distance_threshold.', low=0.0, high=1.0, low_open=True),
    Param('max_gap', 1.0, 'Seconds between star-tracker samples above which the '
          'star-tracker rate restarts.', low=0.0, low_open=True, unit='s'),
    Param('norm_tolerance', 0.1, 'Quaternions whose norm is off 1 by more than this are '
          'rejected.', low=0.0, high=1.0, low_open=True, high_open=True),
    Param('axes', 'x,y,z', 'Comma-separated gyro axes to monitor (x, y, z).',
          validate=_axes),
    Param('reference_rate', [0.0, 0.0, 0.0], 'Guidance body rate (x y z) used when the '
          'file has no ref_* columns or telemetry/reference_rate is silent.', unit='rad/s',
          validate=_three),
    Param('reference_timeout', 1.0, 'Seconds of data time without telemetry/reference_rate '
          'after which reference_rate is used.', low=0.0, low_open=True, unit='s',
          scope='node'),
    Param('pair_tolerance', 1.0e-3, 'Seconds within which a gyro and a star-tracker stamp '
          'are the same sample.', low=0.0, high=1.0, unit='s', scope='node'),
    Param('max_lag', 40, 'Gyro samples that may wait for their star-tracker match.', low=1,
          high=10_000, read_only=True, unit='samples', scope='node'),
    _time_jump('the detector'),
    STALE_TIMEOUT,
    DIAGNOSTIC_PERIOD,
    EVENTS_FILE,
), 'VSADC gyro drift/bias classifier (vsadc paper, Algorithm 1); docs/vsadc.md. Samples '
   'are star-tracker/gyro pairs.', lambda values: _vsadc_detector(values))

# ----------------------------------------------------------------------- identification

IDENTIFY = Schema('identify', (
    Param('half_width', AUTO, 'Half window of the local-polynomial differentiator; auto = '
          'chosen from the data (noise against bias) when friction is derived from speed, '
          '5 otherwise.', low=1, high=1000, auto=True, kind=int, unit='samples',
          scope='file'),
    Param('alpha', 1.0e-3, 'Family-wise level of the effect and jump tests.', low=0.0,
          high=0.5, low_open=True, scope='file'),
    Param('jumps', True, 'Segment friction jumps before fitting.', scope='file'),
    Param('identical_wheels', True, 'With --wheel all: the wheels are of one design, so '
          'effects are selected on their pooled evidence and a wheel is flagged when its '
          'own data contradict its siblings; false = each wheel alone.', scope='file'),
    Param('inertia', AUTO, 'Wheel inertia J: friction = J dw/dt - K_T I (eq. 1b) when the '
          'file has no friction column; auto = none (the coast-down folder: its pendulum).',
          low=0.0, low_open=True, auto=True, kind=float, unit='kg m^2', scope='file'),
    Param('torque_constant', AUTO, 'Motor torque constant K_T of eq. 1b, needed with a '
          '<id>_current column; auto = none.', low=0.0, low_open=True, auto=True,
          kind=float, unit='N m/A', scope='file'),
), 'Identification of what the friction model misses (`rwa-monitor identify`); '
   'docs/identify.md.')

# -------------------------------------------------------------------------------- fleet


def _limit(level: str, unit: str) -> Param:
    return Param(f'{level}_limit', 0.0, f"Limit of a wheel's {level} friction level whose "
                 'projected crossing (date and 95 % interval) `rwa-monitor fleet` reports: '
                 'the absolute level without a calibration, the rise against the nominal '
                 'with one (docs/fleet.md "Trend of a wheel"); 0.0 = none.', low=0.0,
                 unit=unit, scope='file')


FLEET = Schema('fleet', (
    _limit('dry', 'N m'), _limit('viscous', 'N m s/rad'),
    Param('epoch_utc', '', 'What time 0 of the archive is, as ISO 8601 UTC (e.g. '
          '2026-01-01T00:00:00Z): the outputs give calendar times; empty = the epoch_utc of '
          "the archive's archive.yaml, if any.", scope='file'),
), 'Friction trend and times of `rwa-monitor fleet` (`--config`); docs/fleet.md.')

# ------------------------------------------------------------------------------- replay

REPLAY = Schema('telemetry_replay', (
    Param('file', '', 'Telemetry to replay: CSV or Parquet file, rosbag2 folder, bare .mcap or '
          '.db3 file, or CCSDS space packets (.bin); required, give it with -p file:=PATH '
          '(never in a parameters file, where it would beat the command line).',
          read_only=True, required=True, scope='node'),
    Param('topics', '', 'Topics of the streams in a recording, as wheels=/a,gyro=/b,'
          'star_tracker=/c,reference_rate=/d; streams not named keep the DESIGN.md topics '
          '(/telemetry/wheels, /telemetry/gyro, /telemetry/star_tracker, '
          '/telemetry/reference_rate).', read_only=True, scope='node'),
    Param('xtce_file', '', 'XTCE definition of a file of CCSDS space packets; empty: FILE.xml, '
          'else telemetry.xml beside the file (docs/contracts.md); given, the file is read '
          'as packets whatever its suffix.', read_only=True, scope='node'),
    Param('telemetry_map_file', '', 'Map from XTCE parameters to telemetry columns of a '
          'packet file; empty: FILE_map.yaml, else telemetry_map.yaml beside the file '
          '(docs/contracts.md).', read_only=True, scope='node'),
    Param('rate', 1.0, 'Time factor: 1.0 real time, 40.0 forty times faster, 0.0 as fast as '
          'the subscribers take it without loss.', low=0.0, high=1.0e6, scope='node'),
    Param('start_offset', 0.0, 'Seconds from the first sample where the replay (and every '
          'loop) starts.', low=0.0, read_only=True, unit='s', scope='node'),
    Param('loop', False, 'Start again at start_offset after the last sample (stamps jump '
          'back).', scope='node'),
    Param('min_subscribers', 0, 'Matched subscriptions on telemetry/wheels to wait for '
          'before the first sample (rate 0 waits for at least 1).', low=0, high=1000,
          scope='node'),
    Param('subscriber_timeout', 10.0, 'Seconds to wait, at any rate, for the subscribers '
          'the ROS graph knows to be matched before the first sample; 0 = do not wait '
          '(docs/nodes.md).', low=0.0, high=3600.0, unit='s', scope='node'),
    Param('burst', 1, 'Rows published per executor turn at rate 0 (keep at most the '
          'telemetry depth divided by the number of subscriber turns per row).', low=1,
          high=500, scope='node'),
    Param('exit_when_done', True, 'Shut the process down after the last sample (no loop); '
          'in-process users set false and poll `done`.', scope='node'),
    Param('frame_id', 'body', 'frame_id of the gyro, star-tracker and reference-rate '
          'messages.', read_only=True, scope='node'),
), 'Replay of a telemetry file as ROS topics and /clock; docs/nodes.md.')

SCHEMAS: dict[str, Schema] = {
    s.name: s for s in (REPLAY, LLR, FSS, VSADC, IDENTIFY, FLEET)}


# ------------------------------------------------- checked values -> algorithm keywords

def llr_kwargs(values: Mapping[str, Any]) -> dict[str, Any]:
    """Return LLRDetector / detect_batch keywords from checked LLR values."""
    return {name: values[name] for name in LLR.names(('all',))}


def vsadc_kwargs(values: Mapping[str, Any]) -> dict[str, Any]:
    """Return VsadcDetector keywords from checked VSADC values (axes as a tuple)."""
    kwargs = {name: values[name] for name in VSADC.names(('all',))
              if name != 'reference_rate' and name not in RESIDUAL_PARAMETERS}
    kwargs['axes'] = tuple(a.strip() for a in values['axes'].split(',') if a.strip())
    return kwargs


def _vsadc_detector(values: Mapping[str, Any]) -> Any:
    from rwa_monitor.core.vsadc import VsadcDetector
    return VsadcDetector(**vsadc_kwargs(values))


def fss_config(values: Mapping[str, Any]) -> Any:
    """Return the FssConfig of checked FSS values (ValueError from its own checks)."""
    from rwa_monitor.core.fss.pipeline import FssConfig
    return FssConfig(**{name: values[name] for name in FSS.names(('all',))
                        if name != 'model'})


# ------------------------------------------------------------------- generated texts

def _yaml_value(value: Any) -> str:
    if isinstance(value, bool):
        return 'true' if value else 'false'
    if isinstance(value, float):
        text = repr(value)
        if 'e' in text and '.' not in text.split('e')[0]:
            mantissa, exponent = text.split('e')
            text = f'{mantissa}.0e{exponent}'
        return text
    if isinstance(value, str):
        return f'"{value}"' if value == '' or ',' in value else value
    if isinstance(value, list):
        return '[' + ', '.join(_yaml_value(v) for v in value) + ']'
    return str(value)


def default_text(param: Param) -> str:
    """Return a parameter's default as written in the parameters file."""
    return '(required)' if param.required else _yaml_value(param.default)


def markdown_table(schema: Schema) -> str:
    """Return the markdown table of a schema's parameters (docs/parameters.md)."""
    rows = ['| name | default | allowed | unit | where | meaning |',
            '|---|---|---|---|---|---|']
    for p in schema:
        where = {'all': 'node, file', 'node': 'node', 'file': 'file'}[p.scope]
        rows.append(f'| `{p.name}` | `{default_text(p)}` | {p.allowed() or "any"} | '
                    f'{p.unit or "-"} | {where} | {p.description} |')
    return '\n'.join(rows)


def help_text(schema: Schema, scopes: Sequence[str] = ('all', 'file')) -> str:
    """Return a plain-text list of a schema's parameters for ``--help`` epilogs."""
    lines = [f'parameters of the {schema.name} block (docs/parameters.md):']
    for p in schema:
        if p.scope in scopes:
            unit = f' [{p.unit}]' if p.unit else ''
            lines.append(textwrap.fill(f'{p.name} = {default_text(p)}{unit}: {p.description}',
                                       width=88, initial_indent='  ',
                                       subsequent_indent='      '))
    return '\n'.join(lines)


def parameters_document() -> str:
    """Return docs/parameters.md: one table per schema (``rwa-monitor params --markdown``)."""
    parts = ['# Parameters', '',
             'Generated from `rwa_monitor/core/schema.py` by `rwa-monitor params --markdown`;',
             'test/test_schema.py fails when this file and the schema differ. The node of each',
             'block reads it with `--ros-args --params-file`, the file commands with `--config`',
             '(`detect`) or `--params-file` (`diagnose`); where says which of them uses a',
             f'parameter. `{AUTO}` is the one spelling of an automatic value. A name that no',
             'schema knows is refused with the nearest valid one.', '']
    for schema in SCHEMAS.values():
        parts += [f'## {schema.name}', '', schema.summary, '', markdown_table(schema), '']
    return '\n'.join(parts)


def yaml_block(schema: Schema) -> dict[str, Any]:
    """Return the node block of the shipped parameters file: every default but required."""
    return {schema.name: {'ros__parameters': schema.defaults()}}
