"""CCSDS space packets in, telemetry schema columns out (docs/contracts.md).

``read_packets(FILE.bin, DEF.xml, MAP.yaml)``: the XTCE definition (telemetry/xtce.py)
says where each parameter sits; the map (telemetry/telemetry_map.py) which parameter is
which schema column and what each container's time is. The file is walked in bounded
memory (telemetry/ccsds_scan.py); the packets of each mapped container are decoded a batch
at a time, vectorised when its layout is fixed (telemetry/xtce_layout.py), else by
space-packet-parser packet by packet.

Containers at different rates are joined as the rosbag2 reader joins topics: ``time`` is
the union of every container's stamps, a stream whose rows are not all covered gets a
``present`` mask (telemetry/schema.py), and a column is NaN on rows where its container has
no packet. Within one container packets are put in time order; a packet repeating an
earlier stamp with the same values is dropped and counted, with other values it is an
error (which one holds is unknown).

Counted, reported and skipped (:class:`PacketReport`): packets of APIDs the XTCE does not
define, of containers the map does not use, idle packets, packets of another CCSDS
version, packets whose length does not match their container, and a truncated last
packet. Jumps of a mapped APID's sequence count (any step but +1 modulo 2**14; the same
count again is a repeat, not a gap) are reported as data gaps.
"""

from __future__ import annotations

import os
import warnings

import numpy as np

from rwa_monitor.exceptions import TelemetrySchemaError
from rwa_monitor.telemetry import ccsds_scan as scan
from rwa_monitor.telemetry import telemetry_map, xtce, xtce_layout
from rwa_monitor.telemetry.ccsds_report import PacketReport
from rwa_monitor.telemetry.schema import (ATTITUDE, GYRO, REFERENCE, Telemetry, TIME,
                                          wheel_id_of)


class _Container:
    """One mapped container: its APID, layout, wanted parameters and decoded batches."""

    def __init__(self, definition: xtce.Definition, name: str, apid: int,
                 wanted: list[str]) -> None:
        self.name, self.apid, self.wanted = name, apid, wanted
        self.layout = xtce_layout.layout(definition, name, set(wanted))
        self.root = definition.chain(name)[0].name
        self.spp = definition.spp
        self.batches: list[dict[str, np.ndarray]] = []
        self.mismatch = self.undecodable = 0
        self.first_error = ''
        self.last_count: int | None = None
        self.gaps = self.missing = 0

    def take(self, buf: np.ndarray, offsets: np.ndarray, lengths: np.ndarray,
             words: np.ndarray) -> None:
        """Decode a batch of this container's packets (offsets into ``buf``)."""
        self._sequence(scan.sequence_counts(words))
        if self.layout.fields:
            good = lengths == self.layout.length
            self.mismatch += int(len(good) - good.sum())
            block = np.empty((int(good.sum()), self.layout.length), dtype=np.uint8)
            scan.gather(buf, offsets[good], self.layout.length, block)
            self.batches.append(xtce_layout.decode(block, list(self.layout.fields.values())))
        else:
            self.batches.append(self._reference(buf, offsets, lengths))

    def _reference(self, buf: np.ndarray, offsets: np.ndarray,
                   lengths: np.ndarray) -> dict[str, np.ndarray]:
        """Decode packet by packet with space-packet-parser (containers it alone reads)."""
        rows: list[list[float]] = []
        for offset, length in zip(offsets.tolist(), lengths.tolist()):
            raw = buf[offset:offset + length].tobytes()
            if self.layout.length is not None and length != self.layout.length:
                self.mismatch += 1
                continue
            with warnings.catch_warnings():
                warnings.simplefilter('error', UserWarning)   # bits left over: a mismatch
                try:
                    packet = self.spp.parse_bytes(raw, root_container_name=self.root)
                except UserWarning:
                    self.mismatch += 1
                    continue
                except Exception as err:  # noqa: BLE001 - any packet the reference cannot read
                    self._undecodable(err)
                    continue
            try:
                rows.append([float(packet[name]) for name in self.wanted])
            except (KeyError, TypeError, ValueError) as err:
                self._undecodable(err)
        table = np.array(rows, dtype=np.float64).reshape(len(rows), len(self.wanted))
        return {name: table[:, k] for k, name in enumerate(self.wanted)}

    def _undecodable(self, err: Exception) -> None:
        self.undecodable += 1
        if not self.first_error:
            detail = str(err).splitlines()[0][:200] if str(err) else ''
            self.first_error = f'{type(err).__name__}: {detail}'.rstrip(': ')

    def _sequence(self, counts: np.ndarray) -> None:
        if self.last_count is not None:
            counts = np.concatenate([[self.last_count], counts])
        step = np.diff(counts) % scan.SEQUENCE_MODULO
        jumps = step > 1          # 0: the same packet again (a repeat, not a gap)
        self.gaps += int(jumps.sum())
        self.missing += int(((step[jumps] - 1) % scan.SEQUENCE_MODULO).sum())
        if len(counts):
            self.last_count = int(counts[-1])

    def values(self) -> dict[str, np.ndarray]:
        """Return every wanted parameter over the packets decoded, in file order."""
        return {name: np.concatenate([b[name] for b in self.batches])
                if self.batches else np.empty(0) for name in self.wanted}


