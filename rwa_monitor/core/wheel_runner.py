"""The runner of one reaction wheel: what detect, the nodes, the demo and the fleet call.

A wheel is watched by the LLR detector (llr-realtime paper, Algorithm 1) in one of three
set-ups, chosen once when the runner is made: the paper's model (1) on the friction
itself (plain); model (1) on the residual against a commissioning calibration's nominal
friction (calibrated, docs/llr.md "Calibrated"); or a refined friction model written by
``rwa-monitor identify`` (refined; its regressors, with the auxiliary channels it reads).
The rules that every entry point used to repeat live here once:

- feeding: a calibrated wheel's samples inside the low-speed band or outside the
  calibrated speeds (docs/calibration.md "Where the nominal is tested") are given as
  NaN and counted as not tested, by reason
  (core/nominal.py); whole arrays (:meth:`WheelRunner.feed`, files and passes) and single
  samples (:meth:`WheelRunner.update`, a node) give the same events;
- facts: the detector's rejected samples (those fed as NaN because untested are not
  counted twice), the samples not tested, and the coverage verdict of core/coverage.py
  (:meth:`WheelRunner.facts`);
- state: :meth:`WheelRunner.state` returns a typed record (:class:`WheelRunnerState`,
  the detector's own record inside, core/records.py) and :meth:`WheelRunner.restore`
  resumes from one exactly: events of a record cut anywhere and resumed equal those of
  the whole record.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Mapping

import numpy as np

from rwa_monitor.core.coverage import judge, llr_samples_needed
from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.friction import RegressorSet
from rwa_monitor.core.jit import kernel_array
from rwa_monitor.core.llr import LLRDetector
from rwa_monitor.core.llr_state import LLRState
from rwa_monitor.core.nominal import NominalWheel, tested_text
from rwa_monitor.core.records import RecordError
from rwa_monitor.core.runner_facts import ComponentFacts
from rwa_monitor.core.schema import llr_kwargs

NOT_TESTED = ('low_speed_band', 'outside_calibrated_range')
FAMILY = 'llr'


@dataclass(frozen=True)
class WheelRunnerState:
    """A wheel runner's state: the detector's record and the samples not tested so far."""

    VERSION: ClassVar[int] = 1
    component: str
    setup: str
    detector: LLRState
    not_tested: dict[str, int]


class WheelRunner:
    """One wheel's LLR detector with its set-up: plain, calibrated or refined.

    Parameters
    ----------
    component : str
        Wheel id, copied into the events.
    values : mapping
        Checked parameters of the ``llr_detector`` block (core/schema.py LLR); node-only
        ones are ignored.
    nominal : NominalWheel or None
        The wheel's calibration in force (calibrated set-up).
    regressors : RegressorSet or None
        A refined friction model (refined set-up); not with ``nominal``.

    Examples
    --------
    >>> import numpy as np
    >>> from rwa_monitor.core.schema import LLR
    >>> t = np.arange(3000) * 0.1
    >>> w = 200.0 + 150.0 * np.sin(t / 20.0)
    >>> f = -(2e-4 + 4e-4 * (t >= 150.0)) - 5e-7 * w
    >>> f = f + np.random.default_rng(0).normal(0.0, 5e-5, t.size)
    >>> runner = WheelRunner('rw1', LLR.defaults())
    >>> [(e.kind, round(e.time, 1)) for e in runner.feed(t, w, f) + runner.finish()]
    [('dry', 150.0), ('dry', 150.0)]
    >>> runner.facts().verdict.verdict
    'examined'
    """

    def __init__(self, component: str, values: Mapping[str, Any], *,
                 nominal: NominalWheel | None = None,
                 regressors: RegressorSet | None = None) -> None:
        if nominal is not None and regressors is not None:
            raise ValueError(f'{component}: a calibration and a refined friction model '
                             'cannot both apply to one wheel')
        kwargs = llr_kwargs(values)
        if regressors is not None:
            kwargs['regressors'] = regressors
        self._detector = LLRDetector(component, **kwargs)
        self._nominal = nominal
        self._needed = llr_samples_needed(values)
        self._not_tested = dict.fromkeys(NOT_TESTED, 0) if nominal is not None else {}
        self.last_input: np.ndarray | None = None
        self.setup = ('calibrated' if nominal is not None else
                      'refined' if regressors is not None else 'plain')

    @property
    def component(self) -> str:
        """Wheel id."""
        return self._detector.component

    @property
    def detector(self) -> LLRDetector:
        """Return the wheel's detector, to read its estimates; feed it through the runner."""
        return self._detector

    @property
    def nominal(self) -> NominalWheel | None:
        """The calibration in force, or None."""
        return self._nominal

    def residual(self, time: np.ndarray, speed: np.ndarray, friction: np.ndarray
                 ) -> np.ndarray:
        """Return the detector's input: the friction, or its residual, NaN where untested."""
        if self._nominal is None:
            return np.asarray(friction, dtype=float)
        return self._nominal.residual(time, speed, friction)[0]

    def feed(self, time: np.ndarray, speed: np.ndarray, friction: np.ndarray,
             aux: Mapping[str, np.ndarray] | None = None) -> list[AnomalyEvent]:
        """Give whole arrays (rows after the last one fed); return the events.

        ``aux``: the auxiliary channels a refined model reads (arrays of the rows).
        :attr:`last_input` is then what the detector was given (the residual against the
        nominal with a calibration, NaN where not tested).
        """
        t, w, f = (kernel_array(a) for a in (time, speed, friction))
        if self._nominal is not None:
            f, skipped = self._nominal.residual(t, w, f)
            for reason, count in skipped.items():
                self._not_tested[reason] = self._not_tested.get(reason, 0) + count
        self.last_input = f
        if self.setup == 'refined':
            return self._detector.process_arrays(t, w, f, aux)
        return self._detector.process_arrays(t, w, f)

    def update(self, t: float, speed: float, friction: float,
               aux: Mapping[str, float] | None = None) -> list[AnomalyEvent]:
        """Give one sample (a node's call); return the events (the same as :meth:`feed`).

        A calibrated sample is one compiled call (``LLRDetector.update_nominal``); the
        nominal's table counts the samples not tested.
        """
        if self._nominal is not None:
            return self._detector.update_nominal(self._nominal.table, t, speed, friction)
        return self._detector.update(t, speed, friction, aux)

    def finish(self) -> list[AnomalyEvent]:
        """End of record: the last declared change's final categorisation (docs/llr.md)."""
        return self._detector.finish()

    def not_tested(self) -> dict[str, int]:
        """Return the samples not tested so far by reason (empty without a calibration)."""
        counts = dict(self._not_tested)
        if self._nominal is not None:
            for reason, count in self._nominal.not_tested.items():
                counts[reason] = counts.get(reason, 0) + count
        return counts

    def facts(self) -> ComponentFacts:
        """Return the counts and the verdict of the samples fed so far (core/coverage.py).

        Usable samples: those offered less the detector's rejected ones (non-finite, out
        of range, time not increasing, auxiliary channel missing; a test skipped as
        ill-conditioned still used its samples) and those the calibration left untested,
        which were given to the detector as NaN and are not counted again as non-finite.
        """
        rejected = self._detector.counters
        untested = self.not_tested()
        if untested:
            rejected['non_finite'] = rejected.get('non_finite', 0) - sum(untested.values())
        samples = self._detector.n_samples
        usable = samples - sum(v for k, v in rejected.items() if k != 'ill_conditioned') \
            - sum(untested.values())
        details: dict[str, Any] = {}
        outside = untested.get('outside_calibrated_range', 0)
        if outside and self._nominal is not None:
            details['warning'] = (f'{outside} samples at speeds where the calibration did '
                                  f'not determine its nominal '
                                  f'({tested_text(self._nominal.tested)}): not tested')
        return ComponentFacts(self.component, FAMILY, samples, rejected, untested,
                              judge(samples, usable, self._needed, 'the LLR test'), details)

    def state(self) -> WheelRunnerState:
        """Return the runner's state as a typed record (a copy: feeding on leaves it be)."""
        return WheelRunnerState(self.component, self.setup, self._detector.state(),
                                self.not_tested())

    def restore(self, state: WheelRunnerState) -> None:
        """Resume from ``state`` (made by a runner of the same wheel, set-up and parameters).

        Raise RecordError naming what differs; the runner is then unchanged.
        """
        if state.component != self.component or state.setup != self.setup:
            raise RecordError(f'state of {state.component} ({state.setup}) given to the '
                              f'runner of {self.component} ({self.setup})')
        if set(state.not_tested) != set(self._not_tested) or \
                any(type(v) is not int or v < 0 for v in state.not_tested.values()):
            raise RecordError(f'{self.component}: not_tested {state.not_tested} does not '
                              f'match the set-up {self.setup}')
        self._detector.restore(state.detector)
        if self._nominal is not None:
            self._nominal = NominalWheel(self._nominal.block)   # its table counts from 0
        self._not_tested = dict(state.not_tested)
