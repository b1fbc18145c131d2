"""End of record: the final kind of an open declaration (docs/llr.md "End of record")."""

import math

import numpy as np
import pytest
from scipy import stats

from rwa_monitor.core import keys, llr_growth, llr_kinds, llr_stats
from rwa_monitor.core.llr import detect_batch, LLRDetector
from rwa_monitor.sim.friction import Anomaly, simulate_friction
from rwa_monitor.sim.profiles import paper_profile

PAPER = {'window': 500, 'k_verif': 250, 'false_alarm_rate': 1e-5}


def paper_file(seed: int, n: int = 4000, change: int = 1500, dry: float = 0.5,
               viscous: float = 0.0, profile: str = 'fig3'):
    """Return one of the papers' own profiles (scaled units, 1 Hz) with one step."""
    kind = 'both' if dry and viscous else 'dry' if dry else 'viscous'
    tele = simulate_friction(wheels=('rw1',), n_samples=n, rate_hz=1.0, profile=profile,
                             units='scaled', seed=seed,
                             anomalies=[Anomaly('rw1', kind, float(change), dry, viscous)])
    wheel = tele.wheels['rw1']
    return tele.time, wheel.speed, wheel.friction


def test_a_file_that_ends_before_the_first_recheck_gets_its_final_kind():
    # 4,000 samples, change at 1,500: the first re-check (2 L0 ~ 1,500 samples after the
    # change) may not come before the end. Fresh seeds (development: 300-319, where the
    # last word was undecided in 4 of 20 before and right in 20 of 20 with this step).
    # Every declaration ends with one `final` event on all samples after the change. The
    # final step evaluation confirms the dry step unless the viscous component lies
    # beyond 1.96 (probability 0.05) or the separability guard fails (at 2,500 samples
    # after the change a +0.5 step passes it, docs/llr.md table): >= 7 of 10 right
    # (binomial, p = 0.95: P(< 7) < 0.002). Wrong kinds: below (seed 2731 ended a
    # confirmed `both` before the rule of docs/llr.md "Kinds that survive collinearity").
    right = 0
    for seed in range(2730, 2740):
        t, w, f = paper_file(seed)
        events = detect_batch(t, w, f, **PAPER)
        assert len({e.index for e in events}) == 1, events
        final = events[-1]
        assert final.details[keys.FINAL] is True
        assert final.details[keys.FINAL_SAMPLES] == t.size - final.index
        assert [e.revision for e in events] == list(range(len(events)))
        assert not any(keys.FINAL in e.details for e in events[:-1])
        right += final.kind == 'dry'
        if final.kind == 'undecided':
            assert final.details[keys.KIND_REASON]
    assert right >= 7


def test_streaming_with_finish_equals_batch():
    t, w, f = paper_file(2740)
    det = LLRDetector('rw1', **PAPER)
    streamed = [e for a, b, c in zip(t.tolist(), w.tolist(), f.tolist())
                for e in det.update(a, b, c)]
    assert not any(keys.FINAL in e.details for e in streamed)   # live: no end of record
    streamed += det.finish()
    assert [e.to_json() for e in streamed] == \
        [e.to_json() for e in detect_batch(t, w, f, **PAPER)]
    assert streamed[-1].details[keys.FINAL] and det.finish() == []   # closed once


def test_nothing_open_nothing_final():
    rng = np.random.default_rng(2741)
    t = np.arange(3000.0)
    w = 20.0 + 5.0 * np.cos(np.pi * t / 1000.0)
    f = -np.sign(w) - 0.05 * w + rng.standard_normal(t.size)
    det = LLRDetector('rw1', **PAPER)
    for a, b, c in zip(t.tolist(), w.tolist(), f.tolist()):
        assert det.update(a, b, c) == []
    assert det.finish() == [] and LLRDetector('rw1').finish() == []


def test_constant_speed_after_the_change_stays_undecided_with_the_reason():
    # No speed variation after the change: dry and viscous cannot be separated, however
    # many samples the record holds after it.
    rng = np.random.default_rng(2742)
    n, change = 6000, 3000
    t = np.arange(float(n))
    w = np.where(t < change, 20.0 + 5.0 * np.cos(np.pi * t / 500.0), 20.0)
    fc = np.where(t < change, 1.0, 1.5)
    f = -fc * np.sign(w) - 0.05 * w + 0.2 * rng.standard_normal(n)
    events = detect_batch(t, w, f, **PAPER)
    final = events[-1]
    assert final.details[keys.FINAL] and final.kind == 'undecided'
    assert 'speed variation' in final.details[keys.KIND_REASON]


