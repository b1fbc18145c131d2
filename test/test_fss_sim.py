"""The FSS simulator: semi-Markov jumps, level laws, anomalies, truth, data sets."""

import json

import numpy as np
import pytest

from rwa_monitor.core.fss.model import EXAMPLE_1, EXAMPLE_2
from rwa_monitor.sim import fss


def test_residence_times_and_levels_follow_the_examples():
    rng = np.random.default_rng(0)
    for system in (EXAMPLE_1, EXAMPLE_2):
        level, config, jumped = fss.simulate_switching(system, 400_000, rng)
        starts = np.concatenate(([0], np.flatnonzero(jumped), [level.size]))
        for a, b in zip(starts[1:-2], starts[2:-1]):  # complete sojourns only
            lo, hi = system.residence[config[a]]
            assert lo <= b - a <= hi
            assert np.all(level[a:b] == level[a])
        for q, (lo, hi) in enumerate(system.levels):
            assert np.all((level[config == q] >= lo) & (level[config == q] <= hi))
        assert np.all(np.abs(np.diff(config)) <= 1)


def test_mean_residence_of_example_1():
    # Uniform residence on [1, 2000] and [1, 200]: means 1000.5 and 100.5 steps; with
    # ~360 sojourns of each the standard errors are ~30 and ~3 steps (bounds 5 sd).
    rng = np.random.default_rng(1)
    _, config, jumped = fss.simulate_switching(EXAMPLE_1, 400_000, rng)
    starts = np.flatnonzero(jumped)
    lengths, qs = np.diff(starts), config[starts[:-1]]
    assert lengths[qs == 0].mean() == pytest.approx(1000.5, abs=150)
    assert lengths[qs == 1].mean() == pytest.approx(100.5, abs=15)


@pytest.mark.parametrize('status', fss.STATUSES)
def test_legacy_anomalies_change_only_their_component(status):
    rng = np.random.default_rng(2)
    sig = fss.simulate_wheel(20_000, status, rng, profile='biased', anomalies='legacy')
    dry_range = fss.ANOMALY_BASE_DRY if status == 'dry' else fss.NOMINAL_BASE_DRY
    visc_range = fss.ANOMALY_VISCOUS if status == 'viscous' else fss.NOMINAL_VISCOUS
    assert dry_range[0] <= sig['base_dry'] <= dry_range[1]
    assert visc_range[0] <= sig['viscous'] <= visc_range[1]
    systems = fss.systems_for(status)
    for s, system in enumerate(systems):
        for q, (lo, hi) in enumerate(system.levels):
            sel = sig['configs'][:, s] == q
            assert np.all((sig['levels'][sel, s] >= lo) & (sig['levels'][sel, s] <= hi))
    assert (systems[0].levels != EXAMPLE_1.levels) == (status == 'fss1')
    assert (systems[1].levels != EXAMPLE_2.levels) == (status == 'fss2')


@pytest.mark.parametrize('status', fss.STATUSES)
@pytest.mark.parametrize('size', [1.1, 2.0, 3.0])
def test_realistic_anomalies_scale_the_wheels_own_nominal(status, size):
    wheel = {'base_dry': 0.95, 'viscous': 1.05, 'noise_std': 0.025}
    sig = fss.simulate_wheel(20_000, status, np.random.default_rng(5), profile='biased',
                             wheel=wheel, size=size)
    assert sig['nominal'] == wheel
    assert sig['base_dry'] == pytest.approx(0.95 * (size if status == 'dry' else 1.0))
    assert sig['viscous'] == pytest.approx(1.05 * (size if status == 'viscous' else 1.0))
    assert sig['size'] == (None if status == 'nominal' else size)
    systems = fss.systems_for(status, size=size)
    active = systems[0].levels[1]
    assert active == pytest.approx((0.3 * size, 0.4 * size) if status == 'fss1' else (0.3, 0.4))
    steps = [lo for lo, _ in systems[1].levels]
    assert steps == pytest.approx([0.0, 0.5, 1.0] if status != 'fss2' else
                                  [0.0, 0.5 * size, 1.0 * size])
    for s, system in enumerate(systems):
        for q, (lo, hi) in enumerate(system.levels):
            sel = sig['configs'][:, s] == q
            assert np.all((sig['levels'][sel, s] >= lo) & (sig['levels'][sel, s] <= hi))


