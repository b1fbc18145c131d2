"""Command-line options shared by the commands that read telemetry."""

from __future__ import annotations

import argparse

from rwa_monitor.telemetry.rosbag_io import DEFAULT_TOPICS

INPUT_HELP = ('telemetry: CSV file, rosbag2 folder (metadata.yaml with .mcap or .db3), or a '
              'bare .mcap or .db3 file')
OUTPUT_HELP = ('output: a folder name without suffix writes a rosbag2 recording (MCAP '
               'storage), .mcap or .db3 a bare recording file, .csv a CSV file')


def add_topics(parser: argparse.ArgumentParser) -> None:
    """Add ``--topics STREAM=TOPIC,...``: the topic of each stream in a recording."""
    defaults = ','.join(f'{s}={t}' for s, t in DEFAULT_TOPICS.items())
    parser.add_argument('--topics', default='', metavar='STREAM=TOPIC,...',
                        help='topic names of the streams of a recording (streams not named keep '
                             f'their default; default {defaults})')
