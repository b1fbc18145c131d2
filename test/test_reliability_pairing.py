"""The bounded gyro/star-tracker pairing does not blind the VSADC node under load.

Under load the node's two readers drain at their own pace, so the gyro stream may run
ahead of the star tracker (or behind it). :class:`rwa_monitor.core.streams.StampPairer`
pairs by stamp with bounded buffers: as long as the gyro leads by at most ``max_lag``
samples and the star tracker by at most ``4 * max_lag``, every sample is paired, in
stamp order; beyond that a sample is released unpaired (counted, held by the detector)
and pairing resumes by itself once the streams are back within the bound.
"""

from hypothesis import given, settings
from hypothesis import strategies as st

from rwa_monitor.core.streams import StampPairer

RATE_HZ = 10.0
REF = (0.0, 0.0, 0.0)


def _run(pairer, order, n):
    """Push ``n`` gyro and ``n`` star samples in ``order`` (True: gyro); return releases."""
    out, g, s = [], 0, 0
    for gyro_next in order:
        if gyro_next and g < n:
            pairer.push_gyro(g / RATE_HZ, (float(g), 0.0, 0.0))
            g += 1
        elif s < n:
            pairer.push_star(s / RATE_HZ, (0.0, 0.0, 0.0, 1.0))
            s += 1
        out.extend(pairer.drain(lambda t, lagging: REF))
    return out


def _bounded_order(steps, max_lag, n):
    """Return a push order whose gyro lead stays in [-4 max_lag, max_lag]."""
    order, lead, g, s = [], 0, 0, 0
    for want_gyro in steps + [False] * (2 * n):
        if g == n and s == n:
            break
        gyro = (want_gyro or s == n) and g < n
        if gyro and lead >= max_lag and s < n:
            gyro = False
        if not gyro and lead <= -4 * max_lag and g < n:
            gyro = True
        order.append(gyro)
        g, s, lead = g + gyro, s + (not gyro), lead + (1 if gyro else -1)
    return order


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=600), st.integers(1, 40))
def test_every_sample_is_paired_while_the_lag_is_within_the_bound(steps, max_lag):
    n = 200
    pairer = StampPairer(tolerance=1e-3, max_lag=max_lag)
    released = _run(pairer, _bounded_order(steps, max_lag, n), n)
    assert pairer.counters['unpaired_gyro'] == 0
    assert pairer.counters['unpaired_star_tracker'] == 0
    assert [r[1][0] for r in released] == [float(k) for k in range(n)]
    assert all(r[2] is not None for r in released)


def test_a_lag_beyond_the_bound_is_counted_and_pairing_resumes():
    max_lag, n = 40, 400
    pairer = StampPairer(tolerance=1e-3, max_lag=max_lag)
    # The star tracker stalls for 100 gyro samples (a reader far behind), then both
    # streams go on in step.
    order = [True] * 100 + [False] * 100 + [True, False] * (n - 100)
    released = _run(pairer, order, n)
    unpaired = [r for r in released if r[2] is None]
    assert pairer.counters['unpaired_gyro'] == len(unpaired) == 100 - max_lag
    assert len(released) == n
    assert all(r[2] is not None for r in released[100:])   # resumed, not blinded
    assert [r[0] for r in released] == sorted(r[0] for r in released)
