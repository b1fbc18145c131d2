"""Streaming FSS window diagnosis of one wheel: the detector protocol over the pipeline.

:class:`FssDiagnoser` keeps the last ``window_length`` samples of one wheel
(:class:`~rwa_monitor.core.fss.pipeline.SlidingWindow`) and, every ``window_period``
samples once the window is full, runs :func:`~rwa_monitor.core.fss.pipeline.diagnose` on it
(physics-informed FSS paper, section IV, on a sliding window as the node does). Arrays in,
no file I/O: the classifier is given (read one with
``rwa_monitor.telemetry.fss_model.load_model``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

from rwa_monitor.core import keys
from rwa_monitor.core.fss.classify import WindowClassifier
from rwa_monitor.core.fss.pipeline import diagnose, FssConfig, SlidingWindow


class WindowDiagnosis(NamedTuple):
    """One diagnosis: the window's first and last time (s) and the per-wheel JSON object.

    Parameters
    ----------
    start_s, end_s : float
        Time (s) of the window's first and last sample.
    result : dict
        The window diagnosis of :func:`~rwa_monitor.core.fss.pipeline.diagnose`
        (``anomalies``, ``estimates``, ``changepoints``, ``timings_s``).

    Examples
    --------
    >>> found = WindowDiagnosis(0.0, 29.5, {'anomalies': {'dry': False}})
    >>> found.end_s - found.start_s, found.result['anomalies']['dry']
    (29.5, False)
    """

    start_s: float
    end_s: float
    result: dict


class FssDiagnoser:
    """Diagnose one wheel's sliding window: ``update(t, speed, friction)`` per sample.

    A window diagnoser (:class:`~rwa_monitor.core.protocol.WindowDiagnoser`): ``update``
    returns the :class:`WindowDiagnosis` when one was due at this sample, else None. SI
    telemetry in, rad/s and N m.

    Parameters
    ----------
    classifier : WindowClassifier
        The trained classifier (``rwa_monitor.load_fss_model()``: the shipped one).
    window_length : int
        Samples per diagnosed window.
    window_period : int
        Samples between two diagnoses, once the window is full.
    wglr_window, w_bias, viscous_prior, p_false, dk_error, beam, torque_scale_nm, \
speed_scale_rad_s
        The stages' parameters (core/schema.py ``FSS``, docs/parameters.md).
    max_abs_speed, max_abs_friction : float
        Plausibility limits: samples at or beyond are not tested (rad/s, N m).

    Examples
    --------
    >>> import numpy as np
    >>> from rwa_monitor import load_fss_model
    >>> diagnoser = FssDiagnoser(load_fss_model(), window_length=300, window_period=100)
    >>> rng = np.random.default_rng(0)
    >>> speed = 200.0 + np.arange(400.0)
    >>> friction = -2e-4 - 5e-7 * speed + rng.normal(0.0, 5e-5, 400)
    >>> found = [d for k in range(400)
    ...          if (d := diagnoser.update(0.1 * k, speed[k], friction[k]))]
    >>> len(found), diagnoser.counters['diagnoses'], diagnoser.last_event == found[-1]
    (2, 2, True)
    >>> sorted(found[-1].result['anomalies'])
    ['dry', 'fss1', 'fss2', 'viscous']
    """

    def __init__(self, classifier: WindowClassifier, *, window_length: int = 80_000,
                 window_period: int = 20_000, wglr_window: int = 20, w_bias: float = 1.0e-4,
                 viscous_prior: float = 1.0, p_false: float = 1.0e-9, dk_error: int = 10,
                 beam: int = 256, torque_scale_nm: float = 2.0e-4,
                 speed_scale_rad_s: float = 400.0, max_abs_speed: float = 1.0e5,
                 max_abs_friction: float = 1.0e3) -> None:
        self.classifier = classifier
        self.config = FssConfig(wglr_window=wglr_window, w_bias=w_bias,
                                viscous_prior=viscous_prior, p_false=p_false,
                                dk_error=dk_error, beam=beam, torque_scale_nm=torque_scale_nm,
                                speed_scale_rad_s=speed_scale_rad_s,
                                max_abs_speed=max_abs_speed, max_abs_friction=max_abs_friction)
        self.window = SlidingWindow(length=window_length, period=window_period)
        self._params = {'window_length': window_length, 'window_period': window_period,
                        **{k: getattr(self.config, k) for k in (
                            'wglr_window', 'w_bias', 'viscous_prior', 'p_false', 'dk_error',
                            'beam', 'torque_scale_nm', 'speed_scale_rad_s', 'max_abs_speed',
                            'max_abs_friction')}}
        self.reset()

    @property
    def params(self) -> dict[str, Any]:
        """The keyword parameters (checked)."""
        return dict(self._params)

    @property
    def counters(self) -> dict[str, int]:
        """Return the samples dropped or kept by reason, time gaps and diagnoses run.

        ``non_increasing_time``: stamps not after the last (dropped); ``non_finite``: a
        non-finite stamp (dropped) or value (kept: the stages skip it); ``gaps``: steps
        longer than three times the first one.
        """
        w = self.window
        return {keys.NON_INCREASING_TIME: w.non_increasing_time, keys.NON_FINITE: w.non_finite,
                'gaps': w.gaps, 'diagnoses': self._diagnoses}

    @property
    def last_event(self) -> WindowDiagnosis | None:
        """The latest diagnosis, or None."""
        return self._last

    def reset(self) -> None:
        """Forget every sample, counter and diagnosis."""
        self.window.reset()
        self._diagnoses = 0
        self._last: WindowDiagnosis | None = None

    def update(self, t: float, speed: float, friction: float) -> WindowDiagnosis | None:
        """Add one sample; return the window's diagnosis when one is due, else None."""
        if not self.window.update(t, speed, friction):
            return None
        time_s, speed_w, friction_w = self.window.snapshot()
        result = diagnose(speed_w, friction_w, time_s, self.classifier, self.config)
        self._diagnoses += 1
        self._last = WindowDiagnosis(float(time_s[0]), float(time_s[-1]), result)
        return self._last
