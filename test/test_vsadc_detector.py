"""VSADC on simulated AOCS telemetry: detection, bad input, pipeline and `detect` CLI."""

import json

import numpy as np
import pytest

from rwa_monitor.cli.main import main as cli_main
from rwa_monitor.core.vsadc import VsadcDetector
from rwa_monitor.pipelines import vsadc as pipeline
from rwa_monitor.sim.aocs import AocsConfig, named_fault, simulate_aocs
from rwa_monitor.telemetry import Telemetry, write_telemetry

CONFIG = dict(pipeline.DEFAULTS, reference_window=400)


@pytest.fixture(scope='module')
def medium():
    """Medium drift (1e-6 rad/s per s) on gyro x from 600 s of a 1800 s record, seed 11."""
    return simulate_aocs(1800.0, fault=named_fault('medium', 'x', 600.0), seed=11,
                         config=AocsConfig(st_dropouts_per_hour=0.0))


def _events(tele, rows=None, config=CONFIG):
    det = VsadcDetector(**pipeline.detector_kwargs(config))
    rows = range(len(tele)) if rows is None else rows
    out = []
    for k in rows:
        q = tele.attitude[k]
        out += det.update(tele.time[k], tele.gyro[k], None if q is None else q,
                          tele.reference_rate[k], k)
    return out, det


def test_medium_drift_is_found_on_x_only(medium):
    # d passes the 1.5e-5 rad/s threshold when the 50 s window mean of a 1e-6 rad/s^2
    # ramp does: 1e-6 t^2 / (2 * 50) = 1.5e-5 -> t = 38.7 s after the onset; the window
    # mean noise (1e-5/sqrt(200) gyro, 3.4e-7 star tracker) moves that by about +-2 s.
    events, det = _events(medium)
    assert events and {e.component for e in events} == {'gyro_x'}
    first = events[0]
    assert first.detector == 'vsadc' and first.kind == 'drift'
    assert 600.0 + 30.0 <= first.declared_time <= 600.0 + 50.0
    assert 600.0 - 5.0 <= first.time <= first.declared_time
    # The ramp ends at 800 s; the label is bias within window + sigma_window (100 s) + 20 s.
    bias = [e for e in events if e.kind == 'bias']
    assert bias and 800.0 <= bias[0].declared_time <= 920.0
    assert events[-1].kind == 'bias'


def test_star_tracker_that_stops_holds_the_labels(medium):
    # From 700 s (drift declared, label drift) the star tracker sends nothing: every later
    # row is held, no event follows, even though the gyro keeps drifting.
    rows = range(len(medium))
    tele = Telemetry(time=medium.time, gyro=medium.gyro, attitude=medium.attitude.copy(),
                     reference_rate=medium.reference_rate)
    stop = int(np.searchsorted(tele.time, 700.0))
    tele.attitude[stop:] = np.nan
    events, det = _events(tele, rows)
    assert all(e.declared_time < 700.0 for e in events)
    assert det.counters['held'] == len(tele) - stop + 1          # + the first row: no rate yet
    assert det.states['x'] == 1 and det.states['y'] == 0


def test_star_tracker_lost_on_a_healthy_gyro_never_becomes_a_fault():
    tele = simulate_aocs(900.0, seed=12)
    tele.attitude[2000:] = np.nan
    events, det = _events(tele)
    assert events == [] and det.counters['held'] == len(tele) - 2000 + 1
    assert det.counters['invalid_quaternions'] == len(tele) - 2000


def test_bad_quaternions_and_non_increasing_rows_are_counted_and_harmless(medium):
    clean, _ = _events(medium)
    tele = Telemetry(time=medium.time.copy(), gyro=medium.gyro.copy(),
                     attitude=medium.attitude.copy(), reference_rate=medium.reference_rate)
    # Out-of-order and duplicate rows inserted (copies of earlier rows): dropped, counted,
    # and the events are exactly those of the clean record.
    order = []
    for k in range(len(tele)):
        order += [k, k - 1, k - 10] if k in (1000, 2500, 4000) else [k]
    det = VsadcDetector(**pipeline.detector_kwargs(CONFIG))
    got = []
    for k in order:
        got += det.update(tele.time[k], tele.gyro[k], tele.attitude[k],
                          tele.reference_rate[k], k)
    assert got == clean and det.counters['non_increasing_time'] == 6
    # Non-unit, NaN and zero quaternions and a NaN gyro: held rows, no spurious event.
    healthy = simulate_aocs(900.0, seed=13)
    healthy.attitude[500] = [0, 0, 0, 2.0]
    healthy.attitude[600] = [np.nan, 0, 0, 1.0]
    healthy.attitude[700] = [0, 0, 0, 0.0]
    healthy.gyro[800, 1] = np.inf
    events, det = _events(healthy)
    assert events == []
    c = det.counters
    # The NaN gyro_y is rejected on that axis only (per-channel rejection).
    assert c['invalid_quaternions'] == 3 and c['bad_axis_y'] == 1 and c['bad_gyro'] == 0
    assert (c['accepted'] + c['held'] + c['bad_gyro'] + c['non_increasing_time']
            == len(healthy))


