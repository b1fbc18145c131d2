"""The operator's view: Open MCT with the project's plugin (``rwa-monitor openmct``).

- :mod:`.bundle` finds (and installs with npm) the pinned Open MCT bundle;
- :mod:`.store` holds the telemetry points the page shows, with their history;
- :mod:`.history` fills it from a fleet's outputs and from a recording;
- :mod:`.live` turns decoded live messages into points (the ROS side is
  ``rwa_monitor/nodes/openmct_bridge.py``);
- :mod:`.server` serves the page, the history and the live WebSocket (tornado).

``web/`` holds the page and the plugin (JavaScript); ``npm/`` the package.json and
package-lock.json that pin Open MCT. docs/usage.md, "The operator's view", walks through it.
"""
