"""The exact tail of eq. (7), settled compiled (core/llr_kernel.py ``settle``).

Where the skip bounds leave a candidate, the kernel computes its tail
(core/llr_skip.py ``exact_log_p2``) and records a new minimum itself (Algorithm 1 lines
13-15), in the streaming step as in the loop over arrays. Checked sample by sample
against ``llr_common.candidate_log_p2`` and the rule as written: a tail below the running
p_min becomes p_min at that candidate, with its skip threshold; any other leaves them as
they were.
"""

import math

import numpy as np
import pytest
from test_llr import friction_signal

from rwa_monitor.core import llr_layout as layout
from rwa_monitor.core.gchi2 import skip_threshold
from rwa_monitor.core.llr_common import candidate_log_p2
from rwa_monitor.core.llr_detector import LLRDetector


def _minimum(live):
    return (float(live.floats[layout.F_LOGPMIN]), int(live.ints[layout.I_KMIN]),
            float(live.floats[layout.F_YSTAR]))


@pytest.mark.parametrize('noise_std', [None, 1.0])
def test_the_kernel_records_the_minimum_of_the_exact_tail(noise_std):
    t, w, f = friction_signal(4000, 71, ((2000, 0.6, 0.0),), profile='crossing')
    det = LLRDetector('rw1', window=200, noise_std=noise_std)
    live = det._live
    exact = new_minima = declared = 0
    for ti, wi, fi in zip(t.tolist(), w.tolist(), f.tolist()):
        before = _minimum(live)
        last_k = int(live.ints[layout.I_K])
        events = det.update(ti, wi, fi)
        k = int(live.ints[layout.I_K])
        if events:
            declared += 1           # the declaration restarted the reference
            continue
        if k == last_k:
            assert _minimum(live) == before
            continue
        exact += 1
        dof = int(live.ints[layout.I_DOF])
        assert (dof < 0) == (noise_std is not None)
        logp = candidate_log_p2(float(live.floats[layout.F_Y]), float(live.floats[layout.F_TR]),
                                float(live.floats[layout.F_DM]), before[0],
                                None if dof < 0 else float(dof))
        if logp is not None and logp < before[0]:
            new_minima += 1
            assert _minimum(live) == (logp, k, skip_threshold(logp))
        else:
            assert _minimum(live) == before
    # The stream exercises both branches and the change is found.
    assert exact > new_minima > 10 and declared >= 1


def test_candidate_log_p2_is_none_where_the_bound_rules_the_tail_out():
    from rwa_monitor.core.gchi2 import log_sf2
    from rwa_monitor.core.llr_skip import EXACT_REL, lower_bound
    y, tr, dm = 30.0, 1.2, 0.2
    bound = lower_bound(y, tr, dm, -1.0)
    half = 0.5 * tr
    lam1 = half + math.sqrt(half * half - dm)
    assert candidate_log_p2(y, tr, dm, math.inf) == log_sf2(y, lam1, dm / lam1)
    above = bound - 10.0 * EXACT_REL * (1.0 - bound)
    assert candidate_log_p2(y, tr, dm, above) is None
    assert candidate_log_p2(y, tr, dm, np.nextafter(bound, 0.0)) is not None
