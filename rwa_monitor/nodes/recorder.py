"""Node ``recorder``: record what the detectors publish into a rosbag2 folder.

Subscribes to each topic of the ``topics`` parameter (diagnostic_msgs/DiagnosticArray:
the detectors' ``anomalies`` and ``/diagnostics``) and writes every message, stamped with
its ``header.stamp`` (the telemetry time), into the rosbag2 folder ``output`` (MCAP
storage), so a run can be reviewed afterwards (``rwa-monitor dashboard`` reads the live
topics; any rosbag2 tool reads the folder). The folder appears when the node ends (Ctrl-C
or shutdown): until then the messages are in a temporary folder beside it, so an
interrupted run never leaves a half-written recording under the output name.
"""

from __future__ import annotations

from typing import Any, Sequence

from diagnostic_msgs.msg import DiagnosticArray
import rclpy.logging
from rclpy.node import Node

from rwa_monitor.exceptions import ConfigError, OutputError
from rwa_monitor.nodes.common import (declare_parameters, DIAGNOSTICS_QOS, EVENTS_QOS,
                                      ParamSpec, qos_event_callbacks, run_node)
from rwa_monitor.telemetry.rosbag_io import RecordingWriter

NODE_NAME = 'recorder'
MSG_TYPE = 'diagnostic_msgs/msg/DiagnosticArray'

PARAMETERS = (
    ParamSpec('output', '', 'rosbag2 folder to write (a name without suffix; an existing '
              'recording there is replaced when the node ends).', read_only=True),
    ParamSpec('topics', 'anomalies,/diagnostics', 'Comma-separated DiagnosticArray topics '
              'to record (relative names resolve in the node namespace).', read_only=True),
)


class Recorder(Node):
    """Record DiagnosticArray topics into a rosbag2 folder; see the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node and open the temporary recording."""
        super().__init__(NODE_NAME, **kwargs)
        self.params = declare_parameters(self, PARAMETERS)
        if not self.params['output']:
            raise ConfigError('parameter output: a rosbag2 folder name is required')
        topics = [t.strip() for t in self.params['topics'].split(',') if t.strip()]
        if not topics:
            raise ConfigError('parameter topics: at least one topic is required')
        try:
            self.writer = RecordingWriter(self.params['output'])
        except OutputError as err:
            raise ConfigError(f'parameter output: {err}') from None
        self._subs = []
        for topic in topics:
            name = self.resolve_topic_name(topic)
            qos = DIAGNOSTICS_QOS if name.endswith('diagnostics') else EVENTS_QOS
            self._subs.append(self.create_subscription(
                DiagnosticArray, topic, lambda data, name=name: self._on_message(name, data),
                qos, raw=True, event_callbacks=qos_event_callbacks(self, topic)))
        self.get_logger().info(f'recording {", ".join(topics)} into '
                               f'{self.params["output"]}')

    def _on_message(self, topic: str, data: bytes) -> None:
        self.writer.write(topic, MSG_TYPE, None, data)

    @property
    def counts(self) -> dict[str, int]:
        """Return the number of messages recorded per topic."""
        return dict(self.writer.counts)

    def destroy_node(self) -> None:
        """Close the recording (renamed onto ``output``), then destroy the node."""
        writer = getattr(self, 'writer', None)
        if writer is not None:
            self.writer = None
            writer.close()
            # After SIGINT/SIGTERM the context is gone: the node's logger would also try
            # /rosout and print an error line; a logger of another name only prints.
            logger = self.get_logger() if self.context.ok() else \
                rclpy.logging.get_logger(f'{NODE_NAME}.closed')
            logger.info(f'recorded {writer.counts} into {writer.path}')
        super().destroy_node()


def main(args: Sequence[str] | None = None) -> int:
    """Run the recorder (console script ``rwa-monitor-record``)."""
    return run_node(lambda: Recorder(), args)


if __name__ == '__main__':
    raise SystemExit(main())
