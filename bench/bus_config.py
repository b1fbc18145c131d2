"""The LLR parameters of the bus benchmarks: the shipped defaults (config/rwa_monitor.yaml).

Shared by bench/bench_bus.py and bench/bus_acceptance.py (which bench_bus runs), so that
neither imports the other for it.
"""

from __future__ import annotations

from typing import Any


def llr_config() -> dict[str, Any]:
    """Return the LLR keyword parameters of the shipped parameters file."""
    from rwa_monitor.pipelines import llr
    from rwa_monitor.telemetry.parameters_file import load_block
    params = load_block(None, llr.SCHEMA)
    return {k: v for k, v in params.items() if k in llr.DEFAULTS}
