"""Fleet scale: a constellation's archive through detectors that carry their state.

``rwa-monitor fleet`` (rwa_monitor/cli/cmd_fleet.py) on Dask distributed: archive
discovery (archive), the per-component tasks (components), the detector state as
data and on disk (codec, state), the engine (engine), summary and outputs.
"""
