"""Kinds of growing (ramp) friction changes (docs/llr.md "Kinds on ramps").

The step categorisation fits a step in the dry and viscous directions; over a window in
which the level still rises and |w| trends, the rise is shared with the other direction.
The ramp models name the kind; these tests check them at the level of one categorisation
(bounds from the non-central chi-square of the noise-free sums) and through the detector.
"""

import math
import pathlib

import numpy as np
import pytest
from scipy import stats

from rwa_monitor.core import keys, llr_growth, llr_kinds, llr_stats
from rwa_monitor.core.llr import detect_batch, LLRDetector
from rwa_monitor.core.llr_changes import DeclaredChange, growth_kind
from rwa_monitor.core.llr_config import LLRConfig

Z_STAR = llr_stats.z_threshold(1e-3)
N_BEFORE, N_AFTER = 4000, 2000
DT = 0.25   # s per sample (4 Hz, as the bus)


def bus_like_speed(n: int) -> np.ndarray:
    """Slow swings of a few hundred seconds that cross zero, as the bus wheels do."""
    return 12.0 * np.sin(2.0 * np.pi * np.arange(n) / 5000.0) + 5.0


def _terms(w: np.ndarray, f: np.ndarray) -> np.ndarray:
    h1, h2 = -np.sign(w), -w
    return np.column_stack([h1 * h1, h1 * h2, h2 * h2, h1 * f, h2 * f, f * f])


CASES = {   # (dry, viscous) change: ramps give the slope per second, steps the size
    'dry ramp': ('ramp', 3.0e-3, 0.0),
    'viscous ramp': ('ramp', 0.0, 3.0e-4),
    'both step': ('step', 1.0, 0.05),
}


def _change(name: str) -> np.ndarray:
    """Return the friction change (dry level, viscous level) per sample of a case."""
    shape, dry, visc = CASES[name]
    k = np.arange(N_BEFORE + N_AFTER, dtype=float)
    grow = (np.clip(k - N_BEFORE, 0.0, None) * DT if shape == 'ramp'
            else (k >= N_BEFORE).astype(float))
    return np.column_stack([dry * grow, visc * grow])


def _sums(name: str, noise: np.ndarray | None, speed=bus_like_speed):
    """Return (before, after, ramp block) sums of a case (change at N_BEFORE, tau exact)."""
    w = speed(N_BEFORE + N_AFTER)
    level = _change(name)
    f = -level[:, 0] * np.sign(w) - level[:, 1] * w
    if noise is not None:
        f = f + noise
    terms = _terms(w, f)
    u = (np.arange(N_AFTER) * DT)
    return (terms[:N_BEFORE].sum(axis=0), terms[N_BEFORE:].sum(axis=0),
            llr_growth.ramp_sums(terms[N_BEFORE:], u))


def _noncentrality(name: str) -> tuple[float, float]:
    """Return the non-centralities of the two growth tests (unit noise).

    Entry ``h``: ``RSS`` of the after fit with only kind ``h``'s growth minus that with
    both, on noise-free sums: exactly the non-centrality of the 1-dof chi-square that the
    statistic follows with unit white noise.
    """
    before, after, ramp = _sums(name, None)
    row = llr_growth.ramp_shapes(ramp, 2)[-1]
    return llr_growth.ramp_statistics(llr_growth.ramp_fits(before, after, row, 2), 1.0)


def _categorise(name: str, seed: int, speed=bus_like_speed) -> llr_kinds.Category:
    noise = np.random.default_rng(seed).standard_normal(N_BEFORE + N_AFTER)
    before, after, ramp = _sums(name, noise, speed)
    return llr_kinds.categorise(before, N_BEFORE, after, 2, 1.0, Z_STAR, ramp)


def test_ramp_limits_are_the_chi_square_quantiles():
    reject, absent = llr_growth.ramp_limits(1, Z_STAR)
    assert reject == pytest.approx(Z_STAR ** 2, rel=1e-9)
    assert absent == pytest.approx(llr_kinds.Z_ABSENT ** 2, rel=1e-9)
    # Two degrees of freedom: P(chi2_2 > x) = exp(-x / 2).
    assert llr_growth.ramp_limits(2, Z_STAR)[0] == pytest.approx(-2.0 * math.log(1e-3))
    assert llr_growth.ramp_limits(3, Z_STAR)[0] == pytest.approx(stats.chi2.isf(1e-3, 3))