CLAIMS = {'dry': (keys.Z_DRY,), 'viscous': (keys.Z_VISCOUS,), 'both': (keys.Z_DRY, keys.Z_VISCOUS)}


def _supported(event, z_star: float) -> bool:
    """Return True if each component the event's kind claims is beyond z* in the event."""
    return all(abs(event.details[key]) > z_star for key in CLAIMS[event.kind])


def test_a_confirmed_kind_at_the_end_is_one_the_final_tests_support():
    # The three confirmed wrong kinds found on the Fig. 3 files (docs/llr.md "Kinds that
    # survive collinearity", "End of record"): seed 2731 (dry) ended `both`, named by two
    # growth statistics of nearly one column (z 4.21 / 0.71 in its event); seed 3273 kept
    # a `both` of its declaration (z_viscous -3.94 on 760 samples, -2.38 on all 2,523) and,
    # with a viscous step, a `dry` of its first re-check (z_dry 3.40, then 2.57). Now a
    # confirmed `both` has both components beyond z* and a kind kept at the end of record
    # its own (every confirmed step-shaped final is checked in the next test).
    z_star = llr_stats.z_threshold(1e-3)
    for seed, dry, viscous in ((2731, 0.5, 0.0), (3273, 0.5, 0.0), (3273, 0.0, 0.025)):
        t, w, f = paper_file(seed, dry=dry, viscous=viscous)
        events = detect_batch(t, w, f, **PAPER)
        final = events[-1]
        assert final.details[keys.FINAL] and final.kind == 'undecided', final
        assert final.details[keys.KIND_GUESS] == ('dry' if dry else 'viscous')
        both = [e for e in events if e.kind == 'both' and e.details[keys.KIND_CONFIRMED]]
        assert all(_supported(e, z_star) for e in both)


def _growth_correlation(end: int, knot: float, change: int = 1500) -> float:
    """Return the correlation of the two growth columns after the offsets (noise-free).

    The after segment ``[change, end]`` of the Fig. 3 profile, the time shape ``min(u,
    knot)``: the growth z values of the two kinds (each beside the other) have this
    correlation, with the sign reversed.
    """
    w = paper_profile('fig3', np.arange(change, end + 1))
    r = np.minimum(np.arange(w.size, dtype=float), knot)
    h = np.column_stack([-np.sign(w), -w])
    q = np.linalg.qr(h)[0]
    growth = r[:, None] * h
    a, b = (growth - q @ (q.T @ growth)).T
    return float(a @ b / math.sqrt((a @ a) * (b @ b)))


def test_no_confirmed_wrong_kind_at_the_end_of_fresh_paper_files():
    # Fresh seeds (development: 300-319, 2730-2739, 3200-3299, 5000-5399), Fig. 3 profile,
    # 4,000 samples, a dry +0.5 or a viscous +0.025 step at 1,500. The end-of-record kind of
    # a pure step is a confirmed wrong kind only if, in the final evaluation, (a) the test
    # of the absent component rejects at the category level (|z| > z*, probability 1e-3
    # for the known change time): that covers `both` and the other single kind, confirmed
    # by this evaluation or kept from an earlier one (a kept kind must be supported); or
    # (b) the growth tests name the other kind: its growth z beyond z* while this kind's
    # is within 1.96. The two growth z have correlation -r (r below, every time shape,
    # noise-free), so (b) needs an independent normal deviate beyond (z* |r| - 1.96) /
    # sqrt(1 - r^2) for one of the shapes. P(a wrong kind in 40 runs) <= 40 (1e-3 + b).
    z_star = llr_stats.z_threshold(1e-3)
    knots = [*range(250, 2501, 50), math.inf]
    r = min(abs(_growth_correlation(3999, knot)) for knot in knots)
    deviate = (z_star * r - llr_kinds.Z_ABSENT) / math.sqrt(1.0 - r * r)
    growth_named = len(knots) * 2.0 * stats.norm.sf(deviate)
    assert growth_named < 1e-6
    assert 40 * (1e-3 + growth_named) < 0.041
    wrong = []
    for seed in range(3400, 3420):
        for dry, viscous, kind in ((0.5, 0.0, 'dry'), (0.0, 0.025, 'viscous')):
            t, w, f = paper_file(seed, dry=dry, viscous=viscous)
            final = detect_batch(t, w, f, **PAPER)[-1]
            assert final.details[keys.FINAL]
            if final.details[keys.KIND_CONFIRMED] and final.kind != kind:
                wrong.append((seed, kind, final.kind))
            if final.details[keys.KIND_CONFIRMED] and \
                    final.details[keys.KIND_SHAPE] == 'step':
                assert _supported(final, z_star), final
    assert wrong == []


