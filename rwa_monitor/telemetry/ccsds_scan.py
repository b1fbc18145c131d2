"""Walking a file of concatenated CCSDS space packets in bounded memory.

A packet is a 6-byte primary header (CCSDS 133.0-B-2: version 3 bits, type 1, secondary
header flag 1, APID 11, sequence flags 2, sequence count 14, data length 16 = bytes after
the header minus one) and its data field. The file is read in chunks of ``chunk_bytes``
into one buffer that is reused; a compiled loop (:func:`walk_plain`, in C as
``_packetwalk.walk``) follows the length fields and lists the offsets of the packets whose
APID is wanted, counting the others, so memory is the buffer and the wanted packets'
values, whatever the file size. A packet cut by the
end of a chunk is carried into the next one; at the end of the file the bytes of a packet
cut short are counted as a truncated tail and dropped.

Counted and skipped, never decoded: packets of a version other than 0, idle packets
(APID 2047), and packets of APIDs nobody asked for (:class:`Counts`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
import os
from typing import Callable

import numpy as np

HEADER = 6
MAX_PACKET = HEADER + 65536
APIDS = 2048
IDLE_APID = 2047
SEQUENCE_MODULO = 1 << 14
BAD_VERSION = APIDS          # slot of the per-APID counters for packets of version != 0
CHUNK_BYTES = 16 * 1024 * 1024
BATCH = 1 << 18              # wanted packets per compiled call (bounds the offset arrays)


def walk_plain(buf, start, end, wanted, counts, offsets, lengths, words):  # noqa: ANN001
    """Follow packets from ``start`` while whole ones fit before ``end``.

    Every complete packet is counted in ``counts`` (by APID, or in slot BAD_VERSION);
    those whose APID is ``wanted`` have their offset, total length and first 4 header bytes
    (big-endian: flags and APID, sequence flags and count) written into ``offsets``,
    ``lengths`` and ``words`` until they are full. Returns (wanted found, position of the
    first packet not consumed).
    """
    pos = start
    n = 0
    capacity = offsets.shape[0]
    while pos + 6 <= end and n < capacity:
        length = (np.int64(buf[pos + 4]) << 8 | np.int64(buf[pos + 5])) + 7
        if pos + length > end:
            break
        first = np.int64(buf[pos])
        if first >> 5 != 0:
            counts[2048] += 1
        else:
            apid = (first & 7) << 8 | np.int64(buf[pos + 1])
            counts[apid] += 1
            if wanted[apid]:
                offsets[n] = pos
                lengths[n] = length
                words[n] = (first << 24 | np.int64(buf[pos + 1]) << 16
                            | np.int64(buf[pos + 2]) << 8 | np.int64(buf[pos + 3]))
                n += 1
        pos += length
    return n, pos


def gather_plain(buf: np.ndarray, offsets: np.ndarray, length: int, out: np.ndarray) -> None:
    """Copy the ``length`` bytes at each offset into the rows of ``out`` (n, length)."""
    if len(offsets):
        rows = np.lib.stride_tricks.as_strided(buf, (len(buf) - length + 1, length), (1, 1),
                                               writeable=False)
        out[...] = rows[offsets]


def _kernels() -> tuple[Callable[..., tuple[int, int]], Callable[..., None]]:
    """Return (walk, gather): the C module's, else the plain walk compiled by numba."""
    try:
        from rwa_monitor.telemetry import _packetwalk
    except ImportError:          # not built (no C compiler): the same loop, compiled
        from rwa_monitor.core.jit import njit
        return njit(cache=True)(walk_plain), gather_plain
    return _packetwalk.walk, _packetwalk.gather


walk, gather = _kernels()


@dataclass
class Counts:
    """What a walk found besides the wanted packets (the reader's report adds its own)."""

    per_apid: np.ndarray = field(default_factory=lambda: np.zeros(APIDS + 1, np.int64))
    truncated_bytes: int = 0

    @property
    def packets(self) -> int:
        """Return the number of complete packets."""
        return int(self.per_apid.sum())

    @property
    def bad_version(self) -> int:
        """Return the number of packets whose version field is not 0."""
        return int(self.per_apid[BAD_VERSION])


def sequence_counts(words: np.ndarray) -> np.ndarray:
    """Return the 14-bit sequence counts of the header words of :func:`walk_plain`."""
    return words & 0x3FFF


def apids(words: np.ndarray) -> np.ndarray:
    """Return the 11-bit APIDs of the header words of :func:`walk_plain`."""
    return (words >> 16) & 0x7FF


Batch = Callable[[np.ndarray, np.ndarray, np.ndarray, np.ndarray], None]


def scan(path: str | os.PathLike, wanted: np.ndarray, take: Batch,
         chunk_bytes: int = CHUNK_BYTES) -> Counts:
    """Walk the file; call ``take(buf, offsets, lengths, words)`` per batch of wanted packets.

    ``wanted`` is a bool array over the 2048 APIDs. ``buf`` is only valid during the call
    (it is reused). Returns the counters of the whole file.
    """
    counts = Counts()
    size = max(int(chunk_bytes), MAX_PACKET)
    buf = np.empty(size + MAX_PACKET, dtype=np.uint8)
    offsets = np.empty(BATCH, dtype=np.int64)
    lengths = np.empty(BATCH, dtype=np.int64)
    words = np.empty(BATCH, dtype=np.int64)
    table = np.ascontiguousarray(wanted, dtype=np.bool_)
    carry = 0
    with open(path, 'rb', buffering=0) as handle:
        view = memoryview(buf)
        while True:
            read = handle.readinto(view[carry:carry + size]) or 0
            end = carry + read
            pos = 0
            while True:
                n, pos = walk(buf, pos, end, table, counts.per_apid, offsets, lengths, words)
                if n:
                    take(buf, offsets[:n], lengths[:n], words[:n])
                if n < BATCH:
                    break
            carry = end - pos
            if read == 0:
                counts.truncated_bytes = carry
                return counts
            buf[:carry] = buf[pos:end]