def test_full_ramp_model_is_the_separate_fit_of_the_after_segment():
    # full = before fitted alone + after fitted on (h, u h_dry, u h_viscous); the
    # single-kind growth models are nested in it.
    noise = np.random.default_rng(3).standard_normal(N_BEFORE + N_AFTER)
    before, after, ramp = _sums('dry ramp', noise)
    w = bus_like_speed(N_BEFORE + N_AFTER)
    level = _change('dry ramp')
    f = -level[:, 0] * np.sign(w) - level[:, 1] * w + noise
    h = np.column_stack([-np.sign(w), -w])
    u = np.arange(N_AFTER) * DT
    ha, fa = h[N_BEFORE:], f[N_BEFORE:]
    z = np.column_stack([ha, u * ha[:, 0], u * ha[:, 1]])
    hb, fb = h[:N_BEFORE], f[:N_BEFORE]
    expected = (float(np.linalg.lstsq(hb, fb, rcond=None)[0] @ (hb.T @ fb))
                + float(np.linalg.lstsq(z, fa, rcond=None)[0] @ (z.T @ fa)))
    explained = llr_growth.ramp_fits(before, after, llr_growth.ramp_shapes(ramp, 2)[-1], 2)
    assert explained[0] == pytest.approx(expected, rel=1e-9)
    assert explained[0] >= max(explained[1], explained[2])


@pytest.mark.parametrize('name, kind', [('dry ramp', 'dry'), ('viscous ramp', 'viscous')])
def test_a_ramp_is_named_its_kind(name, kind):
    """40 seeded ramps, change time exact, unit noise known (the test's exact case).

    Without the growth tests the step categorisation of the noise-free data confirms
    ``both`` (the rise is shared with the other direction). The kind is named when the
    other kind's growth is not significant at 5 % (probability 0.95: it is absent, central
    chi-square with 1 dof) and its own is at 1e-3 (non-central chi-square, non-centrality
    from the noise-free sums), if the guard holds (noise-free margin checked). A wrong
    single kind needs a false significance of the other kind's growth at 1e-3.
    """
    before, after, ramp = _sums(name, None)
    step = llr_kinds.categorise(before, N_BEFORE, after, 2, 1.0, Z_STAR)
    assert (step.kind, step.confirmed) == ('both', True)
    h = llr_stats.KINDS.index(kind)
    lam = _noncentrality(name)
    reject, absent = llr_growth.ramp_limits(1, Z_STAR)
    assert lam[h] == pytest.approx(0.0, abs=1e-6)
    p_named = (stats.chi2.cdf(absent, 1) * stats.ncx2.sf(reject, 1, lam[1 - h])
               * (1.0 - 1e-3))
    assert p_named > 0.85
    # Guard (the step rule's): a step of the other kind of this torque would be found with
    # 90 % power; noise-free margin >= 5 sd of the single-kind step estimate (whose
    # variance is the inverse Schur complement of its column in the joint fit).
    _, dx = llr_stats.change_fits(before, after, 2)
    pi_b, pi_a = (llr_stats.unpack(x, 2)[0] for x in (before, after))
    joint = np.block([[pi_b + pi_a, pi_a[:, h:h + 1]], [pi_a[h:h + 1, :], pi_a[h, h]]])
    sd = math.sqrt(np.linalg.inv(joint)[-1, -1])
    scale = (1.0, pi_a[0, 1] / pi_a[0, 0])
    margin = abs(dx[h, h]) * scale[h] - step.detectable[1 - h] * scale[1 - h]
    assert margin > 5.0 * sd * scale[h]
    runs = 40
    cats = [_categorise(name, seed) for seed in range(runs)]
    right = sum(c.kind == kind and c.confirmed for c in cats)
    wrong = sum(c.confirmed and c.kind == llr_stats.KINDS[1 - h] for c in cats)
    assert right >= stats.binom.ppf(1e-3, runs, p_named), [c.kind for c in cats]
    assert wrong <= stats.binom.isf(1e-3, runs, 1e-3)
    assert all(c.shape == 'ramp' for c in cats if c.kind == kind)


