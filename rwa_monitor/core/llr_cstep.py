"""The streaming step of the paper's model as a C function, called in one C call per sample.

:func:`step_address` compiles (numba ``cfunc``, cached like the kernels) the function
``int64 step(double *fs, int64 n_fs, int64 *ints, int64 n_ints, double t, double w,
double f)``: the kernel's :func:`rwa_monitor.core.llr_kernel.sample` (its exact tail
settled, ``llr_kernel.settle``) on the detector's two state arrays seen through their
pointers, the same compiled code as ``llr_kernel.step`` (no other implementation). The
optional C module ``rwa_monitor.core._stepcall`` (rwa_monitor/core/_stepcall.c, built by
setup.py) calls it: :class:`StepOwner`, a base of the detector, holds the armed step and
the arrays; :func:`compiled_update` makes the detector's ``update`` a method implemented
in C that calls the armed step for three floats and the Python ``update`` otherwise.

Without the C module, without numba or with ``NUMBA_DISABLE_JIT=1`` nothing is armed:
:class:`StepOwner` is a stand-in, ``update`` the Python method, which calls
``llr_kernel.step`` itself (the same events; docs/llr.md "Streaming call" says why the
C call, and what each call costs on this machine).
"""

from __future__ import annotations

from typing import Callable

from rwa_monitor.core import llr_kernel as kern

try:
    from numba import carray
except ImportError:   # pragma: no cover - numba is pinned in requirements.txt
    carray = None
try:
    from rwa_monitor.core._stepcall import CompiledUpdate, StepOwner
except ImportError:   # built by setup.py where a C compiler is present (optional)
    CompiledUpdate = None

    class StepOwner:
        """Stand-in base without the C module: no step is ever armed."""

        def _step_arm(self, address: int, fs, ints) -> None:
            raise RuntimeError('the C module rwa_monitor.core._stepcall is not built')

        def _step_disarm(self) -> None:
            """Nothing is armed."""

        def _step_armed(self) -> bool:
            return False

# Returned by the C function when the kernel raised (a float division by zero, the only
# error the step can raise); the C module then raises ArithmeticError.
FAILED = -1
_COMPILED: list = []


def available() -> bool:
    """Return True if the C module is built (the step may then be armed)."""
    return CompiledUpdate is not None


def compiled_update(python_update: Callable, on_flags: str) -> Callable:
    """Return the class attribute ``update``: the C method around ``python_update``.

    Without the C module: ``python_update`` itself. ``on_flags``: the name of the method
    called with the step's non-zero flags (it returns the sample's events).
    """
    return python_update if CompiledUpdate is None else CompiledUpdate(python_update, on_flags)


def step_address() -> int | None:
    """Return the address of the compiled C step (compiled or loaded once), or None.

    None: no C module, no numba, or numba disabled (then the Python path runs).
    """
    if not _COMPILED:
        _COMPILED.append(_compile() if available() else None)
    compiled = _COMPILED[0]
    return None if compiled is None else compiled.address


def _step(fs_ptr, n_fs, ints_ptr, n_ints, t, w, f):
    """:func:`llr_kernel.step` on the arrays at ``fs_ptr``, ``ints_ptr``; FAILED if it raised."""
    try:
        return kern.step(carray(fs_ptr, (n_fs,)), carray(ints_ptr, (n_ints,)), t, w, f)
    except Exception:   # compiled code cannot raise through its C caller
        return FAILED


def _compile():
    if carray is None:   # pragma: no cover
        return None
    from numba import cfunc, config, types
    if config.DISABLE_JIT:
        return None
    signature = types.int64(types.CPointer(types.float64), types.int64,
                            types.CPointer(types.int64), types.int64,
                            types.float64, types.float64, types.float64)
    from rwa_monitor.core.jit import reporting
    with reporting('llr_cstep.step', kern.step):   # llr_kernel.step compiled into it
        return cfunc(signature, cache=True)(_step)
