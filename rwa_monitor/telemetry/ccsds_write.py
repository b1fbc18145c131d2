"""Writing telemetry as CCSDS space packets, with the XTCE and the map that read them back.

``write_packets(FILE.bin, tele)`` writes FILE.bin, FILE.xml (XTCE, built with
space-packet-parser's own XTCE objects) and FILE_map.yaml (docs/contracts.md). One
container per stream of the record, each selected by its APID (:data:`APIDS`):

- primary header as plain integer fields (version 0, type 0 telemetry, secondary header
  flag 1, APID, sequence flags 3 = unsegmented, a sequence count per APID, length);
- a CUC-style secondary header: ``TIME_COARSE`` (32-bit unsigned seconds) and
  ``TIME_FINE`` (32-bit unsigned fraction); the fine field counts nanoseconds
  (``subsecond_scale: 1000000000``) rather than a binary fraction, so a stamp reads back
  as exactly the float of the CSV or ROS stamp it came from (a 2**-16 s fraction cannot
  hold 0.1 s);
- one big-endian IEEE-754 float64 parameter per column, named as the column.

A stream's packets are written only on the rows where it has a sample
(``Telemetry.present``), in time order across containers. Times must lie in
[0, 2**32) s. The three files are each written atomically, the packets last.
"""

from __future__ import annotations

import os
import pathlib

import numpy as np

from rwa_monitor.telemetry.atomic import atomic_write, write_text_atomic
from rwa_monitor.telemetry.schema import ATTITUDE, GYRO, REFERENCE, Telemetry, TRUTH_PREFIX

# Stream -> (container name, APID).
APIDS = {'wheels': ('WheelPacket', 0x100), 'gyro': ('GyroPacket', 0x101),
         'star_tracker': ('StarTrackerPacket', 0x102),
         'reference_rate': ('ReferenceRatePacket', 0x103), 'columns': ('ColumnsPacket', 0x104)}
HEADER_FIELDS = (('CCSDS_VERSION', 3), ('CCSDS_TYPE', 1), ('CCSDS_SEC_HDR_FLAG', 1),
                 ('CCSDS_APID', 11), ('CCSDS_SEQ_FLAGS', 2), ('CCSDS_SEQ_COUNT', 14),
                 ('CCSDS_LENGTH', 16))
COARSE, FINE = 'TIME_COARSE', 'TIME_FINE'
FINE_SCALE = 1_000_000_000
# XTCE 1.2's namespace (the target namespace of its schema, SpaceSystem.xsd).
XTCE_NAMESPACES = {'xtce': 'http://www.omg.org/spec/XTCE/20180204',
                   'xsi': 'http://www.w3.org/2001/XMLSchema-instance'}
XTCE_DATE = '2026-01-01T00:00:00'  # the version of this layout, not the time of writing
_UNITS = {'speed': 'rad/s', 'friction': 'N m', 'gyro': 'rad/s', 'ref': 'rad/s'}


def sibling_paths(path: str | os.PathLike) -> tuple[pathlib.Path, pathlib.Path]:
    """Return the XTCE and map paths written beside a packet file (FILE.xml, FILE_map.yaml)."""
    target = pathlib.Path(path)
    return target.with_suffix('.xml'), target.with_name(target.stem + '_map.yaml')


def stream_columns(tele: Telemetry) -> dict[str, list[str]]:
    """Return stream -> its columns, for the streams the record has."""
    names = [c for c in tele.columns() if c != 'time']
    out: dict[str, list[str]] = {}
    for column in names:
        if column in GYRO:
            stream = 'gyro'
        elif column in ATTITUDE:
            stream = 'star_tracker'
        elif column in REFERENCE:
            stream = 'reference_rate'
        elif column.startswith(TRUTH_PREFIX) or column in tele.aux:
            stream = 'columns'
        else:
            stream = 'wheels'
        out.setdefault(stream, []).append(column)
    return out


def write_packets(path: str | os.PathLike, tele: Telemetry,
                  xtce_path: str | os.PathLike | None = None,
                  map_path: str | os.PathLike | None = None) -> None:
    """Write ``tele`` as packets with its XTCE and map (module docstring).

    ``xtce_path`` / ``map_path`` None: :func:`sibling_paths`. ValueError if a time cannot
    be written.
    """
    xml, yml = sibling_paths(path)
    streams = stream_columns(tele)
    for name in (c for cols in streams.values() for c in cols):
        if name in dict(HEADER_FIELDS) or name in (COARSE, FINE):
            raise ValueError(f'column {name!r} has the name of a header field')
    data = packet_bytes(tele, streams)
    write_text_atomic(pathlib.Path(xtce_path or xml), xtce_text(tele, streams))
    write_text_atomic(pathlib.Path(map_path or yml), map_text(streams))
    with atomic_write(path, 'wb', encoding=None) as handle:
        handle.write(data)


