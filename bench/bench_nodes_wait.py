"""``python -m bench nodes_wait``: does the documented two-process run lose rows? (issue 24).

Each run starts the three detectors as their own processes with the documented command
(console script, ``--params-file`` of the shipped configuration), waits until each shows
on ``/diagnostics``, then starts ``rwa-monitor-replay --ros-args -p file:=F -p rate:=R``
exactly as docs/usage.md writes it (no ``min_subscribers``). It counts what each node
received (its own counters on ``/diagnostics``: llr_detector and fss_diagnoser
``messages`` of ``telemetry/wheels``, vsadc_detector ``gyro_messages``, and the
llr_detector's per-wheel ``samples`` against rows x wheels) and reads, from the
replay's log, the matched subscriber counts it started with.

``LOADERS`` busy-loop processes run beside every run (the added CPU load of a loaded
machine). ``RWA_BENCH_WAIT_BASE`` names another checkout run alternately with this one
("before"; the same load for both). Results: bench/results/nodes_wait.json and the
``nodes_wait`` section of docs/results.md.
"""

from __future__ import annotations

import os
import pathlib
import random
import re
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Any

from bench import nodes_chain, report

RATES = {0.0: 6000, 40.0: 2000}   # replay rate -> rows of the 10 Hz recording
LOADERS = 3                       # busy-loop processes beside the 2-core machine's load
REPLAY_TIMEOUT_S = 240.0
QUIET_S = 10.0                    # s without a count moving after the replay exited
SETTLE_BEFORE_S = 2.0             # main's rule: start after 2 s of steady matched counts
WARM_UP_ROWS = 300                # a first replay, not counted: the detectors' kernels compile
_START = re.compile(r'starting after ([\d.]+) s.*?subscribers: ([^()\n]*)')
_CHANGE = re.compile(r'after ([\d.]+) s, matched subscribers: ([^\n]*)')


class _Listener(nodes_chain._Listener):
    """The chain's /diagnostics listener, plus llr_detector's per-wheel sample counts."""

    def __init__(self, domain_id: int) -> None:
        super().__init__(domain_id)
        self.wheel_samples: dict[str, int] = {}

    def _on_status(self, msg: Any) -> None:
        super()._on_status(msg)
        for status in msg.status:
            if (status.name.startswith('llr_detector: ')
                    and status.hardware_id in nodes_chain.WHEELS):
                values = {kv.key: kv.value for kv in status.values}
                if 'samples' in values:
                    self.wheel_samples[status.hardware_id] = int(values['samples'])


def _busy_loops(count: int) -> list[subprocess.Popen]:
    return [subprocess.Popen([sys.executable, '-c', 'while True: pass'])
            for _ in range(count)]


def _counts(text: str) -> dict[str, int]:
    counts = {}
    for item in text.split(','):
        topic, _, n = item.strip().rpartition(' ')
        if topic and n.isdigit():
            counts[topic] = int(n)
    return counts


def start_counts(log: str) -> dict[str, Any]:
    """Return the wait (s) and matched counts from the replay's 'starting after' line.

    With the replay's log of every change of the counts while waiting (this code, not
    main's), also the time of the last change and ``steady_gap_s``, the longest time the
    counts stood still with a subscriber matched before that last change: a gap of 2 s
    or more is a run where a rule of "2 s of steady counts" would have started before
    the last subscriber matched.
    """
    found = _START.search(log)
    if not found:
        return {}
    out: dict[str, Any] = {'waited_s': float(found.group(1)),
                           'matched': _counts(found.group(2))}
    changes = [(float(t), _counts(text)) for t, text in _CHANGE.findall(log)]
    if changes:
        out['last_change_s'] = changes[-1][0]
        gaps = [b[0] - a[0] for a, b in zip(changes, changes[1:]) if any(a[1].values())]
        out['steady_gap_s'] = round(max(gaps, default=0.0), 2)
    return out


