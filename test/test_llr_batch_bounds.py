"""The cheap bounds of log p_k that steer the batch scan hold (core/llr_batch.py).

The scan evaluates p_k exactly only where its lower bound can beat the running minimum of
the upper bounds; both must therefore bound the exact tail (Lemma 1, studentised or not)
for the batch events to equal the streaming ones.
"""

import math

import numpy as np
import pytest

from rwa_monitor.core.llr_batch import _lower_bounds, _rough_bounds
from rwa_monitor.core.llr_common import candidate_log_p2


@pytest.mark.parametrize('dof', [None, 30.0, 1000.0, 1e6])
def test_rough_and_candidate_bounds_bracket_the_exact_tail(dof):
    rng = np.random.default_rng(40)
    n = 400
    lam1 = rng.uniform(1e-3, 1.0, n)
    lam2 = lam1 * rng.choice([0.0, 1e-6, 0.3, 0.999, 1.0], n)
    tr, dm = lam1 + lam2, lam1 * lam2
    y = rng.exponential(8.0, n) * lam1
    dofs = None if dof is None else np.full(n, dof)
    upper, lower = _rough_bounds(y, tr, dm, dofs)
    low = _lower_bounds(y, tr, dm, dofs)
    for i in range(n):
        exact = candidate_log_p2(float(y[i]), float(tr[i]), float(dm[i]), math.inf, dof)
        tol = 1e-9 * (1.0 + abs(exact))
        assert lower[i] <= low[i] + tol
        assert low[i] <= exact + tol
        assert exact <= upper[i] + tol