def test_star_tracker_at_a_quarter_of_the_gyro_rate(medium):
    # Star tracker at 1 Hz, gyro at 4 Hz: the rows without a quaternion are held, the
    # features pair each quaternion with the gyro sample of the same stamp; max_gap must
    # cover the 1 s star-tracker period. The drift is still found, on x only.
    config = dict(CONFIG, max_gap=1.5, window=50, sigma_window=50, reference_window=100)
    det = VsadcDetector(**pipeline.detector_kwargs(config))
    events = []
    for k in range(len(medium)):
        q = medium.attitude[k] if k % 4 == 0 else None
        events += det.update(medium.time[k], medium.gyro[k], q, medium.reference_rate[k], k)
    assert events and {e.component for e in events} == {'gyro_x'}
    assert events[0].kind == 'drift' and 600.0 < events[0].declared_time < 700.0
    assert det.counters['held'] == len(medium) - det.counters['accepted']


def test_q_sign_flips_change_nothing(medium):
    flipped = Telemetry(time=medium.time, gyro=medium.gyro, attitude=medium.attitude.copy(),
                        reference_rate=medium.reference_rate)
    flipped.attitude[::3] *= -1.0
    assert _events(flipped)[0] == _events(medium)[0]


def test_pipeline_without_reference_columns_uses_the_parameter(medium):
    no_ref = Telemetry(time=medium.time, gyro=medium.gyro, attitude=medium.attitude)
    assert pipeline.applies(no_ref) and not pipeline.applies(Telemetry(time=medium.time))
    # The reference is an inertial hold except during the slew (600-1200 s about z): with
    # ref = 0 the slew itself shows on z as a fault, x still finds the drift.
    events = pipeline.run(no_ref, CONFIG)
    assert any(e.component == 'gyro_x' and e.kind == 'drift' for e in events)
    with pytest.raises(ValueError, match='reference_rate'):
        pipeline.run(no_ref, dict(CONFIG, reference_rate=[0.0]))


def test_detect_command_writes_vsadc_events(tmp_path, medium):
    path = tmp_path / 'gyro.csv'
    write_telemetry(path, medium)
    config = tmp_path / 'p.yaml'
    config.write_text('vsadc_detector:\n  ros__parameters:\n    reference_window: 400\n')
    out = tmp_path / 'events.json'
    # Exit code 1: an anomaly was found (docs/usage.md).
    assert cli_main(['detect', str(path), '--config', str(config), '-o', str(out)]) == 1
    doc = json.loads(out.read_text())
    gyro = [e for e in doc['events'] if e['detector'] == 'vsadc']
    assert gyro and gyro[0]['component'] == 'gyro_x' and gyro[0]['kind'] == 'drift'
    assert 590.0 <= gyro[0]['time'] <= gyro[0]['declared_time']
    assert doc['summary']['pipelines']['vsadc']['components']['counters']['rows'] == len(medium)


def test_two_healthy_hours_give_no_event():
    # Healthy distances at window 200: about 3e-6 rad/s (star-tracker rate noise
    # sqrt(2) 5 arcsec / 50 s = 6.9e-7 and gyro 1e-5 / sqrt(200) = 7.1e-7 per component,
    # plus the nominal estimate's own error, the slew and dropouts); the threshold
    # 1.5e-5 is about 15 of those standard deviations away. Default settings, three axes.
    tele = simulate_aocs(7200.0, seed=31)
    events, det = _events(tele, config=pipeline.DEFAULTS)
    assert events == []
    assert all(ch.ready for ch in det.channels)


def test_huge_finite_rates_are_counted_on_their_axis_never_overflow():
    """A reference or gyro value of 1e308 is no rate: counted per axis, the rest runs on."""
    from rwa_monitor.core.vsadc import VsadcDetector
    det = VsadcDetector(window=20)
    q = [0.0, 0.0, 0.0, 1.0]
    for k in range(6000):
        ref = [1e308, 0.0, 0.0] if k % 3 == 0 else [0.0, 0.0, 0.0]
        gyro = [0.0, -1e308 if k % 5 == 0 else 0.0, 0.0]
        det.update(0.1 * k, gyro, q, ref)
    counters = det.counters
    # Row 0 has no star-tracker rate yet (held): counted there, not on the axes.
    assert counters['bad_axis_x'] == 1999 and counters['bad_axis_y'] == 1199
    assert counters['bad_axis_z'] == 0 and det.channels[2].samples > 5000
