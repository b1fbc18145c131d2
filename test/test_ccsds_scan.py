"""The C packet walk and gather (telemetry/_packetwalk.c) equal the plain Python ones."""

from hypothesis import given, settings, strategies as st
import numpy as np
import pytest

from rwa_monitor.telemetry import ccsds_scan

_packetwalk = pytest.importorskip('rwa_monitor.telemetry._packetwalk')


def _run(walk, data, start, wanted_apids, capacity):
    buf = np.frombuffer(data, dtype=np.uint8)
    wanted = np.zeros(ccsds_scan.APIDS, dtype=bool)
    wanted[list(wanted_apids)] = True
    counts = np.zeros(ccsds_scan.APIDS + 1, dtype=np.int64)
    offsets = np.full(capacity, -1, dtype=np.int64)
    lengths = np.full(capacity, -1, dtype=np.int64)
    words = np.full(capacity, -1, dtype=np.int64)
    n, pos = walk(buf, start, len(buf), wanted, counts, offsets, lengths, words)
    return (n, pos, counts.tolist(), offsets[:n].tolist(), lengths[:n].tolist(),
            words[:n].tolist())


def _packets(draw_lengths, apids):
    out = b''
    for length, apid in zip(draw_lengths, apids):
        out += bytes([(apid >> 8) & 0xFF, apid & 0xFF, 0xC0, 0, length >> 8, length & 0xFF])
        out += bytes(length + 1)
    return out


@settings(max_examples=200, deadline=None)
@given(noise=st.binary(max_size=300), lengths=st.lists(st.integers(0, 40), max_size=30),
       apids=st.lists(st.integers(0, 0x3FFF), min_size=30, max_size=30),
       wanted=st.sets(st.integers(0, 2047), max_size=5), capacity=st.integers(1, 12),
       start=st.integers(0, 8))
def test_the_c_walk_equals_the_plain_one(noise, lengths, apids, wanted, capacity, start):
    data = _packets(lengths, apids) + noise     # other versions (bits above the APID) too
    wanted = set(wanted) | {a & 0x7FF for a in apids[:2]}
    start = min(start, len(data))
    assert _run(_packetwalk.walk, data, start, wanted, capacity) == \
        _run(ccsds_scan.walk_plain, data, start, wanted, capacity)


@given(data=st.binary(min_size=1, max_size=200), length=st.integers(1, 20),
       picks=st.lists(st.integers(0, 10 ** 6), max_size=20))
def test_the_c_gather_equals_the_plain_one(data, length, picks):
    buf = np.frombuffer(data, dtype=np.uint8)
    if len(buf) < length:
        return
    offsets = np.array([p % (len(buf) - length + 1) for p in picks], dtype=np.int64)
    fast = np.empty((len(offsets), length), dtype=np.uint8)
    plain = np.empty_like(fast)
    _packetwalk.gather(buf, offsets, length, fast)
    ccsds_scan.gather_plain(buf, offsets, length, plain)
    np.testing.assert_array_equal(fast, plain)


def test_bad_arguments_are_errors_not_crashes():
    buf = np.zeros(16, dtype=np.uint8)
    counts = np.zeros(ccsds_scan.APIDS + 1, dtype=np.int64)
    with pytest.raises(ValueError, match='bad bounds'):
        _packetwalk.walk(buf, 0, 99, np.zeros(ccsds_scan.APIDS, bool), counts,
                         np.zeros(4, np.int64), np.zeros(4, np.int64), np.zeros(4, np.int64))
    with pytest.raises(TypeError, match='items of 8 bytes'):
        _packetwalk.walk(buf, 0, 16, np.zeros(ccsds_scan.APIDS, bool), counts,
                         np.zeros(4, np.int32), np.zeros(4, np.int64), np.zeros(4, np.int64))
    with pytest.raises(ValueError, match='out of bounds'):
        _packetwalk.gather(buf, np.array([10], np.int64), 8, np.zeros((1, 8), np.uint8))


def test_without_the_c_module_numba_walks_the_same_file(tmp_path):
    import subprocess
    import sys

    from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel, write_telemetry
    n = 3000
    write_telemetry(tmp_path / 'r.bin', Telemetry(time=np.arange(n) * 0.1, wheels={
        'rw1': Wheel(np.sin(np.arange(n)), np.cos(np.arange(n)))}))
    expected = read_telemetry(tmp_path / 'r.bin').wheels['rw1'].friction
    script = '\n'.join([
        'import sys, numpy as np',
        "sys.modules['rwa_monitor.telemetry._packetwalk'] = None  # as if never built",
        'from rwa_monitor.telemetry import ccsds_scan, read_telemetry',
        "assert ccsds_scan.walk is not ccsds_scan.walk_plain and 'numba' in sys.modules",
        f"np.save(sys.argv[1], read_telemetry({str(tmp_path / 'r.bin')!r})"
        ".wheels['rw1'].friction)"])
    subprocess.run([sys.executable, '-c', script, str(tmp_path / 'f.npy')], check=True,
                   timeout=300)
    np.testing.assert_array_equal(np.load(tmp_path / 'f.npy'), expected)