class Detectors:
    """The three detectors, each its own process (documented command), and a listener."""

    def __init__(self, code: pathlib.Path, workdir: pathlib.Path) -> None:
        from rwa_monitor.telemetry import write_telemetry
        config = code / 'config' / 'rwa_monitor.yaml'
        self.domain_id = random.randint(201, 232)
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(self.domain_id),
                        ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST', PYTHONUNBUFFERED='1')
        self.workdir = workdir
        self.listener = _Listener(self.domain_id)
        self.procs: dict[str, subprocess.Popen] = {}
        for name, script in nodes_chain.SEPARATE.items():
            args = [nodes_chain._script(script), '--ros-args', '--params-file', str(config),
                    '-p', f'{name}:diagnostic_period:={nodes_chain.DIAGNOSTIC_PERIOD}',
                    '-p', f'{name}:stale_timeout:=600.0']
            self.procs[name] = subprocess.Popen(
                args, env=dict(self.env, PYTHONPATH=str(code)), stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL, cwd=workdir)
        if not self.listener.spin_until(self._counts_known, 600.0):
            self.close()
            raise RuntimeError('a detector did not start')
        warm_up = workdir / 'warm_up.csv'
        write_telemetry(warm_up, nodes_chain.recording(WARM_UP_ROWS))
        self.replay(warm_up, WARM_UP_ROWS, 0.0, code)

    def _counts_known(self) -> bool:
        return (all(self.listener.last(n) >= 0 for n in nodes_chain.COUNTERS)
                and len(self.listener.wheel_samples) in (0, len(nodes_chain.WHEELS)))

    def counts(self) -> dict[str, int]:
        """Return each node's row counter and llr_detector's wheel samples (key 'wheels')."""
        out = {n: self.listener.last(n) for n in nodes_chain.COUNTERS}
        out['wheels'] = sum(self.listener.wheel_samples.values())
        return out

    def replay(self, csv: pathlib.Path, rows: int, rate: float,
               code: pathlib.Path) -> dict[str, Any]:
        """Run the replay of ``code`` at ``rate``; return what each node counted of it."""
        base = self.counts()
        expected = {n: rows for n in nodes_chain.COUNTERS}
        expected['wheels'] = rows * len(nodes_chain.WHEELS)
        result: dict[str, Any] = {'rows': rows, 'rate': rate, 'load': os.getloadavg()[0]}
        start = time.monotonic()
        replay = subprocess.Popen(
            [nodes_chain._script('rwa-monitor-replay'), '--ros-args', '-p', f'file:={csv}',
             '-p', f'rate:={rate}'],
            env=dict(self.env, PYTHONPATH=str(code)), stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, cwd=self.workdir)
        quiet = {'counts': base, 'since': start}

        def finished() -> bool:
            now, counts = time.monotonic(), self.counts()
            if counts != quiet['counts']:
                quiet.update(counts=counts, since=now)
            if replay.poll() is not None and 'replay_exit_s' not in result:
                result['replay_exit_s'] = round(now - start, 2)
            if all(counts[k] - base[k] >= v for k, v in expected.items()):
                return True
            return replay.poll() is not None and now - quiet['since'] > QUIET_S
        self.listener.spin_until(finished, REPLAY_TIMEOUT_S)
        self.listener.spin_until(lambda: False, 3 * nodes_chain.DIAGNOSTIC_PERIOD)
        result['wall_s'] = time.monotonic() - start
        log = nodes_chain._stop(replay)
        counts = self.counts()
        result['counted'] = {k: counts[k] - base[k] for k in expected}
        result['lost'] = {k: v - result['counted'][k] for k, v in expected.items()
                          if result['counted'][k] != v}
        result['replay_start'] = start_counts(log)
        result['replay_warnings'] = [line for line in log.splitlines() if 'WARN' in line]
        result['replay_exit'] = replay.returncode
        result['last_count_s'] = round(quiet['since'] - start, 2)
        if result['lost'] or replay.returncode:
            result['log'] = log[-4000:]
        return result

    def close(self) -> None:
        """Stop the detectors (SIGINT) and the listener."""
        for proc in self.procs.values():
            nodes_chain._stop(proc)
        self.listener.close()