@pytest.mark.parametrize('name, kind', [('dry ramp', 'dry'), ('viscous ramp', 'viscous')])
def test_a_growing_change_is_not_confirmed_by_the_step_rule(name, kind):
    """A ramp the growth tests cannot name is never confirmed ``both`` by the step rule.

    The cause of the wrong kinds of bus ramps (docs/calibration.md "Kinds on ramps"): when
    the other kind's growth is significant at 5 % (probability 0.05 for a pure ramp) the
    growth tests name nothing and the step verdict stood: the step fit of a growing level
    is ``both`` (noise-free z of both directions far beyond z*), so a pure ramp was
    confirmed ``both`` in about 5 % of the runs (before this check: 18 and 24 of 400).
    The step check rejects the step model on the after segment (its growth statistic has
    a noise-free non-centrality far beyond the Bonferroni limit), so a confirmed wrong kind
    needs a false significance at 1e-3 (the other kind's growth) or a missed growth
    (probability from the non-central chi-square, checked below).
    """
    before, after, ramp = _sums(name, None)
    shapes = llr_growth.ramp_shapes(ramp, 2)
    lam = llr_growth.growth_statistic(after, shapes, 1.0, 2)
    limit = stats.chi2.isf(1e-3 / shapes.shape[0], 2)
    miss = stats.ncx2.cdf(limit, 2, lam)
    assert miss < 1e-6
    runs = 200
    cats = [_categorise(name, seed) for seed in range(runs)]
    wrong = sum(c.confirmed and c.kind != kind for c in cats)
    assert wrong <= stats.binom.isf(1e-3, runs, 1e-3 + miss), [c.kind for c in cats]
    # A step does not grow: its statistic is central (noise-free 0), so the check takes a
    # step's verdict away only through a false significance at the category level.
    before, after, ramp = _sums('both step', None)
    assert llr_growth.growth_statistic(after, llr_growth.ramp_shapes(ramp, 2), 1.0,
                                       2) == pytest.approx(0.0, abs=1e-6)


def test_a_both_step_stays_both():
    """A step in both directions is not named a single kind by the growth tests.

    A step does not grow: both growth statistics are central chi-square (noise-free
    non-centrality 0), so a single kind is named only by a false significance at 1e-3
    of one of them; the step categorisation confirms ``both`` (z of 19 and 9 noise-free).
    """
    assert _noncentrality('both step') == pytest.approx((0.0, 0.0), abs=1e-6)
    runs = 40
    cats = [_categorise('both step', seed) for seed in range(runs)]
    single = sum(c.kind in ('dry', 'viscous') for c in cats)
    assert single <= stats.binom.isf(1e-3, runs, 2e-3)
    assert sum(c.kind == 'both' and c.shape == 'step' for c in cats) >= runs - single - 1


def test_ramp_shapes_include_a_ramp_that_stopped():
    # Blocks of the after segment: the shape of candidate i grows until the end of block i
    # and is flat after; the last candidate is the straight ramp.
    rng = np.random.default_rng(0)
    terms = rng.standard_normal((30, 6))
    u = np.arange(30) * DT
    blocks = np.array([llr_growth.ramp_sums(terms[a:b], u[a:b])
                       for a, b in ((0, 10), (10, 20), (20, 30))])
    shapes = llr_growth.ramp_shapes(blocks, 2)
    for i, end in enumerate((9, 19, 29)):
        r = np.minimum(u, u[end])
        assert shapes[i, :6] == pytest.approx((terms * r[:, None]).sum(axis=0), rel=1e-12)
        assert shapes[i, 6:] == pytest.approx((terms * (r * r)[:, None]).sum(axis=0),
                                              rel=1e-12)


