"""``rwa-monitor-monitor``: every detector node in one process (llr, vsadc, fss).

The one-process composition of llr_detector, vsadc_detector and fss_diagnoser: the same
node classes, names, topics, parameters and diagnostics as the three console scripts, in
one rclpy context turned by one EventsExecutor. A telemetry row then crosses the process
boundary once instead of three times, and the three nodes share one ``/clock`` and one
discovery participant (docs/nodes.md "Where the time goes"; its rate in docs/results.md).
Parameters go to each node by its block (``--params-file``) or ``-p NODE:name:=value``;
an unprefixed ``-p`` reaches every node, which refuses the names no schema knows.
"""

from __future__ import annotations

from typing import Sequence

from rwa_monitor.nodes.fss_diagnoser import FssDiagnoserNode
from rwa_monitor.nodes.llr_detector import LLRDetectorNode
from rwa_monitor.nodes.process import node_help, run_nodes
from rwa_monitor.nodes.vsadc_detector import VsadcDetectorNode

NODE_CLASSES = (LLRDetectorNode, VsadcDetectorNode, FssDiagnoserNode)


def main(args: Sequence[str] | None = None) -> int:
    """Run the three detector nodes in one process (console script ``rwa-monitor-monitor``)."""
    return run_nodes(list(NODE_CLASSES), args, help_text=lambda: node_help(
        'rwa-monitor-monitor', __doc__) + '\nThe parameters of each node: rwa-monitor-llr '
        '--help, rwa-monitor-vsadc --help, rwa-monitor-fss --help.')


if __name__ == '__main__':
    raise SystemExit(main())
