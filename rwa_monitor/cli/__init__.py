"""The ``rwa-monitor`` command.

Each sub-command lives in its own module ``rwa_monitor/cli/cmd_<name>.py`` with
``register(subparsers)``; each simulator in ``rwa_monitor/cli/simulate_<kind>.py`` with
``register(subparsers)`` under ``rwa-monitor simulate``. Modules are found by name, so a new
command never edits a shared file.
"""
