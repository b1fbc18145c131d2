"""What every rwa_monitor node shares, by responsibility (the API of docs/nodes.md).

- :mod:`~rwa_monitor.nodes.qos`: :func:`telemetry_qos`, :data:`EVENTS_QOS`,
  :data:`DIAGNOSTICS_QOS`, :data:`CLOCK_QOS`, :func:`qos_event_callbacks`;
- :mod:`~rwa_monitor.nodes.parameters`: :func:`descriptor`, :func:`declare_parameters`,
  :func:`refuse_unknown_overrides`, :func:`beaten_overrides`;
- :mod:`~rwa_monitor.nodes.diagnostics`: :class:`DiagnosticsPublisher` and the levels;
- :mod:`~rwa_monitor.nodes.wheels_input`: reading ``telemetry/wheels`` (bytes decoder,
  wheel refusals);
- :mod:`~rwa_monitor.nodes.process`: :func:`run_node`, :func:`run_nodes`, :func:`spin`.

This module re-exports them, so that ``from rwa_monitor.nodes.common import ...`` keeps
working for every node and test.
"""

from rwa_monitor.nodes.diagnostics import (  # noqa: F401
    ComponentHealth, DiagnosticsPublisher, ERROR, LEVEL_NAMES, OK, publish_calibration_change,
    STALE, WARN)
from rwa_monitor.nodes.parameters import (  # noqa: F401
    beaten_overrides, declare_parameters, descriptor, Parameters, ParamSpec,
    refuse_unknown_overrides, warn_beaten_overrides)
from rwa_monitor.nodes.process import (  # noqa: F401
    node_help, rcl_error_line, RCLError, run_node, spin, wants_help, with_sim_time)
from rwa_monitor.nodes.qos import (  # noqa: F401
    CLOCK_QOS, DIAGNOSTICS_QOS, EVENTS_QOS, qos_event_callbacks, TELEMETRY_DEPTH,
    telemetry_qos)
from rwa_monitor.nodes.wheels_input import Refusal, wheel_names, wheel_refusal  # noqa: F401
from rwa_monitor.telemetry.codecs import format_value, key_values  # noqa: F401
