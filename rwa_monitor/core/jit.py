"""The compiler of the per-sample numeric kernels (numba), or none; compiled when first used.

``njit`` compiles a function to machine code (no fast-math: IEEE operations in source
order, so compiled and plain Python give the same floats; ``cache=True`` keeps the machine
code next to the module, compiled once per machine). Without numba, or with
``NUMBA_DISABLE_JIT=1``, the decorated functions run as the plain Python they are: one
implementation either way (docs/architecture.md "Compiled kernels").

A kernel given an explicit signature is compiled **at its first call**, not at import
(numba compiles such a kernel when it is decorated): importing the package, ``--help``
or a command that never runs the LLR compiles nothing, and ``detect`` compiles only the
kernels it calls. The first call compiles the declared signature (or loads it from the
cache) and then stops compiling, as numba's own eager kernels do, so arguments convert
to the declared types exactly as before. On a machine's first run the compilation takes
tens of seconds: :func:`set_reporter` lets a command say so while it happens (the CLI
prints a notice and progress; the core itself prints nothing).
"""

from __future__ import annotations

import contextlib
import functools
import threading
import time
from typing import Any, Callable, Iterator

import numpy as np

__all__ = ['kernel_array', 'njit', 'reporting', 'set_reporter', 'warm']

# reporter(event, kernel, seconds, compiling): event 'start' (seconds 0) or 'end' (seconds
# taken); compiling() is True once the kernel missed the cache (it is being compiled).
_reporter: Callable[[str, str, float, Callable[[], bool]], None] | None = None
_lazy: list[Any] = []           # every kernel compiled at first use, for warm()
_lock = threading.Lock()


@functools.cache
def _numba() -> Any:
    """Return numba, imported at the first kernel's decoration, or None without it.

    Not at this module's import: a command sets its reporter (:func:`set_reporter`) before
    it imports any kernel, and ``rwa-monitor fleet`` starts its workers' server first.
    """
    try:
        import numba
    except ImportError:   # pragma: no cover - numba is pinned in requirements.txt
        return None
    return numba


def set_reporter(reporter: Callable[[str, str, float, Callable[[], bool]], None] | None
                 ) -> Callable[[str, str, float, Callable[[], bool]], None] | None:
    """Have ``reporter(event, kernel, seconds, compiling)`` called around each first use.

    Returns the reporter it replaces, for a caller that puts it back when it is done.
    """
    global _reporter
    previous, _reporter = _reporter, reporter
    return previous


def njit(*args: Any, **kwargs: Any) -> Any:
    """Return numba's ``njit`` decorator; with a signature, compiled at the first call."""
    numba = _numba()
    if numba is None or numba.config.DISABLE_JIT:
        if args and callable(args[0]):
            return args[0]
        return lambda fn: fn
    if not args or callable(args[0]) or args[0] is None:
        return numba.njit(*args, **kwargs)
    signatures = args[0] if isinstance(args[0], (list, tuple)) else [args[0]]

    def decorate(fn: Callable) -> Any:
        dispatcher = numba.njit(**kwargs)(fn)
        name = f'{fn.__module__.rsplit(".", 1)[-1]}.{fn.__name__}'

        def first_call(*call_args: Any, **call_kwargs: Any) -> Callable:
            # numba's dispatcher calls this when no compiled version matches; it returns
            # what the dispatcher then calls with the arguments.
            compile_declared(dispatcher, name, signatures)
            return lambda *a, **k: dispatcher(*a, **k)
        dispatcher._compile_for_args = first_call
        dispatcher.rwa_declared = (name, signatures)
        _lazy.append(dispatcher)
        return dispatcher
    return decorate


def kernel_array(values: Any, dtype: Any = float) -> np.ndarray:
    """Return ``values`` as a C-contiguous array of ``dtype`` that the kernels take.

    The kernels' declared signatures are of writable arrays: numba types a read-only
    array apart and finds no match for it (a TypeError from deep inside a detector). A
    read-only input, as ``np.load(..., mmap_mode='r')``, ``np.frombuffer`` or a zero-copy
    Arrow column give, is therefore copied; any other array goes as
    ``np.ascontiguousarray`` gives it (itself when it already fits). Copying at the entry
    rather than compiling read-only variants keeps one compiled version per kernel.
    """
    array = np.ascontiguousarray(values, dtype=dtype)
    return array if array.flags.writeable else array.copy()


def _misses(*dispatchers: Any) -> int:
    """Return the cache misses (compilations) of ``dispatchers`` so far (numba's stats)."""
    return sum(sum(d.stats.cache_misses.values()) for d in dispatchers)


@contextlib.contextmanager
def reporting(name: str, *dispatchers: Any) -> Iterator[None]:
    """Tell the reporter (if any) that kernel ``name`` compiles (or loads) inside.

    The reporter gets ``compiling()``: True once one of ``dispatchers`` missed the cache
    (numba counts the miss before it compiles), so a load is never called a compile.
    """
    reporter = _reporter
    start = time.perf_counter()
    before = _misses(*dispatchers)

    def compiling() -> bool:
        return _misses(*dispatchers) > before
    if reporter is not None:
        reporter('start', name, 0.0, compiling)
    try:
        yield
    finally:
        if reporter is not None:
            reporter('end', name, time.perf_counter() - start, compiling)


def compile_declared(dispatcher: Any, name: str, signatures: list) -> None:
    """Compile (or load from the cache) a kernel's declared signatures; stop compiling."""
    with _lock:
        if '_compile_for_args' not in vars(dispatcher):
            return                              # done by another thread meanwhile
        with reporting(name, dispatcher):
            for signature in signatures:
                dispatcher.compile(signature)
        dispatcher.disable_compile()
        del dispatcher._compile_for_args        # back to numba's own


def warm(modules: tuple[str, ...] = ('rwa_monitor.core.gchi2', 'rwa_monitor.core.llr_kernel',
                                     'rwa_monitor.core.llr_calibrated_step',
                                     'rwa_monitor.core.llr_ramp_kernel',
                                     'rwa_monitor.core.scaled_solve',
                                     'rwa_monitor.core.trend_sums')) -> int:
    """Compile every kernel of ``modules`` now (or load it from the cache); return how many.

    For an installation step (``make venv``) or an operator who would rather wait now
    than at the first command.
    """
    import importlib
    for module in modules:
        importlib.import_module(module)
    for dispatcher in list(_lazy):
        if '_compile_for_args' in vars(dispatcher):
            compile_declared(dispatcher, *dispatcher.rwa_declared)
    return len(_lazy)
