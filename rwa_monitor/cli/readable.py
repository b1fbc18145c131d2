"""Numbers and levels as a person reads them, for every table the commands print.

The files (JSON, CSV) keep the exact values; a printed table shows a p-value that
underflowed as ``< 1e-300`` (not ``0``), a missing one as ``n/a`` (not ``nan``), other
numbers with three significant digits, and says what each level means.
"""

from __future__ import annotations

import math
from typing import Any

# Smallest p-value printed as a number: below it (0.0 once it underflows) "< 1e-300".
SMALLEST_P = 1e-300

# What each level of /diagnostics and of the anomaly events means (docs/nodes.md, Levels).
LEVEL_MEANINGS = (
    ('OK', 'examined, no anomaly'),
    ('WARN', 'an anomaly: LLR dry or viscous, VSADC bias, an FSS flag'),
    ('ERROR', 'a larger departure: LLR both (dry and viscous), VSADC drift (a gyro drifts '
              'without bound), a failed diagnosis'),
    ('WAIT', 'not examined yet: a window diagnoser filling its first window'),
    ('STALE', 'no input for the stale timeout, or not examined'),
    ('LOST', 'its node has published nothing for a while'),
)


def p_value_text(value: Any) -> str:
    """Return a p-value as printed: ``3.2e-09``, ``< 1e-300`` when it underflowed, ``n/a``."""
    number = _float(value)
    if number is None or math.isnan(number):
        return 'n/a'
    if number < SMALLEST_P:
        return f'< {SMALLEST_P:.0e}'
    return f'{number:.2g}'


def number_text(value: Any) -> str:
    """Return a number with three significant digits (``n/a`` for none or NaN)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return str(value)
    if isinstance(value, int):
        return str(value)
    if math.isnan(value):
        return 'n/a'
    return f'{value:.3g}'


def levels_legend() -> str:
    """Return one line saying what each level means."""
    return 'levels: ' + '; '.join(f'{name} {meaning}' for name, meaning in LEVEL_MEANINGS)


def _float(value: Any) -> float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float)):
        return float(value)
    try:
        return float(value)
    except (TypeError, ValueError):
        return None