def test_a_closed_change_gets_the_answer_of_the_whole_record():
    # Demo scenario seed 3300, rw2 (dry +2e-4 N m at 3,600 s): `dry` at its declaration,
    # `both` at its re-checks 4 L0 and 8 L0 (z_viscous 3.90 and 3.30 on ~3,000 and ~6,000
    # samples against z* 3.29), then nothing: the re-checks were over long before the end
    # of the record. The end of record now also finalises the last declared change after
    # its re-checks (docs/llr.md "End of record", *closed changes*): on all 72,000 samples
    # after the change the tests say `dry` (z_viscous -0.29), and the event says so.
    from rwa_monitor.cli import cmd_demo
    from rwa_monitor.sim.friction import simulate_friction_with_truth
    duration = cmd_demo.DEFAULT_HOURS * 3600.0
    tele, _ = simulate_friction_with_truth(
        wheels=list(cmd_demo.WHEELS), duration_s=duration, rate_hz=cmd_demo.RATE_HZ,
        seed=3300,
        anomalies=[Anomaly('rw2', 'dry', round(duration / 3), delta_dry=2.0e-4),
                   Anomaly('rw3', 'viscous', round(2 * duration / 3), delta_viscous=1.0e-6)])
    ch = tele.wheels['rw2']
    events = detect_batch(tele.time, ch.speed, ch.friction, component='rw2')
    assert {e.index for e in events} == {events[0].index}
    assert any(e.kind == 'both' for e in events[:-1])   # the live re-checks' answer
    final = events[-1]
    assert final.details[keys.FINAL] and final.kind == 'dry'
    assert final.details[keys.KIND_CONFIRMED]
    assert final.details[keys.FINAL_SAMPLES] == ch.speed.size - final.index


def test_a_closed_change_whose_answer_stands_gets_no_final_event():
    # Golden-like records keep their events: a closed change gets a final event only when
    # the answer on the whole record differs from the last one given. 12,000 samples,
    # change at 1,500 (re-checks over by ~7,500); every declaration's events are its own.
    for seed in range(3640, 3650):
        t, w, f = paper_file(seed, n=12_000)
        events = detect_batch(t, w, f, **PAPER)
        last = events[-1]
        if keys.FINAL in last.details:
            before = max((e for e in events[:-1] if e.index == last.index),
                         key=lambda e: e.revision)
            assert (before.kind, before.details[keys.KIND_GUESS],
                    before.details[keys.KIND_CONFIRMED]) != \
                (last.kind, last.details[keys.KIND_GUESS], last.details[keys.KIND_CONFIRMED])
        det = LLRDetector('rw1', **PAPER)
        streamed = [e for a, b, c in zip(t.tolist(), w.tolist(), f.tolist())
                    for e in det.update(a, b, c)]
        assert streamed + det.finish() == events and det.finish() == []


def test_no_confirmed_wrong_kind_at_the_end_of_fresh_long_paper_files():
    # Fresh seeds 3600-3619, Fig. 3 profile, 12,000 samples, a dry +0.5 or a viscous
    # +0.025 step at 1,500: the re-checks end near 7,500 and the change is closed; its
    # answer at the end is the final evaluation's (an earlier kind kept only where those
    # tests support it). A wrong confirmed kind needs, in that evaluation: (a) a false
    # rejection of the absent component (probability 1e-3), or (b) the growth tests naming
    # the other kind: for a step neither growth exists, and the other kind's growth beside
    # this kind's is compared, at its best of the m time shapes, with the chi2_1 quantile
    # at 1e-3 / m (docs/llr.md "Kinds on ramps", one rule for the time shapes), so (b) has
    # probability <= 1e-3 whatever the correlation of the shapes (on this longer segment
    # the growth columns are not nearly one, as on the 4,000-sample files above).
    # P(a wrong kind in 40 runs) <= 40 (1e-3 + 1e-3) = 0.08.
    z_star = llr_stats.z_threshold(1e-3)
    assert llr_growth.ramp_limits(1, z_star, 13)[0] == pytest.approx(
        stats.chi2.isf(1e-3 / 13, 1))
    wrong = []
    for seed in range(3600, 3620):
        for dry, viscous, kind in ((0.5, 0.0, 'dry'), (0.0, 0.025, 'viscous')):
            t, w, f = paper_file(seed, n=12_000, dry=dry, viscous=viscous)
            events = detect_batch(t, w, f, **PAPER)
            first = events[0]
            final = max((e for e in events if e.index == first.index),
                        key=lambda e: e.revision)
            if final.details[keys.KIND_CONFIRMED] and final.kind != kind:
                wrong.append((seed, kind, final.kind))
    assert wrong == []