def test_realistic_sizes_are_drawn_in_range():
    sizes = [fss.simulate_wheel(200, 'dry', np.random.default_rng(k))['size']
             for k in range(50)]
    assert all(fss.ANOMALY_SIZE[0] <= z <= fss.ANOMALY_SIZE[1] for z in sizes)
    with pytest.raises(ValueError, match='size'):
        fss.simulate_wheel(200, 'dry', np.random.default_rng(0), size=0.5)


def test_telemetry_sign_units_and_truth():
    tele = fss.simulate_fss(statuses=('nominal', 'dry'), n_samples=5000, seed=3)
    assert list(tele.wheels) == ['rw1', 'rw2']
    for wheel_id, wheel in tele.wheels.items():
        dry = tele.truth[f'{wheel_id}_dry']
        visc = tele.truth[f'{wheel_id}_viscous']
        resid = wheel.friction - (-dry * np.sign(wheel.speed) - visc * wheel.speed)
        noise = tele.truth[f'{wheel_id}_noise_std'][0]
        # 5000 Gaussian samples: the sample std is within 5 % of the true one (sd 1 %).
        assert resid.std() == pytest.approx(noise, rel=0.05)
        assert np.allclose(dry, tele.truth[f'{wheel_id}_base_dry']
                           + tele.truth[f'{wheel_id}_fss1'] + tele.truth[f'{wheel_id}_fss2'])
    assert tele.truth['rw2_status'][0] == fss.STATUSES.index('dry')
    again = fss.simulate_fss(statuses=('nominal', 'dry'), n_samples=5000, seed=3)
    assert np.array_equal(again.wheels['rw2'].friction, tele.wheels['rw2'].friction)


def test_dataset_builder_is_seeded_with_a_manifest(tmp_path):
    manifest = fss.build_dataset(tmp_path / 'a', per_status=1, seed=4, n_samples=2000)
    fss.build_dataset(tmp_path / 'b', per_status=1, seed=4, n_samples=2000)
    assert [e['status'] for e in manifest['windows']] == list(fss.STATUSES)
    on_disk = json.loads((tmp_path / 'a' / 'manifest.json').read_text())
    assert on_disk['windows'] == manifest['windows']
    for entry in manifest['windows']:
        a = fss.load_window(tmp_path / 'a', entry)
        b = fss.load_window(tmp_path / 'b', entry)
        assert np.array_equal(a[1], b[1]) and a[0].size == 2000
        ref = fss.load_window(tmp_path / 'a', entry, reference=True)
        assert ref[0].size == 2000 and not np.array_equal(ref[1], a[1])
    with pytest.raises(ValueError, match='manifest'):
        fss.load_manifest(tmp_path)


def test_legacy_dataset_reproduces_the_first_bench_draws(tmp_path):
    # Window j of status s of a legacy data set is simulate_wheel on the seed sequence
    # (seed, s, j) with the legacy anomalies: the first bench's windows, unchanged.
    manifest = fss.build_dataset(tmp_path, per_status=1, seed=0, n_samples=2000,
                                 anomalies='legacy', statuses=('dry',))
    entry = manifest['windows'][0]
    rng = np.random.default_rng(np.random.SeedSequence(0, spawn_key=(1, 0)))
    sig = fss.simulate_wheel(2000, 'dry', rng, anomalies='legacy')
    assert fss.ANOMALY_BASE_DRY[0] <= entry['base_dry'] == sig['base_dry']
    assert np.array_equal(fss.load_window(tmp_path, entry)[1],
                          sig['friction'].astype(np.float32))
    with pytest.raises(ValueError, match='reference'):
        fss.load_window(tmp_path, entry, reference=True)


def test_bad_simulator_parameters():
    with pytest.raises(ValueError, match='status'):
        fss.simulate_fss(statuses=('broken',))
    with pytest.raises(ValueError, match='n_samples'):
        fss.simulate_fss(n_samples=0)