def _summary(runs: list[dict[str, Any]]) -> dict[str, Any]:
    lossy = [r for r in runs if r['lost']]
    return {'runs': len(runs), 'runs_with_loss': len(lossy),
            'lost': [r['lost'] for r in lossy],
            'matched_at_start_of_lossy': [r['replay_start'].get('matched') for r in lossy],
            'runs_warning_late': sum(any('matched after' in w for w in r['replay_warnings'])
                                     for r in runs),
            'last_change_s': [r['replay_start'].get('last_change_s') for r in runs],
            'steady_gap_s': [r['replay_start'].get('steady_gap_s') for r in runs],
            'waited_s': [r['replay_start'].get('waited_s') for r in runs],
            'load': [round(r['load'], 1) for r in runs]}


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run N replays per rate (and per checkout); write JSON and docs/results.md."""
    from rwa_monitor.telemetry import write_telemetry
    repeats = 2 if quick else int(os.environ.get('RWA_BENCH_WAIT_RUNS', '20'))
    here = pathlib.Path(__file__).resolve().parent.parent
    base = os.environ.get('RWA_BENCH_WAIT_BASE')
    codes = {'before': pathlib.Path(base)} if base else {}
    codes['after'] = here
    workdir = pathlib.Path(tempfile.mkdtemp(prefix='rwa_wait_'))
    loaders = _busy_loops(LOADERS)
    results: dict[str, Any] = {'quick': quick, 'loaders': LOADERS, 'base': base,
                               'repeats': repeats, 'load_before': os.getloadavg()[0],
                               'runs': {}}
    try:
        for rate, rows in RATES.items():
            csv = workdir / f'bus_{rows}.csv'
            write_telemetry(csv, nodes_chain.recording(rows))
            detectors = Detectors(here, workdir)
            try:
                for i in range(repeats):
                    for label, code in codes.items():
                        one = detectors.replay(csv, rows, rate, code)
                        results['runs'].setdefault(f'{label}, rate {rate:g}', []).append(one)
                        print(f'  {label} rate {rate:g} #{i + 1}: lost {one["lost"] or 0}, '
                              f'start {one["replay_start"]}, load {one["load"]:.1f}',
                              flush=True)
            finally:
                detectors.close()
    finally:
        for proc in loaders:
            proc.kill()
            proc.wait()
        shutil.rmtree(workdir, ignore_errors=True)
    results['load_after'] = os.getloadavg()[0]
    results['summary'] = {key: _summary(runs) for key, runs in results['runs'].items()}
    report.write_json(out_dir, 'nodes_wait', results)
    report.update_section('nodes_wait', markdown(results))
    return results


def markdown(results: dict[str, Any]) -> str:
    """Return the ``nodes_wait`` section of docs/results.md."""
    rows = []
    for key, s in results['summary'].items():
        waited = [w for w in s['waited_s'] if w is not None]
        lost = '; '.join(', '.join(f'{n} {v}' for n, v in r.items()) for r in s['lost'])
        short = '; '.join(', '.join(f'{t.rsplit("/", 1)[-1]} {m}' for t, m in c.items())
                          for c in s['matched_at_start_of_lossy'] if c)
        gaps = [g for g in s.get('steady_gap_s', []) if g is not None]
        caught = (f'{sum(g >= SETTLE_BEFORE_S for g in gaps)}/{len(gaps)}; max '
                  f'{max(gaps):.1f} s' if gaps else '-')
        rows.append([key, f'{s["runs"] - s["runs_with_loss"]}/{s["runs"]}', lost or '-',
                     short or '-', caught, s['runs_warning_late'],
                     f'{min(waited):.1f}-{max(waited):.1f}' if waited else '-',
                     f'{min(s["load"]):.1f}-{max(s["load"]):.1f}'])
    rates = ', '.join(f'rate {r:g}: {n} rows' for r, n in RATES.items())
    lines = ['## Replay waiting for its subscribers (issue 24, item 6)', '',
             f'`python -m bench nodes_wait`{" --quick" if results["quick"] else ""} '
             '(bench/bench_nodes_wait.py): the documented two-process run. The three '
             'detectors (one process each, shipped parameters file) are started and warmed '
             'up by a first replay, then `rwa-monitor-replay --ros-args -p file:=F -p '
             f'rate:=R` is started {results["repeats"]} times per rate and checkout ({rates}; '
             '4 wheels at 10 Hz, gyro, star tracker, reference rate), "before" (main) and '
             '"after" alternately against the same detectors, with '
             f'{results["loaders"]} busy-loop processes beside them on the 2-core machine. '
             'A run is complete when llr_detector and fss_diagnoser counted every wheels row, '
             'vsadc_detector every gyro row and llr_detector rows x 4 wheel samples. Load: '
             'the 1-minute average when each replay started.', '',
             report.table(['checkout, rate', 'runs complete', 'lost (node rows; wheels = '
                           'llr wheel samples)', 'matched at start of the lossy runs',
                           'a subscriber matched after >= 2 s of steady counts',
                           'runs warning of a late subscriber', 'replay waited (s)', 'load'],
                          rows)]
    return '\n'.join(lines)
