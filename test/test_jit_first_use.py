"""Kernels compiled at first use, with a notice.

Issue 36: the first detect waited 34 s in silence, and importing the package compiled every
kernel (a command that never runs the LLR included).
"""

import io
import os
import subprocess
import sys
import time

import pytest

from rwa_monitor.core import jit
from rwa_monitor.progress import KernelNotice, Progress

numba = pytest.importorskip('numba')
pytestmark = pytest.mark.skipif(numba.config.DISABLE_JIT, reason='numba disabled')


def test_importing_the_kernels_compiles_none(tmp_path):
    code = ('from rwa_monitor.core import llr_kernel, llr_calibrated_step, gchi2\n'
            'print(sum(len(k.signatures) for k in (llr_kernel.run, llr_kernel.step, '
            'llr_calibrated_step.step_calibrated, gchi2.log_sf2)))')
    env = {**os.environ, 'NUMBA_CACHE_DIR': str(tmp_path)}
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == '0'


def test_setting_a_reporter_imports_no_compiler():
    # The command line sets its reporter before any command runs; numba is imported by
    # the first kernel module, so that `fleet` starts its workers' server before it.
    code = ('import sys\nfrom rwa_monitor.core import jit\njit.set_reporter(None)\n'
            'print("numba" in sys.modules)\n'
            'from rwa_monitor.core import llr_kernel\nprint("numba" in sys.modules)')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ['False', 'True']


def test_a_declared_signature_is_compiled_at_the_first_call_and_converts_as_before():
    @jit.njit('float64(float64, float64)', cache=False)
    def twice_plus(x, y):
        return 2.0 * x + y
    assert twice_plus.signatures == []
    assert twice_plus(3, 4) == 10.0               # ints convert to the declared float64
    assert [str(s) for s in twice_plus.signatures] == ['(float64, float64)']
    assert twice_plus(1.5, 1) == 4.0
    assert len(twice_plus.signatures) == 1        # no second specialisation
    with pytest.raises(TypeError):
        twice_plus('x', 1.0)


def test_the_notice_speaks_only_of_a_compile_and_says_how_far():
    out = io.StringIO()
    notice = KernelNotice(out=out, after=0.05, interval=0.05)
    notice('start', 'cached.kernel', 0.0, lambda: False)      # a load from the cache
    time.sleep(0.3)
    notice('end', 'cached.kernel', 0.3, lambda: False)
    assert out.getvalue() == '' and notice.compiled == []
    notice('start', 'llr_kernel.run', 0.0, lambda: True)      # missed the cache
    deadline = time.monotonic() + 10.0
    while out.getvalue().count('compiling llr_kernel.run') < 2:
        assert time.monotonic() < deadline, out.getvalue()
        time.sleep(0.02)
    notice('end', 'llr_kernel.run', 4.2, lambda: True)
    lines = out.getvalue().splitlines()
    assert lines[0].startswith('rwa-monitor: first run on this machine: compiling the')
    assert lines[-1] == 'rwa-monitor: compiled llr_kernel.run in 4.2 s'
    assert notice.compiled == [('llr_kernel.run', 4.2)]
    assert sum('first run' in line for line in lines) == 1


def test_progress_in_a_log_prints_a_line_every_interval_and_at_the_end():
    out = io.StringIO()
    start = time.monotonic()
    progress = Progress('writing passes', total=100, out=out, interval=0.05)
    for done in range(100):
        progress.update(done)
        if done in (30, 60):
            time.sleep(0.3)           # a slow step: the heartbeat shows the command alive
    progress.finish()
    elapsed = time.monotonic() - start
    lines = out.getvalue().splitlines()
    assert 3 <= len(lines) <= elapsed / 0.05 + 2          # at most one per interval
    assert lines[-1].startswith('writing passes: 100/100 (100 %)')
    assert any(line.startswith('writing passes: 30/100') for line in lines)   # the beat
    assert '\r' not in out.getvalue()


def test_a_notice_on_a_closed_stream_is_dropped_not_raised(monkeypatch):
    # A command run in-process (a test's captured stderr, a closed log) may leave its
    # stream closed while a later kernel compiles: the notice must not fail the compile.
    import threading
    raised = []
    monkeypatch.setattr(threading, 'excepthook', raised.append)
    out = io.StringIO()
    notice = KernelNotice(out=out, after=0.0, interval=60.0)
    out.close()
    notice('start', 'trend_sums.residual_lag_gram', 0.0, lambda: True)
    time.sleep(0.2)
    notice('end', 'trend_sums.residual_lag_gram', 2.0, lambda: True)
    assert raised == []
    assert notice.noticed and notice.compiled == [('trend_sums.residual_lag_gram', 2.0)]


def test_the_command_line_puts_back_the_reporter_it_found():
    from rwa_monitor.cli.main import main

    def mine(*args):
        pass

    before = jit.set_reporter(mine)
    try:
        assert main(['params']) == 0
        assert jit.set_reporter(mine) is mine
    finally:
        jit.set_reporter(before)
