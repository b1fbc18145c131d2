"""Fixed packet layouts from an XTCE definition, decoded a whole array of packets at once.

A container has a fixed layout when every entry of its packets (base containers first,
nested container references in place) has a size known from the definition alone; its
packets then all have one length and each parameter sits at one bit offset. The values the
map asks for are decoded vectorised when they are integers (unsigned or two's complement,
either byte order when byte-aligned, any bit offset up to 57 bits) or IEEE-754 floats
(16, 32, 64 bits, byte-aligned), with no calibrator or a polynomial one. A numpy record
type (one field per byte-aligned value) reads them from an ``(n, length)`` byte array;
bit fields are shifted out of the bytes that hold them. A container with anything else
(MIL-STD-1750A floats, spline or context calibrators, sizes that depend on the data, time
and boolean types among the values asked for) is decoded by space-packet-parser, packet
by packet, whole.

The arithmetic follows space-packet-parser's so the two give the same float64 values
(test/test_ccsds.py checks it on every test file): signed integers other than unsigned
are two's complement, a polynomial is summed term by term in the order of the file, on
the integer raw value raised to the power exactly.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

_SIGNED = ('twosComplement', 'twosCompliment', 'signed')
_IEEE = ('IEEE754', 'IEEE754_1985', 'IEEE-754')
_LITTLE = 'leastSignificantByteFirst'


@dataclass(frozen=True)
class Field:
    """Where a parameter sits in a packet of fixed layout, and how it is encoded."""

    name: str
    offset: int          # bits from the start of the packet
    size: int            # bits
    kind: str            # 'uint', 'int' or 'float'
    little: bool         # least significant byte first
    terms: tuple[tuple[float, int], ...] | None  # polynomial (coefficient, exponent)


@dataclass(frozen=True)
class Layout:
    """A container's packet layout: its length and the fields decoded vectorised.

    ``length`` is the packet length in bytes when the layout is fixed, else None. When
    every wanted parameter can be decoded here, ``fields`` holds them and ``why`` is
    empty; otherwise ``fields`` is empty, ``why`` says what stops it, and the packets go
    to space-packet-parser.
    """

    container: str
    length: int | None
    fields: dict[str, Field]
    why: str = ''


def size_of(parameter: Any) -> int | None:
    """Return the size in bits of a parameter's encoding, None if it depends on the data."""
    from space_packet_parser.xtce import encodings as enc
    encoding = parameter.parameter_type.encoding
    if isinstance(encoding, (enc.IntegerDataEncoding, enc.FloatDataEncoding)):
        return int(encoding.size_in_bits)
    if isinstance(encoding, enc.BinaryDataEncoding):
        return encoding.fixed_size_in_bits
    if isinstance(encoding, enc.StringDataEncoding):
        if encoding.fixed_length and not encoding.leading_length_size \
                and not encoding.termination_character:
            return int(encoding.fixed_length)
    return None


def vector_field(parameter: Any, offset: int) -> Field | str:
    """Return the Field of a wanted parameter at ``offset``, or why it is not vectorised."""
    from space_packet_parser.xtce import calibrators as cal
    from space_packet_parser.xtce import encodings as enc
    from space_packet_parser.xtce import parameter_types as pt
    ptype, encoding = parameter.parameter_type, parameter.parameter_type.encoding
    if type(ptype) not in (pt.IntegerParameterType, pt.FloatParameterType):
        return f'a {type(ptype).__name__}'
    if encoding.context_calibrators:
        return 'context calibrators'
    terms = None
    if encoding.default_calibrator is not None:
        if not isinstance(encoding.default_calibrator, cal.PolynomialCalibrator):
            return f'a {type(encoding.default_calibrator).__name__}'
        terms = tuple((float(c.coefficient), int(c.exponent))
                      for c in encoding.default_calibrator.coefficients)
    size, little = int(encoding.size_in_bits), encoding.byte_order == _LITTLE
    aligned = offset % 8 == 0 and size in (8, 16, 32, 64)
    if isinstance(encoding, enc.FloatDataEncoding):
        if encoding.encoding not in _IEEE or not (aligned and size != 8):
            return f'a {encoding.encoding} float of {size} bits at bit {offset}'
        kind = 'float'
    elif isinstance(encoding, enc.IntegerDataEncoding):
        if encoding.encoding != 'unsigned' and encoding.encoding not in _SIGNED:
            return f'an integer encoding {encoding.encoding!r}'
        if (little and not aligned) or size > (64 if aligned else 57):
            return f'an integer of {size} bits at bit {offset}'
        kind = 'uint' if encoding.encoding == 'unsigned' else 'int'
        if terms and any(e < 0 or e * size > 62 for _, e in terms):
            return 'a polynomial whose powers leave 64-bit integers'
    else:
        return f'a {type(encoding).__name__}'
    return Field(parameter.name, offset, size, kind, little, terms)


