"""Packet files for the packet tests: an XTCE written with yamcs-pymdb, packets bit by bit.

The definition (:func:`pymdb_xtce`) is the kind a ground segment writes: a primary header
as plain integer fields (yamcs-pymdb's ``add_ccsds_header`` writes an aggregate type that
space-packet-parser 6.2 refuses), a CUC time (32-bit seconds, 16-bit binary fraction),
bit fields off byte boundaries, two's complement and little-endian integers, polynomial
calibrators, a spline calibrator and a leading-size string (which leave their containers
to space-packet-parser), containers at different rates and one the map does not use.
:func:`packet` packs any fields with Python integers, independently of the reader.
"""

from __future__ import annotations

import io
import pathlib
import struct

import numpy as np

WHEEL, GYRO, STAR, HOUSEKEEPING, REFERENCE = 100, 101, 102, 103, 104
HEADER = [('CCSDS_VERSION', 3), ('CCSDS_TYPE', 1), ('CCSDS_SEC_HDR_FLAG', 1),
          ('CCSDS_APID', 11), ('CCSDS_SEQ_FLAGS', 2), ('CCSDS_SEQ_COUNT', 14),
          ('CCSDS_LENGTH', 16)]

MAP = '''\
time:
  WheelPacket: {seconds: SEC, subseconds: SUBSEC, subsecond_scale: 65536}
  GyroPacket: GYR_TIME
  StarPacket: {seconds: SEC, subseconds: SUBSEC, subsecond_scale: 65536}
  RefPacket: {seconds: SEC, subseconds: SUBSEC, subsecond_scale: 65536}
columns:
  rw1_speed: RW1_SPD
  rw1_friction: RW1_TRQ
  rw2_speed: RW2_SPD
  rw2_friction: RW2_TRQ
  rw1_temperature: TEMP
  gyro_x: GYR_X
  gyro_y: GYR_Y
  gyro_z: GYR_Z
  q_x: Q_X
  q_y: Q_Y
  q_z: Q_Z
  q_w: Q_W
  ref_x: REF_X
  ref_y: REF_Y
  ref_z: REF_Z
epoch_utc: 2026-01-01T00:00:00Z
'''


def pymdb_xtce(path: pathlib.Path) -> pathlib.Path:
    """Write the test definition with yamcs-pymdb; return its path."""
    import yamcs.pymdb as y
    system = y.System('RWA')
    header = [y.IntegerParameter(system, name, signed=False,
                                 encoding=y.IntegerEncoding(bits=bits))
              for name, bits in HEADER]
    apid = header[3]
    root = y.Container(system, 'CCSDSPacket', abstract=True,
                       entries=[y.ParameterEntry(p) for p in header])
    sec = y.IntegerParameter(system, 'SEC', signed=False, encoding=y.uint32_t)
    sub = y.IntegerParameter(system, 'SUBSEC', signed=False, encoding=y.uint16_t)
    twos = y.IntegerEncodingScheme.TWOS_COMPLEMENT

    def container(name, number, entries):
        return y.Container(system, name, base=root, condition=y.eq(apid, number),
                           entries=[y.ParameterEntry(p) for p in entries])

    container('WheelPacket', WHEEL, [
        sec, sub,
        y.FloatParameter(system, 'RW1_SPD', bits=64, encoding=y.FloatEncoding(bits=64),
                         units='rad/s'),
        y.FloatParameter(system, 'RW1_TRQ', bits=32, encoding=y.FloatEncoding(bits=32)),
        y.IntegerParameter(system, 'STATUS', signed=False, encoding=y.IntegerEncoding(bits=3)),
        y.IntegerParameter(system, 'TEMP', signed=True,
                           encoding=y.IntegerEncoding(bits=13, scheme=twos),
                           calibrator=y.Polynomial([20.0, 0.01, 1e-6])),
        y.IntegerParameter(system, 'RW2_SPD', signed=True,
                           encoding=y.IntegerEncoding(bits=16, scheme=twos),
                           calibrator=y.Polynomial([0.0, 0.05])),
        y.IntegerParameter(system, 'RW2_TRQ', signed=True,
                           encoding=y.IntegerEncoding(bits=32, little_endian=True,
                                                      scheme=twos),
                           calibrator=y.Polynomial([1e-6, 1e-7]))])
    container('GyroPacket', GYRO, [
        y.FloatParameter(system, 'GYR_TIME', bits=64, encoding=y.FloatEncoding(bits=64)),
        *(y.FloatParameter(system, f'GYR_{a}', bits=32, encoding=y.FloatEncoding(bits=32))
          for a in 'XYZ')])
    container('StarPacket', STAR, [sec, sub, *(
        y.FloatParameter(system, f'Q_{a}', bits=64, encoding=y.FloatEncoding(bits=64))
        for a in 'XYZW')])
    container('HkPacket', HOUSEKEEPING, [
        y.IntegerParameter(system, 'HK_MODE', signed=False, encoding=y.uint16_t)])
    container('RefPacket', REFERENCE, [
        sec, sub,
        y.IntegerParameter(system, 'NAME_BITS', signed=False, encoding=y.uint8_t),
        y.StringParameter(system, 'MODE_NAME', encoding=y.StringEncoding(length_bits=8,
                                                                         termination=None)),
        y.FloatParameter(system, 'REF_X', bits=64, encoding=y.FloatEncoding(bits=64),
                         calibrator=y.Interpolate([-10.0, 10.0], [-20.0, 20.0])),
        *(y.FloatParameter(system, f'REF_{a}', bits=64, encoding=y.FloatEncoding(bits=64))
          for a in 'YZ')])
    text = io.StringIO()
    system.dump(text)
    # yamcs-pymdb's leading-size string names a Yamcs-only size reference that
    # space-packet-parser cannot follow: here the size comes from NAME_BITS instead.
    path.write_text(text.getvalue().replace('_yamcs_ignore', 'NAME_BITS').replace(
        '<LeadingSize sizeInBitsOfSizeTag="8"/>', ''))
    return path


