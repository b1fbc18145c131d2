"""``python -m rwa_monitor.cli.compile_kernels``: compile the detectors' kernels now.

The kernels (core/jit.py) are compiled for the machine at their first use and cached;
on a machine's first run that takes tens of seconds inside the first command (which says
so). ``make venv`` runs this module after installing, so that a clone's first command
answers at once; a pip user may run it once after ``pip install``.
"""

from __future__ import annotations

import sys
import time

from rwa_monitor.core import jit
from rwa_monitor.progress import KernelNotice


def main() -> int:
    """Compile (or load from the cache) every kernel; print what it did; return 0."""
    notice = KernelNotice()
    jit.set_reporter(notice)
    start = time.perf_counter()
    count = jit.warm()
    from rwa_monitor.core import llr_cstep
    if llr_cstep.step_address() is not None:      # the streaming step's C entry
        count += 1
    jit.set_reporter(None)
    compiled = len(notice.compiled)
    print(f'rwa-monitor: {count} kernels ready in {time.perf_counter() - start:.1f} s '
          f'({compiled} compiled now, {count - compiled} from the cache)', file=sys.stderr)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
