"""The kernel's lower bound of log p_k, which decides where the exact tail is computed, holds.

The compiled per-sample test (core/llr_kernel.py ``test``) leaves a candidate to the exact
tail (eq. (7)) only if its lower bound can beat p_min; the bound must therefore be below
the exact tail (Lemma 1, studentised or not), or a new minimum, hence an event, is missed.
"""

import math

import numpy as np
import pytest

from rwa_monitor.core.llr_common import candidate_log_p2
from rwa_monitor.core.llr_skip import lower_bound


@pytest.mark.parametrize('dof', [None, 30.0, 1000.0, 1e6])
def test_kernel_lower_bound_is_below_the_exact_tail(dof):
    rng = np.random.default_rng(40)
    n = 400
    lam1 = rng.uniform(1e-3, 1.0, n)
    lam2 = lam1 * rng.choice([0.0, 1e-6, 0.3, 0.999, 1.0], n)
    tr, dm = lam1 + lam2, lam1 * lam2
    y = rng.exponential(8.0, n) * lam1
    for i in range(n):
        exact = candidate_log_p2(float(y[i]), float(tr[i]), float(dm[i]), math.inf, dof)
        low = lower_bound(float(y[i]), float(tr[i]), float(dm[i]), -1.0 if dof is None else dof)
        assert low <= exact + 1e-9 * (1.0 + abs(exact))
