"""The protocols of the streaming detectors: one per family, each with a typed ``update``.

Every detector takes one sample per ``update`` call and returns the findings of that
sample. What all share (:class:`StreamingDetector`): ``reset()`` forgets every sample,
counter and finding; ``counters`` counts the input dropped or held, by reason, with the
names of :mod:`rwa_monitor.core.keys` (``non_finite``, ``non_increasing_time``,
``out_of_range``, ``ill_conditioned``, or a detector's own reason); ``params`` returns the
checked keyword parameters (their schema: core/schema.py); ``last_event`` (read-only) is
the latest finding. The families add ``update``:

- :class:`WheelDetector` (``LLRDetector``): ``update(t, speed, friction, aux=None)``;
- :class:`GyroDetector` (``VsadcDetector``, ``GyroDiagnosis``):
  ``update(t, gyro, q, ref=None, index=None)``;
- :class:`WindowDiagnoser` (``FssDiagnoser``): ``update(t, speed, friction)``, a
  :class:`~rwa_monitor.core.fss.diagnoser.WindowDiagnosis` when a window is due.

Nodes, pipelines and benchmarks rely on these names only (docs/architecture.md,
"Detector protocols"); test/test_protocol.py drives every exported detector through its
family's protocol.
"""

from __future__ import annotations

from typing import (Any, Mapping, Protocol, runtime_checkable, Sequence, TYPE_CHECKING,
                    TypeVar)

from rwa_monitor.core.events import AnomalyEvent

if TYPE_CHECKING:
    from rwa_monitor.core.fss.diagnoser import WindowDiagnosis
    from rwa_monitor.core.runner_facts import ComponentFacts

S = TypeVar('S')

__all__ = ['ComponentRunner', 'GyroDetector', 'StreamingDetector', 'WheelDetector',
           'WindowDiagnoser']


@runtime_checkable
class StreamingDetector(Protocol):
    """What every streaming detector has: reset, counters, params, last_event.

    Examples
    --------
    >>> from rwa_monitor import VsadcDetector
    >>> detector = VsadcDetector()
    >>> isinstance(detector, StreamingDetector)
    True
    >>> detector.last_event is None, detector.counters['rows'], detector.params['window']
    (True, 0, 200)
    """

    def reset(self) -> None:
        """Forget every sample, counter and finding."""

    @property
    def counters(self) -> dict[str, int]:
        """Return the input dropped or held, by reason (names of core/keys.py)."""

    @property
    def params(self) -> dict[str, Any]:
        """Return the checked keyword parameters."""

    @property
    def last_event(self) -> Any:
        """Return the latest finding, or None."""


@runtime_checkable
class WheelDetector(StreamingDetector, Protocol):
    """A detector of one reaction wheel's friction, one telemetry sample per call.

    Examples
    --------
    >>> from rwa_monitor import LLRDetector
    >>> detector = LLRDetector('rw1', window=50)
    >>> isinstance(detector, WheelDetector)
    True
    >>> detector.update(0.0, 100.0, -2.5e-4)
    []
    """

    def update(self, t: float, speed: float, friction: float,
               aux: Mapping[str, float] | None = None) -> list[AnomalyEvent]:
        """Take one sample; return the events it declares (usually none).

        Parameters
        ----------
        t : float
            Stamp (s), increasing; a stamp not after the last accepted one is dropped and
            counted (``non_increasing_time``).
        speed : float
            Wheel speed (rad/s).
        friction : float
            Friction torque (N m).
        aux : mapping of str to float, optional
            Auxiliary channels a friction model reads (e.g. temperature).

        Returns
        -------
        list of AnomalyEvent
            The declarations and revisions of this sample.
        """

    @property
    def last_event(self) -> AnomalyEvent | None:
        """Return the latest event returned by ``update``, or None."""


@runtime_checkable
class GyroDetector(StreamingDetector, Protocol):
    """A detector of gyro drift and bias per axis, one gyro / star-tracker row per call.

    Examples
    --------
    >>> from rwa_monitor import GyroDiagnosis, VsadcDetector
    >>> detectors = (GyroDiagnosis(), VsadcDetector())
    >>> all(isinstance(d, GyroDetector) for d in detectors)
    True
    >>> [d.update(0.0, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]) for d in detectors]
    [[], []]
    """

    def update(self, t: float, gyro: Sequence[float], q: Sequence[float] | None,
               ref: Sequence[float] | None = None,
               index: int | None = None) -> list[AnomalyEvent]:
        """Take one row; return the events of every axis whose label changed.

        Rows are accepted by the one row filter of :mod:`rwa_monitor.core.gyro_rows`.

        Parameters
        ----------
        t : float
            Stamp (s), increasing.
        gyro : sequence of 3 floats
            Measured body rate (rad/s), axes x, y, z.
        q : sequence of 4 floats or None
            Star-tracker attitude quaternion (x, y, z, w, scalar last); None when the row
            has none (the axes hold their labels).
        ref : sequence of 3 floats or None
            Guidance reference body rate (rad/s); None = zero (inertial pointing). A
            detector whose feature cancels the true rate ignores it.
        index : int or None
            Row number reported in events; default: the rows seen so far.

        Returns
        -------
        list of AnomalyEvent
            One event per axis whose label changed at this row (usually empty).
        """

    @property
    def last_event(self) -> AnomalyEvent | None:
        """Return the latest event returned by ``update``, or None."""


@runtime_checkable
class WindowDiagnoser(StreamingDetector, Protocol):
    """A diagnoser of one wheel's sliding window, one telemetry sample per call.

    Examples
    --------
    >>> from rwa_monitor import FssDiagnoser, load_fss_model
    >>> diagnoser = FssDiagnoser(load_fss_model(), window_length=300)
    >>> isinstance(diagnoser, WindowDiagnoser), diagnoser.update(0.0, 100.0, -2.5e-4)
    (True, None)
    """

    def update(self, t: float, speed: float, friction: float) -> WindowDiagnosis | None:
        """Add one sample; return the window's diagnosis when one is due, else None.

        Parameters
        ----------
        t : float
            Stamp (s), increasing.
        speed : float
            Wheel speed (rad/s).
        friction : float
            Friction torque (N m).

        Returns
        -------
        WindowDiagnosis or None
            The diagnosis of the window ending at this sample, when one was due.
        """

    @property
    def last_event(self) -> WindowDiagnosis | None:
        """Return the latest diagnosis, or None."""


@runtime_checkable
class ComponentRunner(Protocol[S]):
    """What every runner has beside its family's ``feed`` and ``update`` (its state: ``S``).

    The runners (core/wheel_runner.py, core/gyro_runner.py) are what detect, the nodes
    and the fleet call (docs/architecture.md "Runners"); a detector family's runner owns
    its state as the typed record ``S``.
    """

    def finish(self) -> list[AnomalyEvent]:
        """End of record: the events of what is still open (usually none)."""

    def facts(self) -> ComponentFacts:
        """Return the counts, the coverage verdict and the detector's facts so far."""

    def state(self) -> S:
        """Return the runner's state as its family's typed record (a copy)."""

    def restore(self, state: S) -> None:
        """Resume from ``state``; RecordError (nothing changed) if it does not fit."""