def _ramp_run(seed: int, dry: float, visc: float, n: int = 24_000, start: int = 6000,
              ramp: int = 7200, second: tuple[int, float, float] | None = None):
    """Detector-level run: unit noise, bus-like speed, a ramp from ``start`` to full size.

    ``second``: (index, dry step, viscous step) of a second, independent change.
    """
    rng = np.random.default_rng(seed)
    k = np.arange(n, dtype=float)
    w = bus_like_speed(n)
    rise = np.clip((k - start) / ramp, 0.0, 1.0)
    fc = 1.0 + dry * rise
    fv = 0.05 + visc * rise
    if second is not None:
        fc = fc + second[1] * (k >= second[0])
        fv = fv + second[2] * (k >= second[0])
    f = -fc * np.sign(w) - fv * w + rng.standard_normal(n)
    return k * DT, w, f


def test_detector_names_ramps_declares_them_once_and_streaming_equals_batch():
    """Seeded ramps through the detector (ramp sums taken block by block, revisions).

    Regression on fixed seeds (measured: the first declaration ends with the right
    confirmed kind in 6/6 dry and 5/6 viscous ramps, the step categorisation alone in 0/6
    and 3/6; at most one more declaration of the same ramp: 0 in the 6 dry ramps, 3 with
    each hypothesis of the continuation test at its own best time shape, and each dry
    ramp was declared 4 times before the continuation test); a confirmed wrong
    single kind needs a false significance at 1e-3. Streaming and batch events are
    identical.
    """
    for dry, visc, kind, least in ((6.0, 0.0, 'dry', 5), (0.0, 0.06, 'viscous', 4)):
        right = wrong = 0
        for seed in range(6):
            t, w, f = _ramp_run(seed, dry, visc)
            events = detect_batch(t, w, f)
            first = [e for e in events if e.revision == 0 and e.index >= 5500]
            assert 1 <= len(first) <= 2, first
            final = max((e for e in events if e.index == first[0].index),
                        key=lambda e: e.revision)
            confirmed = final.details[keys.KIND_CONFIRMED]
            right += confirmed and final.kind == kind
            wrong += confirmed and final.kind in ('dry', 'viscous') and final.kind != kind
            if seed == 0:
                det = LLRDetector('rw1')
                streamed = []
                for a, b, c in zip(t.tolist(), w.tolist(), f.tolist()):
                    streamed.extend(det.update(a, b, c))
                assert streamed + det.finish() == events
        assert right >= least, (kind, right)
        assert wrong == 0, (kind, wrong)


def test_a_ramp_that_stops_is_not_declared_again_at_its_end():
    # Seeds 20-39 (found on 0-19): a dry ramp rises until sample 13200 and stays. The
    # continuation test compared each hypothesis at its own best time shape, so H1 paired
    # an earlier knot with a free step that took up the rest of the rise, and the end of
    # the ramp was declared as a new change, named viscous or both (11 extra declarations
    # here; 12 on 0-19). Profiled at H0's best shape, whose knot lies within one block of
    # the end, a step adds only what a slightly misplaced knot leaves (measured: 0 extra on
    # 0-19 and 20-39; the bound leaves room for the category level's chance, 1e-3 a test).
    extra = 0
    for seed in range(20, 40):
        t, w, f = _ramp_run(seed, 6.0, 0.0)
        extra += sum(e.revision == 0 and e.index >= 5500 for e in detect_batch(t, w, f)) - 1
    assert extra <= 2, extra


@pytest.mark.parametrize('second', [(11_000, 0.0, 0.1), (11_000, 3.0, 0.0)])
def test_a_second_change_during_a_ramp_is_still_declared(second):
    """The continuation test never hides a second change declared while a ramp grows.

    A viscous (dry) step of torque ~1 sd (3 sd) at 11000, while the dry ramp declared at
    about 8100 is still followed: a new change is declared within 500 samples of it in
    every run (measured 6/6 each), because a step beside the growing ramp is significant
    at 1e-3 (:func:`llr_growth.continues`).
    """
    for seed in range(3):
        t, w, f = _ramp_run(seed, 6.0, 0.0, second=second)
        firsts = [e.index for e in detect_batch(t, w, f) if e.revision == 0]
        assert any(abs(i - second[0]) <= 500 for i in firsts), firsts


