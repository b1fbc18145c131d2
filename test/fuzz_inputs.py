"""Inputs for the property tests of issue 24, item 7: valid files and their mutations.

``seeds()`` writes one small valid file of every kind the package reads (CSV, MCAP,
rosbag2 folder, parameters YAML, calibration, friction model, journal);
``mutated(data)`` is a hypothesis strategy of damaged copies (bytes replaced, deleted,
duplicated, inserted; the file cut short), ``garbage`` one of arbitrary bytes.
"""

import json
import os
import pathlib

from hypothesis import HealthCheck, settings, strategies as st
import numpy as np

from rwa_monitor.telemetry import Telemetry, Wheel, write_telemetry

REPO = pathlib.Path(__file__).resolve().parents[1]
# A handful of examples per reader or command: each example reads or runs a real file.
# FUZZ_N / FUZZ_CLI_N raise the counts for a longer search (not needed by the suite).
READER_SETTINGS = settings(max_examples=int(os.environ.get('FUZZ_N', 30)), deadline=None,
                           derandomize=True,
                           suppress_health_check=[HealthCheck.too_slow,
                                                  HealthCheck.data_too_large])
CLI_SETTINGS = settings(READER_SETTINGS, max_examples=int(os.environ.get('FUZZ_CLI_N', 6)))

garbage = st.binary(max_size=3000)


@st.composite
def mutated(draw, data: bytes) -> bytes:
    """Return ``data`` damaged by one to three edits (a strategy)."""
    out = bytearray(data)
    for _ in range(draw(st.integers(1, 3))):
        at = draw(st.integers(0, len(out)))
        size = draw(st.integers(0, 64))
        edit = draw(st.sampled_from(('replace', 'delete', 'duplicate', 'insert', 'cut')))
        if edit == 'replace':
            out[at:at + size] = draw(st.binary(min_size=size, max_size=size))
        elif edit == 'delete':
            del out[at:at + size]
        elif edit == 'duplicate':
            out[at:at] = out[at:at + size]
        elif edit == 'insert':
            out[at:at] = draw(st.sampled_from((b'\x00', b'\xff\xfe', b'nan', b'1e999', b',',
                                               b'\n', b'"', b'&a [*a]', b'*x', b'- ',
                                               b': ', b'{', b'[', b'\r\n', b'\t')))
        else:
            del out[at:]
    return bytes(out)


def small_telemetry(n: int = 400) -> Telemetry:
    """Return a small two-wheel record with gyro, attitude and an auxiliary column."""
    rng = np.random.default_rng(0)
    t = np.arange(n) * 0.1
    speed = 20 * np.sin(t / 10.0)
    tele = Telemetry(time=t, wheels={
        w: Wheel(speed, -2e-4 * np.sign(speed) - 1e-6 * speed + 5e-5 * rng.standard_normal(n))
        for w in ('rw1', 'rw2')})
    tele.gyro = 1e-5 * rng.standard_normal((n, 3))
    tele.attitude = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    tele.aux['rw1_temperature'] = 20 + 0.01 * t
    return tele


def seeds(folder: pathlib.Path) -> dict[str, bytes]:
    """Return kind -> bytes of a valid file of each kind (written under ``folder``)."""
    tele = small_telemetry()
    write_telemetry(folder / 'seed.csv', tele)
    wheels_only = small_telemetry()
    wheels_only.gyro = wheels_only.attitude = None
    write_telemetry(folder / 'wheels.csv', wheels_only)
    write_telemetry(folder / 'seed.mcap', tele)
    write_telemetry(folder / 'seed_bag', tele)
    journal = ''.join(json.dumps(r) + '\n' for r in (
        {'record': 'event', 'key': 'llr/rw1/3', 'wall_time_s': 1.0,
         'event': {'detector': 'llr', 'component': 'rw1', 'kind': 'dry', 'change_time_s': 1.0,
                   'change_index': 3, 'declaration_time_s': 2.0, 'declaration_index': 9,
                   'p_value': 1e-7, 'revision': 0}},
        {'record': 'acknowledged', 'key': 'llr/rw1/3', 'wall_time_s': 2.0}))
    bag = folder / 'seed_bag'
    return {
        'csv': (folder / 'seed.csv').read_bytes(),
        'wheels_csv': (folder / 'wheels.csv').read_bytes(),
        'mcap': (folder / 'seed.mcap').read_bytes(),
        'metadata': (bag / 'metadata.yaml').read_bytes(),
        'bag_mcap': next(bag.glob('*.mcap')).read_bytes(),
        'parameters': (REPO / 'config' / 'rwa_monitor.yaml').read_bytes(),
        'calibration': (REPO / 'bench' / 'results' / 'calibration' /
                        'calibration.yaml').read_bytes(),
        'friction_model': (REPO / 'bench' / 'results' / 'identify_example_drag' /
                           'friction_model.yaml').read_bytes(),
        'journal': journal.encode(),
        'fss_model': (REPO / 'rwa_monitor' / 'data' / 'fss_model.json').read_bytes(),
    }