def map_text(streams: dict[str, list[str]]) -> str:
    """Return the telemetry map of the containers written for ``streams``."""
    lines = ['# Written by rwa-monitor with the packets (docs/contracts.md).',
             '# time: container -> the time of its packets (s); columns: schema column ->',
             '# XTCE parameter.', 'time:']
    for stream in streams:
        lines.append(f'  {APIDS[stream][0]}: {{seconds: {COARSE}, subseconds: {FINE}, '
                     f'subsecond_scale: {FINE_SCALE}}}')
    lines.append('columns:')
    lines += [f"  '{c}': '{c}'" for cols in streams.values() for c in cols]
    return '\n'.join(lines) + '\n'


def xtce_text(tele: Telemetry, streams: dict[str, list[str]]) -> str:
    """Return the XTCE document of the containers written for ``streams``."""
    from lxml import etree
    from space_packet_parser import XtcePacketDefinition
    from space_packet_parser.xtce import comparisons, containers, encodings
    from space_packet_parser.xtce import parameter_types as pt
    from space_packet_parser.xtce.parameters import Parameter

    def uint(name: str, bits: int) -> Parameter:
        return Parameter(name, pt.IntegerParameterType(
            name, encodings.IntegerDataEncoding(bits, encoding='unsigned')))

    header = [uint(n, b) for n, b in HEADER_FIELDS]
    root = containers.SequenceContainer('CCSDSPacket', header, abstract=True)
    time = [uint(COARSE, 32), uint(FINE, 32)]
    made = [root]
    for stream, columns in streams.items():
        name, apid = APIDS[stream]
        values = [Parameter(c, pt.FloatParameterType(
            c, encodings.FloatDataEncoding(64, encoding='IEEE754'), unit=_unit(c)))
            for c in columns]
        made.append(containers.SequenceContainer(
            name, [*time, *values], base_container_name=root.name,
            restriction_criteria=[comparisons.Comparison(str(apid), 'CCSDS_APID', '==')]))
        root.inheritors.append(name)
    definition = XtcePacketDefinition(made, ns=XTCE_NAMESPACES, xtce_ns_prefix='xtce',
                                      space_system_name='rwa_monitor', date=XTCE_DATE)
    return etree.tostring(definition.to_xml_tree(), pretty_print=True, xml_declaration=True,
                          encoding='utf-8').decode('utf-8')


def _unit(column: str) -> str | None:
    for key, unit in _UNITS.items():
        if column.endswith('_' + key) or column.startswith(key + '_'):
            return unit
    return None


def packet_bytes(tele: Telemetry, streams: dict[str, list[str]]) -> bytes:
    """Return the packets of every stream, in time order (module docstring)."""
    ticks = np.round(np.asarray(tele.time, dtype=np.float64) * FINE_SCALE)
    if len(ticks) and (ticks.min() < 0 or ticks.max() >= 2.0 ** 32 * FINE_SCALE):
        raise ValueError('packet times must lie in [0, 2**32) s (CUC seconds)')
    ticks = ticks.astype(np.int64)
    columns = tele.columns()
    parts, stamps, order = [], [], []
    for k, (stream, names) in enumerate(streams.items()):
        rows = tele.rows(stream)
        records = _records(APIDS[stream][1], ticks[rows],
                           [np.asarray(columns[c], dtype=np.float64)[rows] for c in names])
        parts.append(records.view(np.uint8).reshape(len(rows), records.dtype.itemsize))
        stamps.append(ticks[rows])
        order.append(np.full(len(rows), k))
    if not parts:
        return b''
    sequence = np.lexsort((np.concatenate(order), np.concatenate(stamps)))
    sizes = np.concatenate([np.full(len(p), p.shape[1], dtype=np.int64) for p in parts])
    starts = np.empty(len(sizes), dtype=np.int64)
    starts[sequence] = np.concatenate([[0], np.cumsum(sizes[sequence])[:-1]])
    out = np.zeros(int(sizes.sum()), dtype=np.uint8)
    first = 0
    for part in parts:    # each row to its start: a strided view over ``out``, written through
        width = part.shape[1]
        rows = np.lib.stride_tricks.as_strided(out, (len(out) - width + 1, width), (1, 1))
        rows[starts[first:first + len(part)]] = part
        first += len(part)
    return out.tobytes()


def _records(apid: int, ticks: np.ndarray, values: list[np.ndarray]) -> np.ndarray:
    names = ['id', 'sequence', 'length', 'coarse', 'fine'] + [f'v{i}' for i in range(
        len(values))]
    formats = ['>u2', '>u2', '>u2', '>u4', '>u4'] + ['>f8'] * len(values)
    offsets = [0, 2, 4, 6, 10] + [14 + 8 * i for i in range(len(values))]
    size = 14 + 8 * len(values)
    if size - 7 > 0xFFFF:
        raise ValueError(f'{len(values)} columns do not fit in one packet')
    records = np.zeros(len(ticks), dtype=np.dtype({'names': names, 'formats': formats,
                                                   'offsets': offsets, 'itemsize': size}))
    records['id'] = 0x0800 | apid           # version 0, telemetry, secondary header
    records['sequence'] = 0xC000 | (np.arange(len(ticks)) % (1 << 14))
    records['length'] = size - 7
    records['coarse'] = ticks // FINE_SCALE
    records['fine'] = ticks % FINE_SCALE
    for i, v in enumerate(values):
        records[f'v{i}'] = v
    return records