def test_a_viscous_ramp_is_not_confirmed_both_by_its_step_fit():
    # Seed 3319 (development): the first declaration of a viscous ramp was confirmed `both`
    # at its 8 L0 re-check (z_dry -3.50, z_viscous 15.02): the step fit of a level still
    # rising shares the rise with the dry direction; the step check did not reject (13.78
    # against 18.95 at 13 time shapes), the growth tests named nothing. Beside a growing
    # viscous change the dry step explains chi 2.37 (straight ramp): not significant, so
    # the `both` is withdrawn (docs/llr.md "Kinds that survive collinearity").
    t, w, f = _ramp_run(3319, 0.0, 0.06)
    events = detect_batch(t, w, f)
    first = [e for e in events if e.revision == 0 and e.index >= 5500][0]
    mine = [e for e in events if e.index == first.index]
    assert not any(e.kind == 'both' for e in mine)
    assert mine[-1].details[keys.KIND_GUESS] == 'viscous'


def test_no_confirmed_wrong_kind_on_fresh_ramps():
    # Fresh seeds 3620-3639 (development: 0-29, 100-109, 3200-3219, 3300-3319; scored on
    # 3500-3519 before this test): the final kind of the first declaration of a dry and a
    # viscous ramp. A confirmed wrong kind needs a false significance at the category
    # level in one of its evaluations (the declaration, three re-checks, the end of
    # record; each growth test Bonferroni-corrected over its time shapes, and a `both`
    # needs each step component beside the other kind's growth), taking the true ramp as
    # one of the candidate shapes: P(any in 40 runs) <= 40 x 5 x 1e-3 = 0.2 (a union
    # bound; measured 0 of 80 on 3200-3219, 3300-3319).
    wrong = []
    for seed in range(3620, 3640):
        for dry, visc, kind in ((6.0, 0.0, 'dry'), (0.0, 0.06, 'viscous')):
            t, w, f = _ramp_run(seed, dry, visc)
            events = detect_batch(t, w, f)
            first = [e for e in events if e.revision == 0 and e.index >= 5500][0]
            final = max((e for e in events if e.index == first.index),
                        key=lambda e: e.revision)
            if final.details[keys.KIND_CONFIRMED] and final.kind != kind:
                wrong.append((seed, kind, final.kind))
    assert wrong == []


def test_a_kind_beside_the_other_kinds_growth():
    # White box of llr_kinds.stands_beside_growth: the step rule with the other kind
    # allowed to grow. Own component beyond z*^2, the other absent at 5 %, separable.
    dx = np.array([[1.0e-3, 0.0], [0.0, 1.0e-4], [1.0e-3, 1.0e-4]])
    limit, absent = Z_STAR * Z_STAR, llr_kinds.Z_ABSENT ** 2
    free = (0.0, 0.0)
    stands = llr_kinds.stands_beside_growth
    assert stands((0.5, limit + 1.0), 1, limit, dx, free, 10.0)
    assert stands((limit + 1.0, absent), 0, limit, dx, free, 10.0)
    # Only the step tests' own kind: the same statistics do not name the other.
    assert not stands((0.5, limit + 1.0), 0, limit, dx, free, 10.0)
    assert not stands((absent + 0.1, limit + 1.0), 1, limit, dx, free, 10.0)
    assert not stands((0.5, limit), 1, limit, dx, free, 10.0)
    # Not separable: a dry step of the torque of this viscous change would not be found.
    assert not stands((0.5, limit + 1.0), 1, limit, dx, (1.0, 0.0), 10.0)


BUS_RAMP = pathlib.Path(__file__).parent / 'data' / 'bus_viscous_ramp_sums.npz'


