"""Whether a component was examined: the one rule of every command, node and bench.

A detector or diagnoser reports a verdict (healthy, nominal, no change found) only for a
component it examined. :func:`judge` decides from three counts:

- ``not_examined``: fewer usable samples than the algorithm needs for its first verdict
  (``needed``: the LLR test's reference plus window, ``2 window + 1``; the gyro
  diagnosis' nominal class; the window diagnoser's changepoint windows; each pipeline
  says which);
- ``unknown``: enough for a verdict, but more than :data:`MOSTLY_UNTESTED_SHARE` of the
  samples were rejected or left untested, so what was found holds for a minority of the
  record only;
- ``examined`` otherwise.

Both non-examined verdicts make a command exit 3 (docs/usage.md) and carry their counts.
"""

from __future__ import annotations

from typing import Any, Mapping, NamedTuple

from rwa_monitor.core.params import AUTO

# Largest share of a component's samples that may be rejected or left untested (non-finite,
# out of range, inside a calibration's low-speed band...) for its verdict to stand: above
# it a wheel, gyro axis or diagnosed window is ``unknown``, never healthy or nominal
# (docs/usage.md, "Exit codes and verdicts"). ``calibrate`` refuses a low-speed band that
# would leave more than this share of the commissioning data untested. Defined here, not
# in core/schema.py, because the window diagnoser (core/fss) uses it and core/schema.py
# imports core/fss; it is a fixed rule, not a parameter.
MOSTLY_UNTESTED_SHARE = 0.5

EXAMINED = 'examined'
UNKNOWN = 'unknown'
NOT_EXAMINED = 'not_examined'

__all__ = ['Coverage', 'EXAMINED', 'judge', 'llr_samples_needed', 'MOSTLY_UNTESTED_SHARE',
           'NOT_EXAMINED', 'UNKNOWN']


class Coverage(NamedTuple):
    """The verdict of one component and its counts (samples offered, usable, needed)."""

    verdict: str
    samples: int
    usable: int
    needed: int
    reason: str | None = None

    @property
    def examined(self) -> bool:
        """True if the component's verdict stands (neither unknown nor not examined)."""
        return self.verdict == EXAMINED

    def fields(self) -> dict[str, Any]:
        """Return the JSON / diagnostics key-values of this verdict (counts, reason)."""
        out: dict[str, Any] = {'verdict': self.verdict, 'samples': self.samples,
                               'usable_samples': self.usable, 'needed_samples': self.needed}
        if self.reason:
            out['verdict_reason'] = self.reason
        return out


def judge(samples: int, usable: int, needed: int, what: str = 'the detector',
          share: float = MOSTLY_UNTESTED_SHARE) -> Coverage:
    """Return the verdict of a component given ``usable`` of ``samples`` (``needed``).

    ``what`` names the algorithm in the reason (``'the LLR test'``).
    """
    samples, usable, needed = int(samples), int(usable), int(needed)
    if usable < max(needed, 1):
        return Coverage(NOT_EXAMINED, samples, usable, needed,
                        f'{usable} usable samples of {samples}; {what} needs at least '
                        f'{needed}')
    untested = samples - usable
    if untested > share * samples:
        return Coverage(UNKNOWN, samples, usable, needed,
                        f'{untested} of {samples} samples rejected or not tested (more '
                        f'than {share:.0%}): the verdict would hold for a minority of them')
    return Coverage(EXAMINED, samples, usable, needed)


def llr_samples_needed(values: Mapping[str, Any]) -> int:
    """Return the accepted samples a wheel needs before the LLR's first test.

    ``values``: the LLR parameters (core/schema.py LLR). The first test holds a reference
    of ``window + 1`` samples and a window of ``window`` (docs/llr.md, "Warm-up"):
    ``2 window + 1``; more when the noise model is fitted on more (``noise_fit_samples``).
    """
    window = int(values['window'])
    fit = values.get('noise_fit_samples', AUTO)
    return max(2 * window + 1, 0 if fit in (AUTO, None) else int(fit))
