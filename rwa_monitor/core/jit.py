"""The compiler of the per-sample numeric kernels (numba), or none.

``njit`` compiles a function to machine code (no fast-math: IEEE operations in source
order, so compiled and plain Python give the same floats; ``cache=True`` keeps the machine
code next to the module, compiled once per machine). Without numba, or with
``NUMBA_DISABLE_JIT=1``, the decorated functions run as the plain Python they are: one
implementation either way (docs/llr.md "Compiled per-sample path").
"""

from __future__ import annotations

try:
    from numba import njit
except ImportError:   # pragma: no cover - numba is pinned in requirements.txt
    def njit(*args, **kwargs):
        """Return the function unchanged (no compiler)."""
        return args[0] if args and callable(args[0]) else (lambda fn: fn)

__all__ = ['njit']