def read_packets(path: str | os.PathLike, xtce_path: str | os.PathLike,
                 map_path: str | os.PathLike, chunk_bytes: int = scan.CHUNK_BYTES
                 ) -> tuple[Telemetry, PacketReport]:
    """Read a packet file with its XTCE definition and telemetry map.

    Parameters
    ----------
    path : str or path
        Concatenated CCSDS space packets.
    xtce_path, map_path : str or path
        The XTCE definition and the telemetry map (docs/contracts.md).
    chunk_bytes : int
        Bytes read at a time (memory is this, the wanted values and a batch of offsets).

    Returns
    -------
    (Telemetry, PacketReport)
        The record (multi-rate as the module docstring says) and what was counted.

    Raises
    ------
    TelemetrySchemaError or ConfigError
        One line naming the file that is wrong and what is wrong with it.
    """
    definition = xtce.load(xtce_path)
    tmap = telemetry_map.read_map(map_path)
    columns_of = telemetry_map.check(tmap, definition)
    decoded, report = decode_file(path, definition, tmap, columns_of, chunk_bytes)
    return _join(os.fspath(path), tmap, columns_of, decoded, report), report


def decode_file(path: str | os.PathLike, definition: xtce.Definition,
                tmap: telemetry_map.TelemetryMap, columns_of: dict[str, list[str]],
                chunk_bytes: int = scan.CHUNK_BYTES
                ) -> tuple[dict[str, dict[str, np.ndarray]], PacketReport]:
    """Return container -> parameter -> values (file order) and the report of the walk.

    The parameters are each container's time parameters and mapped ones
    (``columns_of``: :func:`telemetry_map.check`); packets whose length does not match
    their container are left out.
    """
    name = os.fspath(path)
    containers = _containers(definition, tmap, columns_of)
    by_apid = {c.apid: c for c in containers}
    wanted = np.zeros(scan.APIDS, dtype=bool)
    wanted[list(by_apid)] = True

    def take(buf: np.ndarray, offsets: np.ndarray, lengths: np.ndarray,
             words: np.ndarray) -> None:
        found = scan.apids(words)
        if len(by_apid) == 1:
            next(iter(by_apid.values())).take(buf, offsets, lengths, words)
            return
        for apid in np.flatnonzero(np.bincount(found, minlength=scan.APIDS)).tolist():
            pick = found == apid
            by_apid[apid].take(buf, offsets[pick], lengths[pick], words[pick])

    if not os.path.isfile(name):
        raise TelemetrySchemaError(name, 'no such packet file')
    try:
        counts = scan.scan(name, wanted, take, chunk_bytes)
    except OSError as err:
        raise TelemetrySchemaError(name, f'cannot read: {err.strerror or err}') from None
    report = _report(definition, counts, containers)
    return {c.name: c.values() for c in containers}, report


def _containers(definition: xtce.Definition, tmap: telemetry_map.TelemetryMap,
                columns_of: dict[str, list[str]]) -> list[_Container]:
    out: list[_Container] = []
    for name, spec in tmap.time.items():
        root = definition.chain(name)[0].name
        apid_parameter = _apid_parameter(definition, root)
        apid = definition.apid(name, apid_parameter)
        wanted = list(dict.fromkeys([*spec.parameters(),
                                     *(tmap.columns[c] for c in columns_of[name])]))
        clash = next((c for c in out if c.apid == apid), None)
        if clash is not None:
            raise TelemetrySchemaError(definition.path, f'containers {clash.name!r} and '
                                       f'{name!r} both select APID {apid}')
        out.append(_Container(definition, name, apid, wanted))
    return out


def _apid_parameter(definition: xtce.Definition, root: str) -> str:
    """Return the name of the 11-bit field at bit 5 of ``root`` (the CCSDS APID)."""
    offset = 0
    for parameter in definition.entries(root):
        size = xtce_layout.size_of(parameter)
        if offset == xtce.APID_BIT and size == xtce.APID_BITS:
            return parameter.name
        if size is None or offset > xtce.APID_BIT:
            break
        offset += size
    raise TelemetrySchemaError(definition.path, f'container {root!r} has no 11-bit field at '
                               'bit 5: not a CCSDS primary header (no APID)')