def test_the_end_of_a_closed_change_never_adds_a_component(monkeypatch):
    # A closed change confirmed `dry` by its re-checks (seed 3660, 12,000 samples): if the
    # whole record's evaluation says `both` (found on the bus, calibrated seed 3102 rw2:
    # `dry` at z 32.1 / 0.3, then on all 18,407 samples z 239.8 / 3.66, a viscous share of
    # 1.5 % of the dry torque that grows with the samples), the answer stands (no event);
    # another single kind is given; an unconfirmed evaluation that still supports `dry`
    # (z_dry beyond z*) keeps it (no event). `both` -> `dry`: the demo test above.
    t, w, f = paper_file(3660, n=12_000)
    det = LLRDetector('rw1', **PAPER)
    events = det.process_arrays(t, w, f)
    assert events[-1].kind == 'dry' and events[-1].details[keys.KIND_CONFIRMED]
    assert det.state().change.closed
    real = llr_kinds.categorise

    def saying(kind, confirmed):
        def fake(*args, **kwargs):
            out = real(*args, **kwargs)
            return out._replace(kind=kind, guess=kind if confirmed else 'dry',
                                confirmed=confirmed, z=(240.0, 3.7))
        return fake

    for kind, confirmed, given in (('both', True, False), ('viscous', True, True),
                                   ('undecided', False, False)):
        again = LLRDetector('rw1', **PAPER)
        again.process_arrays(t, w, f)
        monkeypatch.setattr(llr_kinds, 'categorise', saying(kind, confirmed))
        final = again.finish()
        monkeypatch.setattr(llr_kinds, 'categorise', real)
        assert bool(final) == given, (kind, final)
    assert llr_kinds.adds_component('dry', 'both') and llr_kinds.adds_component(
        'viscous', 'both')
    assert not any(llr_kinds.adds_component(a, b) for a, b in (
        ('both', 'dry'), ('dry', 'viscous'), ('undecided', 'both'), ('both', 'both')))


def test_a_closed_change_takes_its_tail_once_per_ring_with_the_same_sums(monkeypatch):
    # After its re-checks a change takes the samples since its last take once per ring
    # length (LLRConfig.tail_stride), not once per window: the ring still holds all of
    # them at the take, so the tail's sums are those of takes every window samples, up to
    # the order of the additions. A stride past the ring would sum overwritten samples.
    from rwa_monitor.core.llr_config import LLRConfig
    t, w, f = paper_file(3640, n=30_000)

    def tail(stride_of):
        monkeypatch.setattr(LLRConfig, 'tail_stride', property(stride_of))
        det = LLRDetector('rw1', **PAPER)
        events = det.process_arrays(t, w, f)
        closed = det.state().change
        events += det.finish()
        return events, closed, det.state().change, det.config.ring_length

    events, closed, final, ring = tail(lambda c: c.ring_length)
    by_window, closed_w, final_w, _ = tail(lambda c: c.window)
    assert closed.closed and closed.tail and closed_w.tail
    assert t.size - closed.checks[-1] > 4 * ring     # several takes of the ring's stride
    assert (closed.ramp_end - closed.checks[-1]) % ring == 0
    assert (closed_w.ramp_end - closed.checks[-1]) % PAPER['window'] == 0
    assert closed.ramp_end != closed_w.ramp_end
    assert final.ramp_end == final_w.ramp_end == t.size - 1
    np.testing.assert_allclose(final.ramp, final_w.ramp, rtol=1e-12, atol=0)
    np.testing.assert_array_equal(final.speeds, final_w.speeds)
    assert [(e.kind, e.index, e.revision) for e in events] == \
        [(e.kind, e.index, e.revision) for e in by_window]
