"""Online LLR friction-anomaly detector (llr-realtime paper, Algorithm 1 and 2, eq. (1)-(7)).

The public entry point. :class:`LLRDetector` is the streaming object (one per wheel):
``update(t, speed, friction)`` per sample, O(1) per sample via prefix sums over the
reference segment, memory bounded by a ring of the last ``2 * window + k_verif + 2``
samples; ``state()`` / ``restore()`` save and resume it (:class:`LLRState`, a typed
record). :func:`detect_batch` gives the same events from whole arrays, running the same
code. Where each part lives:

- :mod:`rwa_monitor.core.llr_detector`: the detector (configuration, state, entry points);
- :mod:`rwa_monitor.core.llr_config`: the checked parameters (core/schema.py);
- :mod:`rwa_monitor.core.llr_state`: the state records; :mod:`rwa_monitor.core.llr_restore`
  what a restore checks;
- :mod:`rwa_monitor.core.llr_kernel`: the compiled per-sample step of the paper's model;
- :mod:`rwa_monitor.core.llr_samples`: the noise fit, scaling and whitening of samples;
- :mod:`rwa_monitor.core.llr_changes`: declaration, revision, re-check, continuation;
- :mod:`rwa_monitor.core.llr_general`: the per-sample step of larger models (p > 2);
- :mod:`rwa_monitor.core.llr_common`: p_k, events, the declaration;
  :mod:`rwa_monitor.core.llr_noise`: the noise model;
- :mod:`rwa_monitor.core.llr_stats`: prefix sums, fits and quantiles;
  :mod:`rwa_monitor.core.llr_kinds`: the kind of a change;
  :mod:`rwa_monitor.core.llr_growth`: the after-segment growth statistics;
- :mod:`rwa_monitor.core.llr_batch`: whole arrays.

The algorithm as implemented, its departures from the paper and the categorisation design
are in docs/llr.md.
"""

from __future__ import annotations

from rwa_monitor.core.llr_batch import detect_batch, detect_batch_with_counters
from rwa_monitor.core.llr_common import candidate_log_p2
from rwa_monitor.core.llr_config import LLRConfig
from rwa_monitor.core.llr_detector import LLRDetector
from rwa_monitor.core.llr_noise import NoiseModel
from rwa_monitor.core.llr_state import COUNTER_NAMES, DeclaredChange, LLRState

__all__ = ['candidate_log_p2', 'COUNTER_NAMES', 'DeclaredChange', 'detect_batch',
           'detect_batch_with_counters', 'LLRConfig', 'LLRDetector', 'LLRState', 'NoiseModel']