def layout(definition: Any, container: str, wanted: set[str]) -> Layout:
    """Return the layout of ``container`` for the ``wanted`` parameters (module docstring)."""
    entries = definition.entries(container)
    found: dict[str, Field | str] = {}
    offset: int | None = 0
    why = definition.refused.get(container, '')
    for parameter in entries:
        if parameter.name in wanted:   # a later entry of the same name wins, as in the reference
            found[parameter.name] = ('its size depends on the data' if offset is None
                                     else vector_field(parameter, offset))
        size = size_of(parameter)
        if size is None and offset is not None:
            why = why or f'{parameter.name} has a size that depends on the data'
            offset = None
        elif offset is not None:
            offset += size
    if offset is not None and offset % 8:
        why = why or f'its packets are {offset} bits, not whole bytes'
    length = None if why or offset is None else offset // 8
    slow = {name: f for name, f in found.items() if isinstance(f, str)}
    if length is None or slow:
        why = why or '; '.join(f'{name} is {f}' for name, f in slow.items())
        return Layout(container, length, {}, why)
    return Layout(container, length, dict(found), '')


def record_dtype(fields: list[Field], length: int) -> np.dtype:
    """Return the numpy record type of the byte-aligned fields of a packet of ``length``."""
    names, formats, offsets = [], [], []
    for f in fields:
        if f.offset % 8 == 0 and f.size in (8, 16, 32, 64):
            code = {'uint': 'u', 'int': 'i', 'float': 'f'}[f.kind]
            order = '<' if f.little else '>'
            names.append(f.name)
            formats.append(f'{order}{code}{f.size // 8}')
            offsets.append(f.offset // 8)
    return np.dtype({'names': names, 'formats': formats, 'offsets': offsets,
                     'itemsize': length})


def decode(block: np.ndarray, fields: list[Field]) -> dict[str, np.ndarray]:
    """Decode ``fields`` from ``block`` (n packets x length bytes, C order) as float64."""
    records = block.view(record_dtype(fields, block.shape[1]))[:, 0]
    out = {}
    for f in fields:
        if f.name in records.dtype.names:
            raw = records[f.name]
        else:
            raw = _bits(block, f)
        out[f.name] = _calibrated(raw, f.terms)
    return out


def _bits(block: np.ndarray, f: Field) -> np.ndarray:
    """Return the integer at bits ``f.offset .. + f.size`` of each row (big-endian)."""
    first, last = f.offset // 8, (f.offset + f.size - 1) // 8
    value = np.zeros(len(block), dtype=np.uint64)
    for k in range(first, last + 1):
        value = (value << np.uint64(8)) | block[:, k].astype(np.uint64)
    shift = 8 * (last + 1) - (f.offset + f.size)
    value = (value >> np.uint64(shift)) & np.uint64((1 << f.size) - 1)
    if f.kind == 'uint':
        return value
    signed = value.astype(np.int64)
    return np.where(signed >= 1 << (f.size - 1), signed - (1 << f.size), signed)


def _calibrated(raw: np.ndarray, terms: tuple[tuple[float, int], ...] | None) -> np.ndarray:
    if terms is None:
        return raw.astype(np.float64)
    integer = raw.dtype.kind in 'iu'
    base = raw.astype(np.int64) if integer else raw.astype(np.float64)
    total = np.zeros(len(raw))
    for coefficient, exponent in terms:
        power = base ** exponent if integer else base ** float(exponent)
        total = total + coefficient * power.astype(np.float64)
    return total