def packet(apid: int, count: int, fields: list[tuple[int, int]], tail: bytes = b'') -> bytes:
    """Return one packet: primary header, ``fields`` as (raw value, bits), ``tail`` bytes.

    The length field counts the fields and the tail.
    """
    value, bits = 0, 0
    for raw, size in fields:
        value = value << size | (raw & ((1 << size) - 1))
        bits += size
    assert bits % 8 == 0, bits
    data = (value.to_bytes(bits // 8, 'big') if bits else b'') + tail
    head = struct.pack('>HHH', 0x0800 | apid, 0xC000 | (count % 16384), len(data) - 1)
    return head + data


def f64(x: float) -> tuple[int, int]:
    """Return a float64 as a (raw, bits) field."""
    return int.from_bytes(struct.pack('>d', x), 'big'), 64


def f32(x: float) -> tuple[int, int]:
    """Return a float32 as a (raw, bits) field."""
    return int.from_bytes(struct.pack('>f', x), 'big'), 32


def cuc(t: float) -> list[tuple[int, int]]:
    """Return a CUC time (32-bit seconds, 16-bit fraction) as fields."""
    ticks = int(round(t * 65536))
    return [(ticks >> 16, 32), (ticks & 0xFFFF, 16)]


def le32(raw: int) -> tuple[int, int]:
    """Return a 32-bit little-endian integer as a (raw, bits) field."""
    return int.from_bytes((raw & 0xFFFFFFFF).to_bytes(4, 'little'), 'big'), 32


def mixed_file(path: pathlib.Path, seconds: float = 20.0, seed: int = 7) -> dict:
    """Write packets of every container at its own rate; return what went in.

    Wheels at 10 Hz, gyro at 5 Hz (stamps 0.05 s after the wheels'), star tracker at
    1 Hz, reference at 2 Hz (spline-calibrated, after a string), housekeeping at 1 Hz.
    """
    rng = np.random.default_rng(seed)
    items = []
    counts = {a: 0 for a in (WHEEL, GYRO, STAR, HOUSEKEEPING, REFERENCE)}

    def add(t, apid, fields, tail=b''):
        items.append((t, len(items), packet(apid, counts[apid], fields, tail)))
        counts[apid] += 1

    for k in range(int(seconds * 10)):
        t = k / 10
        add(t, WHEEL, [*cuc(t), f64(rng.normal(100, 5)), f32(rng.normal(0, 1e-3)),
                       (k % 8, 3), (int(rng.integers(-4096, 4096)), 13),
                       (int(rng.integers(-32768, 32768)), 16),
                       le32(int(rng.integers(-2**31, 2**31)))])
        if k % 2 == 0:
            add(t + 0.05, GYRO, [f64(t + 0.05), *(f32(v) for v in rng.normal(0, 1e-3, 3))])
        if k % 10 == 0:
            q = rng.normal(size=4)
            add(t, STAR, [*cuc(t), *(f64(v) for v in q / np.linalg.norm(q))])
            add(t, HOUSEKEEPING, [(k, 16)])
        if k % 5 == 0:
            name = b'SLEW' if k % 10 else b'POINT'
            ref = rng.normal(0, 0.5, 3)
            add(t, REFERENCE, [*cuc(t), (8 * len(name), 8)],
                name + b''.join(struct.pack('>d', v) for v in ref))
    items.sort()
    path.write_bytes(b''.join(p for _, _, p in items))
    return dict(counts)
