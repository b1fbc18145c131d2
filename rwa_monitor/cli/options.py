"""Command-line options shared by the commands that read or write telemetry."""

from __future__ import annotations

import argparse
import os
import pathlib
import sys

from rwa_monitor.telemetry import read_with_notes, Telemetry, write_telemetry
from rwa_monitor.telemetry.topics import DEFAULT_TOPICS

INPUT_HELP = ('telemetry: CSV or Parquet file, rosbag2 folder (metadata.yaml with .mcap or '
              '.db3), a bare .mcap or .db3 file, or CCSDS space packets (.bin, with --xtce '
              'and --telemetry-map)')
OUTPUT_HELP = ('output: a folder name without suffix writes a rosbag2 recording (MCAP '
               'storage), .mcap or .db3 a bare recording file, .bin CCSDS space packets '
               '(with FILE.xml and FILE_map.yaml), .csv a CSV file')
FORMATS = ('auto', 'ccsds')


def add_topics(parser: argparse.ArgumentParser) -> None:
    """Add the options naming a recording's topics and a packet file's definitions.

    ``--topics STREAM=TOPIC,...`` (recordings), ``--xtce`` and ``--telemetry-map`` (packet
    files): :func:`read_input` reads the input with them.
    """
    defaults = ','.join(f'{s}={t}' for s, t in DEFAULT_TOPICS.items())
    parser.add_argument('--topics', default='', metavar='STREAM=TOPIC,...',
                        help='topic names of the streams of a recording (streams not named keep '
                             f'their default; default {defaults})')
    add_packets(parser)


def add_packets(parser: argparse.ArgumentParser) -> None:
    """Add ``--xtce DEF.xml`` and ``--telemetry-map MAP.yaml`` (files of space packets)."""
    parser.add_argument('--xtce', type=pathlib.Path, metavar='DEF.xml',
                        help='XTCE definition of a file of CCSDS space packets (default for '
                             'FILE.bin: FILE.xml, else telemetry.xml beside it)')
    parser.add_argument('--telemetry-map', type=pathlib.Path, metavar='MAP.yaml',
                        help='map from XTCE parameters to telemetry columns (docs/contracts.md; '
                             'default for FILE.bin: FILE_map.yaml, else telemetry_map.yaml '
                             'beside it)')


def read_input(path: str | os.PathLike, args: argparse.Namespace) -> Telemetry:
    """Read a command's input with its ``--topics``, ``--xtce`` and ``--telemetry-map``.

    What a packet reader counted and skipped is printed as warnings on standard error.
    """
    tele, notes = read_with_notes(path, getattr(args, 'topics', None) or None,
                                  xtce=getattr(args, 'xtce', None),
                                  telemetry_map=getattr(args, 'telemetry_map', None))
    for note in notes:
        print(f'rwa-monitor {getattr(args, "command", "")}: warning: {note}', file=sys.stderr)
    return tele


def add_format(parser: argparse.ArgumentParser) -> None:
    """Add ``--format {auto,ccsds}`` to a command that writes telemetry with ``-o``."""
    parser.add_argument('--format', choices=FORMATS, default='auto',
                        help='auto: by the suffix of -o (default); ccsds: CCSDS space packets, '
                             'FILE.bin with its XTCE FILE.xml and map FILE_map.yaml')


def output_path(args: argparse.Namespace) -> str:
    """Return where ``-o`` writes under ``--format`` (ccsds: the suffix becomes .bin)."""
    if getattr(args, 'format', 'auto') == 'ccsds':
        return os.fspath(pathlib.Path(args.output).with_suffix('.bin'))
    return os.fspath(args.output)


def write_output_telemetry(args: argparse.Namespace, tele: Telemetry) -> str:
    """Write a simulator's record to ``-o`` in ``--format``; return what was written."""
    path = output_path(args)
    write_telemetry(path, tele, getattr(args, 'topics', None) or None)
    if pathlib.Path(path).suffix.lower() == '.bin':
        from rwa_monitor.telemetry.ccsds_write import sibling_paths
        xml, yml = sibling_paths(path)
        return f'{path} (with {xml} and {yml})'
    return path