def _report(definition: xtce.Definition, counts: scan.Counts,
            containers: list[_Container]) -> PacketReport:
    report = PacketReport(packets=counts.packets, truncated_bytes=counts.truncated_bytes,
                          bad_version=counts.bad_version)
    mapped = {c.apid for c in containers}
    known = set()
    for name in definition.containers:
        try:
            known.add(definition.apid(name, _apid_parameter(
                definition, definition.chain(name)[0].name)))
        except TelemetrySchemaError:
            continue     # an abstract or unmatched container selects no APID
    for apid in np.flatnonzero(counts.per_apid[:scan.APIDS]).tolist():
        n = int(counts.per_apid[apid])
        if apid == scan.IDLE_APID:
            report.idle += n
        elif apid not in mapped:
            (report.unmapped_apids if apid in known else report.unknown_apids)[apid] = n
    for c in containers:
        report.decoded[c.name] = int(counts.per_apid[c.apid]) - c.mismatch - c.undecodable
        if c.mismatch:
            report.length_mismatch[c.name] = c.mismatch
        if c.undecodable:
            report.undecodable[c.name] = f'{c.undecodable} ({c.first_error})'
        if c.gaps:
            report.gaps[c.apid] = {'gaps': c.gaps, 'missing': c.missing}
    return report


def _join(path: str, tmap: telemetry_map.TelemetryMap, columns_of: dict[str, list[str]],
          decoded: dict[str, dict[str, np.ndarray]], report: PacketReport) -> Telemetry:
    """Put each container's packets on the union of the stamps (module docstring)."""
    stamps: dict[str, np.ndarray] = {}
    values: dict[str, dict[str, np.ndarray]] = {}
    for name, spec in tmap.time.items():
        stamps[name], values[name] = _ordered(path, name, _stamps(path, name, spec,
                                                                  decoded[name]),
                                              {c: decoded[name][tmap.columns[c]]
                                               for c in columns_of[name]}, report)
    if not any(len(s) for s in stamps.values()):
        raise TelemetrySchemaError(path, 'no packet of the mapped containers ('
                                   + '; '.join(report.lines() or ['the file is empty']) + ')')
    grid = np.sort(np.concatenate(list(stamps.values())))
    grid = grid[np.concatenate([[True], np.diff(grid) != 0])]   # (np.unique hashes floats)
    columns: dict[str, np.ndarray] = {TIME: grid}
    present: dict[str, np.ndarray] = {}
    for name, table in values.items():
        rows = np.searchsorted(grid, stamps[name])
        for column, column_values in table.items():
            out = np.full(len(grid), np.nan)
            out[rows] = column_values
            columns[column] = out
            mask = present.setdefault(_stream(column), np.zeros(len(grid), dtype=bool))
            mask[rows] = True
    tele = Telemetry.from_columns(columns, source=path)
    tele.present = {stream: mask for stream, mask in present.items() if not mask.all()}
    return tele


def _stamps(path: str, container: str, spec: telemetry_map.TimeSpec,
            values: dict[str, np.ndarray]) -> np.ndarray:
    seconds = values[spec.seconds]
    if spec.subseconds is None:
        return seconds
    sub = values[spec.subseconds]
    exact = (np.all(np.isfinite(seconds)) and np.all(np.isfinite(sub))
             and np.all(seconds == np.floor(seconds)) and np.all(sub == np.floor(sub)))
    if not exact or (len(seconds) and (np.max(np.abs(seconds)) >= 2.0 ** 62 / spec.scale
                                       or np.max(np.abs(sub)) >= 2.0 ** 62)):
        return seconds + sub / spec.scale
    ticks = seconds.astype(np.int64) * spec.scale + sub.astype(np.int64)
    return ticks / spec.scale


def _ordered(path: str, container: str, stamps: np.ndarray, table: dict[str, np.ndarray],
             report: PacketReport) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Return the container's stamps and columns in time order, repeats dropped."""
    bad = np.flatnonzero(~np.isfinite(stamps))
    if bad.size:
        raise TelemetrySchemaError(path, f'{container} packet {int(bad[0])} has no finite '
                                   'time', column=container)
    order = np.argsort(stamps, kind='stable')
    stamps = stamps[order]
    table = {c: v[order] for c, v in table.items()}
    repeat = np.flatnonzero(np.diff(stamps) == 0) + 1
    if repeat.size:
        for column, v in table.items():
            differ = ~((v[repeat] == v[repeat - 1]) | (np.isnan(v[repeat])
                                                       & np.isnan(v[repeat - 1])))
            if differ.any():
                k = int(repeat[np.flatnonzero(differ)[0]])
                raise TelemetrySchemaError(
                    path, f'two {container} packets stamped {float(stamps[k])!r} s with '
                    'different values', column=column)
        keep = np.ones(len(stamps), dtype=bool)
        keep[repeat] = False
        stamps, table = stamps[keep], {c: v[keep] for c, v in table.items()}
        report.duplicates[container] = int(repeat.size)
    return stamps, table


def _stream(column: str) -> str:
    """Return the stream of a schema column (telemetry/schema.py STREAMS)."""
    if column in GYRO:
        return 'gyro'
    if column in ATTITUDE:
        return 'star_tracker'
    if column in REFERENCE:
        return 'reference_rate'
    if wheel_id_of(column) is not None:
        return 'wheels'
    return 'columns'
