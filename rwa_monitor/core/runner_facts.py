"""What a runner tells about one component: counts, the coverage verdict, detector facts.

:class:`ComponentFacts` is the one per-component summary of every entry point (``detect``'s
summary entry, a node's health values, the fleet's summary): the samples offered, those
the detector rejected by reason, those a calibration left untested by reason, the verdict
of core/coverage.py on them, and the detector's own facts (``details``). A gyro's facts
hold one part per axis.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

from rwa_monitor.core.coverage import Coverage
from rwa_monitor.core.records import Scalar


@dataclass(frozen=True)
class ComponentFacts:
    """One component's facts after the samples a runner was fed.

    Parameters
    ----------
    component : str
        Wheel id, gyro axis (``gyro_x``) or ``gyro`` for the three axes together.
    family : str
        ``llr`` (a wheel) or ``vsadc`` (the gyro).
    samples : int
        Rows offered to the component.
    rejected : mapping of str to int
        The detector's rejected samples and skipped tests by reason (core/keys.py names).
    not_tested : mapping of str to int
        Samples a calibration left untested, by reason (empty without a calibration).
    verdict : Coverage or None
        Whether the component was examined (core/coverage.py); None for a whole gyro,
        whose axes (``parts``) each have one.
    details : mapping of str to scalar
        The detector's own facts (e.g. ``final_state``, ``ready``, ``warning``).
    parts : tuple of ComponentFacts
        The gyro's axes; empty for a wheel.
    """

    component: str
    family: str
    samples: int
    rejected: Mapping[str, int]
    not_tested: Mapping[str, int] = field(default_factory=dict)
    verdict: Coverage | None = None
    details: Mapping[str, Scalar] = field(default_factory=dict)
    parts: tuple['ComponentFacts', ...] = ()

    @property
    def examined(self) -> bool:
        """True if every verdict of the component (or of each of its parts) stands."""
        if self.parts:
            return all(part.examined for part in self.parts)
        return self.verdict is not None and self.verdict.examined

    def not_examined(self) -> dict[str, str]:
        """Return component -> reason for each verdict that does not stand."""
        found = {}
        for facts in self.parts or (self,):
            verdict = facts.verdict
            if verdict is not None and not verdict.examined:
                prefix = 'unknown: ' if verdict.verdict == 'unknown' else ''
                found[facts.component] = prefix + str(verdict.reason or verdict.verdict)
        return found

    def fields(self) -> dict[str, Any]:
        """Return the JSON summary entry of a wheel or an axis (detect's per-component)."""
        out: dict[str, Any] = {'samples': self.samples, 'rejected': dict(self.rejected)}
        if self.not_tested:
            out['not_tested'] = dict(self.not_tested)
        out.update(self.details)
        if self.verdict is not None:
            out.update(self.verdict.fields())
        return out
