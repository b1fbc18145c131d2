"""llr_detector as a managed (lifecycle) node, for an integrator that sequences its nodes.

:class:`ManagedLLRDetectorNode` is :class:`~rwa_monitor.nodes.llr_detector.LLRDetectorNode`
with rclpy's lifecycle interface (``LifecycleNodeMixin``: the ``~/change_state`` and
``~/get_state`` services and ``trigger_*`` methods) and the usual states:

- *unconfigured* (after start) and *inactive*: telemetry is received but not fed to any
  detector; it is counted as ``inactive`` on /diagnostics;
- *configure*: loads the ``calibration_file`` in force and checks it (a missing or
  malformed file, or one that changed into one, fails the transition and names the file
  and key; the node stays unconfigured);
- *activate*: telemetry goes to the wheel detectors;
- *deactivate*: telemetry stops reaching the detectors; the latched alarms (journal,
  ``~/acknowledge``, /diagnostics) are kept, as are the detectors' states;
- *cleanup*: the wheel detectors are dropped (the next activation starts afresh); latched
  alarms stay until acknowledged.

Not a console script: it is built in-process (``ManagedLLRDetectorNode(context=...)``)
by an integrator's own launcher; docs/nodes.md "Managed llr_detector".
"""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNodeMixin, LifecycleState, TransitionCallbackReturn

from rwa_monitor.nodes.llr_detector import LLRDetectorNode


class ManagedLLRDetectorNode(LifecycleNodeMixin, LLRDetectorNode):
    """llr_detector with the lifecycle states of the module docstring."""

    def __init__(self, **kwargs: Any) -> None:
        """Create the node unconfigured (``kwargs`` go to rclpy's Node)."""
        LLRDetectorNode.__init__(self, **kwargs)
        LifecycleNodeMixin.__init__(self, enable_communication_interface=True)
        self.input_counters['inactive'] = 0
        self.active = False

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Load and check the calibration in force; FAILURE (logged) if it is bad."""
        try:
            self.get_logger().info(self.calibration.set(self.params['calibration_file']))
        except Exception as err:  # noqa: BLE001 - any refusal of the file fails the transition
            self.get_logger().error(f'configure: calibration_file: {err}')
            return TransitionCallbackReturn.FAILURE
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Feed telemetry to the detectors from now on."""
        self.active = True
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Stop feeding the detectors; latched alarms and detector states are kept."""
        self.active = False
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Drop the wheel detectors (latched alarms stay)."""
        for wheel_id in list(self.wheels):
            self.diagnostics.remove(wheel_id)
        self.wheels.clear()
        return TransitionCallbackReturn.SUCCESS

    def on_raw_wheels(self, buffer: bytes) -> None:
        """Feed one serialised message when active; count it ``inactive`` otherwise."""
        if self.active:
            super().on_raw_wheels(buffer)
        else:
            self.input_counters['inactive'] += 1
