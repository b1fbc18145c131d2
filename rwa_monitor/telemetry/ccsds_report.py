"""What a read of a packet file counted: the report of telemetry/ccsds.py.

Every count is by container or by APID; :meth:`PacketReport.lines` gives one line per
thing that was skipped or missing (the command line prints them as warnings, the library
logs them), :meth:`PacketReport.as_dict` the same as plain JSON types.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class PacketReport:
    """What a read of a packet file counted (module docstring); ``lines()`` for people."""

    packets: int = 0
    decoded: dict[str, int] = field(default_factory=dict)          # container -> packets
    unknown_apids: dict[int, int] = field(default_factory=dict)    # not in the XTCE
    unmapped_apids: dict[int, int] = field(default_factory=dict)   # in it, not mapped
    idle: int = 0
    bad_version: int = 0
    length_mismatch: dict[str, int] = field(default_factory=dict)  # container -> packets
    undecodable: dict[str, str] = field(default_factory=dict)      # container -> count, why
    truncated_bytes: int = 0
    gaps: dict[int, dict[str, int]] = field(default_factory=dict)  # apid -> gaps, missing
    duplicates: dict[str, int] = field(default_factory=dict)       # container -> packets

    def lines(self) -> list[str]:
        """Return one line per thing that was skipped or missing (empty if none)."""
        out = []
        if self.unknown_apids:
            out.append(f'{sum(self.unknown_apids.values())} packets of APIDs the XTCE does '
                       f'not define skipped ({_apid_list(self.unknown_apids)})')
        if self.unmapped_apids:
            out.append(f'{sum(self.unmapped_apids.values())} packets of containers the map '
                       f'does not use skipped ({_apid_list(self.unmapped_apids)})')
        if self.bad_version:
            out.append(f'{self.bad_version} packets of a CCSDS version other than 0 skipped')
        for container, n in self.length_mismatch.items():
            out.append(f'{n} {container} packets whose length does not match the container '
                       'skipped')
        for container, why in self.undecodable.items():
            out.append(f'{container} packets the XTCE decoder could not read skipped: {why}')
        if self.truncated_bytes:
            out.append(f'truncated last packet: its {self.truncated_bytes} bytes dropped')
        for apid, gap in self.gaps.items():
            out.append(f'APID {apid}: {gap["gaps"]} data gaps in the sequence count, '
                       f'{gap["missing"]} packets missing')
        for container, n in self.duplicates.items():
            out.append(f'{n} {container} packets repeating an earlier stamp dropped')
        return out

    def as_dict(self) -> dict[str, Any]:
        """Return the report as plain JSON types."""
        return {'packets': self.packets, 'decoded': dict(self.decoded),
                'unknown_apids': {str(k): v for k, v in self.unknown_apids.items()},
                'unmapped_apids': {str(k): v for k, v in self.unmapped_apids.items()},
                'idle': self.idle, 'bad_version': self.bad_version,
                'length_mismatch': dict(self.length_mismatch),
                'undecodable': dict(self.undecodable),
                'truncated_bytes': self.truncated_bytes,
                'gaps': {str(k): dict(v) for k, v in self.gaps.items()},
                'duplicates': dict(self.duplicates)}


def _apid_list(counts: dict[int, int], shown: int = 8) -> str:
    items = sorted(counts.items(), key=lambda kv: -kv[1])
    text = ', '.join(f'APID {a}: {n}' for a, n in items[:shown])
    return text + (f', {len(items) - shown} more APIDs' if len(items) > shown else '')