def test_a_bus_viscous_ramp_is_named_beside_the_dry_growth():
    """The last re-check of a viscous ramp on the bus: named viscous, no longer undecided.

    Sums saved from ``rwa-monitor``'s bus (bench bus_ramps, development seed 7327, rw2:
    viscous +3e-6 N m s/rad over 1800 s). The step tests find viscous alone (z 0.85,
    27.4) but the after segment grows, so the step verdict cannot stand; the growth tests
    name nothing: the dry and viscous growth columns are nearly collinear here (0.5 % of
    each column's information left), so the viscous growth beside the dry growth reaches
    13.0 against its Bonferroni limit of 16.6 at 22 shapes. Beside a growing dry change
    the viscous step still explains about 820 sigma^2, and beside a growing viscous
    change the dry step explains nothing: viscous (llr_kinds.stands_beside_growth). The
    rules before gave `undecided` ("the change grows"), as on 5 of the 20 development
    seeds' viscous ramps.
    """
    data = np.load(BUS_RAMP)
    before, after, ramp = data['before'], data['after'], data['ramp']
    n_before, z = int(data['n_before']), float(data['z'])
    s2 = llr_stats.before_noise_var(before, n_before, 2)
    shapes = llr_growth.ramp_shapes(ramp, 2)
    assert llr_growth.grows(after, shapes, s2, 2, z)
    best = llr_growth.ramp_fits(before, after, shapes, 2).max(axis=0)
    assert llr_growth.ramp_kind(best, s2, z, shapes.shape[0]) is None
    e_dry, e_viscous = llr_growth.steps_beside_growth(before, after, shapes, 2)
    assert e_dry / s2 <= llr_kinds.Z_ABSENT ** 2 < z * z < e_viscous / s2
    cat = llr_kinds.categorise(before, n_before, after, 2, None, z, ramp)
    assert (cat.kind, cat.confirmed, cat.shape) == ('viscous', True, 'ramp')


BUS_CONTINUATION = pathlib.Path(__file__).parent / 'data' / 'bus_continuation_sums.npz'


def _declared(kind: str, shape: str, before: np.ndarray, n_before: int) -> DeclaredChange:
    """Return a declared change holding what growth_kind reads (the rest placeholders)."""
    return DeclaredChange(n_before=n_before, kind=kind, guess=kind, confirmed=True,
                          revision=1, rows=(0, 0, 0), time=0.0, log_p=-30.0, checks=(),
                          points=(), ramp_end=0, tau=0, closed=False, tail=False,
                          finished=False, after_gap_s=math.nan, shape=shape, before=before,
                          gap=np.zeros_like(before), ramp=np.zeros((1, 19)),
                          speeds=np.zeros((1, 2)))


def test_a_step_kind_the_data_no_longer_find_does_not_fix_the_growth():
    """A second declaration of a bus viscous ramp is its continuation, not a new change.

    Sums saved at the second declaration of bench bus_ramps' seed 7503 (rw2: viscous +3e-6
    N m s/rad over 1800 s), found while developing the rule. Its first re-check, 4 blocks
    into the ramp, was confirmed `dry` by the step tests (z 3.47 against 3.29, z_viscous
    1.32); 50 s later the ramp was declared again. On every sample up to then the step
    tests find dry no more (z 1.2) and viscous instead (5.1). Tested as a dry growth, the
    new declaration is a new change (the code before: the first change kept `dry`, the
    second stayed undecided); a kind the step tests no longer find does not fix the
    direction of growth, and as a growth in either direction it is the same change, whose
    re-check then confirms `viscous`.
    """
    data = np.load(BUS_CONTINUATION)
    before, after, blocks = data['before'], data['after'], data['blocks']
    n_before, z = int(data['n_before']), float(data['z'])
    cat = llr_kinds.categorise(before, n_before, after, 2, None, z)
    assert abs(cat.z[0]) < z < abs(cat.z[1])

    def continues(kind: str) -> bool:
        return llr_growth.continues(before, n_before, after, blocks, data['tail'],
                                    data['offsets'], kind, 2, None, z)

    assert not continues('dry') and continues('undecided')
    config = LLRConfig.from_parameters(category_level=1e-3)   # the bus run's: noise fitted
    assert config.z_threshold == pytest.approx(z) and config.noise_var is None
    assert growth_kind(_declared('dry', 'step', before, n_before), after, config) \
        == 'undecided'
    # A kind named for a growing change (shape ramp) keeps fixing its direction, and so
    # does a step kind the step tests still find (the viscous one here).
    assert growth_kind(_declared('dry', 'ramp', before, n_before), after, config) == 'dry'
    assert growth_kind(_declared('viscous', 'step', before, n_before), after, config) \
        == 'viscous'
