"""``rwa-monitor demo``: the main job, replay + every detector node in one process.

On first run it generates (fixed seed) a 4-wheel, 10 Hz telemetry file of a few hours with
friction anomalies injected on two wheels into a cache directory; then it runs the
telemetry_replay node (as fast as the detectors take it) and every detector node listed
in DETECTOR_NODES in one process on rclpy's EventsExecutor (SingleThreadedExecutor
as the fallback), draws a live view (progress bar, per-wheel health, anomaly log) and ends
with a summary of the events against the injected truth.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import os
import pathlib
import sys
import time
from typing import Any, TextIO

import numpy as np

from rwa_monitor.cli.cmd_dashboard import LEVEL_NAMES
from rwa_monitor.cli.readable import levels_legend
from rwa_monitor.core import keys

# Detector nodes the demo runs: one module name per line. A module that is not there
# (yet) is skipped with a note. Each module names its node class in NODE_CLASS, or
# defines exactly one rclpy Node subclass; the class takes rclpy Node keywords.
DETECTOR_NODES = (
    'rwa_monitor.nodes.llr_detector',
    'rwa_monitor.nodes.vsadc_detector',
    'rwa_monitor.nodes.fss_diagnoser',
)

DEFAULT_HOURS = 3.0
DEFAULT_SEED = 7
RATE_HZ = 10.0
WHEELS = ('rw1', 'rw2', 'rw3', 'rw4')
TIMEOUT_S = 300.0


def node_classes(modules: tuple[str, ...] = DETECTOR_NODES) -> tuple[list[type], list[str]]:
    """Return (node classes found, notes about the modules skipped)."""
    from rclpy.node import Node
    found, notes = [], []
    for name in modules:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name and name.startswith(err.name):
                notes.append(f'{name} is not there yet: skipped')
                continue
            raise
        cls = getattr(module, 'NODE_CLASS', None)
        if cls is None:
            classes = [c for c in vars(module).values() if isinstance(c, type)
                       and issubclass(c, Node) and c is not Node
                       and c.__module__ == module.__name__]
            if len(classes) != 1:
                notes.append(f'{name}: no single Node class (set NODE_CLASS): skipped')
                continue
            cls = classes[0]
        found.append(cls)
    return found, notes


def cache_dir() -> pathlib.Path:
    """Return the cache directory ($RWA_MONITOR_CACHE, else $XDG_CACHE_HOME/rwa_monitor)."""
    env = os.environ.get('RWA_MONITOR_CACHE')
    if env:
        return pathlib.Path(env)
    base = os.environ.get('XDG_CACHE_HOME') or pathlib.Path.home() / '.cache'
    return pathlib.Path(base) / 'rwa_monitor'


def demo_name(hours: float, seed: int, gyro: bool = False) -> str:
    """Return the file name of a generated demo record."""
    return f'demo-4rw-{hours:g}h-seed{seed}{"-gyro" if gyro else ""}.csv'


def demo_file(directory: pathlib.Path, hours: float = DEFAULT_HOURS,
              seed: int = DEFAULT_SEED, gyro: bool = False) -> pathlib.Path:
    """Return the demo telemetry file, generating it (seeded) on first use.

    Anomalies: a dry-friction step on rw2 at 1/3 of the record, a viscous step on rw3 at
    2/3 (sizes: 4 noise standard deviations of torque at the wheel's typical speed).
    ``gyro`` adds the AOCS simulator's gyro, star-tracker and reference-rate channels with
    a medium gyro drift on the y axis at half the record (input for the VSADC node).
    """
    from rwa_monitor.sim.friction import Anomaly, simulate_friction_with_truth
    from rwa_monitor.telemetry import write_telemetry
    path = directory / demo_name(hours, seed, gyro)
    if path.is_file():
        return path
    directory.mkdir(parents=True, exist_ok=True)
    duration = hours * 3600.0
    tele, _ = simulate_friction_with_truth(
        wheels=list(WHEELS), duration_s=duration, rate_hz=RATE_HZ, seed=seed,
        anomalies=[Anomaly('rw2', 'dry', round(duration / 3), delta_dry=2.0e-4),
                   Anomaly('rw3', 'viscous', round(2 * duration / 3), delta_viscous=1.0e-6)])
    if gyro:
        from rwa_monitor.sim.aocs import add_gyro_channels, named_fault
        tele = add_gyro_channels(tele, fault=named_fault('medium', 'y', round(duration / 2)),
                                 seed=seed)
    write_telemetry(path, tele)   # atomic: a concurrent reader sees the whole file or none
    return path


def gyro_faults(tele: Any) -> list[tuple[str, str, float]]:
    """Return the injected gyro faults (axis, kind, start time) from the truth labels."""
    faults = []
    for axis in ('gyro_x', 'gyro_y', 'gyro_z'):
        labels = tele.truth.get(axis)
        if labels is None:
            continue
        changes = np.flatnonzero(np.diff(labels) != 0) + 1
        for k in changes:
            kind = {1: 'drift', 2: 'bias'}.get(int(labels[k]), 'healthy')
            faults.append((axis, kind, float(tele.time[k])))
    return faults


@dataclasses.dataclass
class DemoResult:
    """What the demo measured and found."""

    rows: int
    wall_s: float
    executor: str
    events: list[Any]
    pipeline_events: list[Any]
    changes: list[Any]
    matches: list[tuple[Any, Any]]
    false_alarms: list[Any]
    notes: list[str]
    repeats: list[Any] = dataclasses.field(default_factory=list)
    other_detectors: dict[str, int] = dataclasses.field(default_factory=dict)
    other_events: list[dict[str, Any]] = dataclasses.field(default_factory=list)
    gyro_faults: list[tuple[str, str, float]] = dataclasses.field(default_factory=list)
    wheels: int = len(WHEELS)


def _make_executor(kind: str, context: Any, notes: list[str]) -> tuple[Any, str]:
    from rclpy.executors import SingleThreadedExecutor
    if kind == 'events':
        try:
            from rclpy.experimental import EventsExecutor
            return EventsExecutor(context=context), 'events'
        except Exception as err:  # noqa: BLE001 - any failure means: use the fallback
            notes.append(f'EventsExecutor unavailable ({err}); using SingleThreadedExecutor')
    return SingleThreadedExecutor(context=context), 'single'


def _progress(replay: Any, started: float, width: int = 30) -> str:
    done = replay.progress
    bar = '#' * int(done * width) + '-' * (width - int(done * width))
    elapsed = max(time.monotonic() - started, 1e-9)
    t = replay.telemetry.time
    now = t[min(replay.next_row, len(t) - 1)] - t[0]
    return (f'[{bar}] {100 * done:5.1f}%  t={now:8.1f}/{t[-1] - t[0]:.0f} s  '
            f'{replay.published / elapsed:7.0f} rows/s')


def run_demo(path: pathlib.Path, *, domain_id: int = 0, executor: str = 'events',
             out: TextIO | None = None, live: bool = True,
             modules: tuple[str, ...] = DETECTOR_NODES,
             overrides: dict[str, Any] | None = None,
             timeout_s: float = TIMEOUT_S) -> DemoResult:
    """Replay ``path`` through every detector node in one process; return the result.

    ``overrides``: parameters given to every detector node (e.g. ``calibration_file``).
    """
    import rclpy
    from rclpy.context import Context
    from rclpy.logging import LoggingSeverity
    from rclpy.parameter import Parameter

    from rwa_monitor.cli.cmd_dashboard import Board, make_node, render, Screen
    from rwa_monitor.nodes.llr_detector import LLRDetectorNode
    from rwa_monitor.nodes.replay import TelemetryReplay
    from rwa_monitor.paths import config_file
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    out = sys.stdout if out is None else out
    classes, notes = node_classes(modules)
    for note in notes:
        print(f'note: {note}', file=out)
    params_args = ['--ros-args', '--params-file', str(config_file())]
    context = Context()
    rclpy.init(context=context, domain_id=domain_id)
    nodes: list[Any] = []
    runner = None
    try:
        runner, kind = _make_executor(executor, context, notes)
        given = [Parameter(k, value=v) for k, v in (overrides or {}).items()]
        detectors = [cls(context=context, cli_args=params_args, parameter_overrides=given)
                     for cls in classes]
        board = Board()
        view = make_node(board, context=context)
        replay = TelemetryReplay(context=context, cli_args=params_args, parameter_overrides=[
            Parameter('file', value=str(path)), Parameter('rate', value=0.0),
            Parameter('burst', value=50 if kind == 'events' else 1),
            Parameter('min_subscribers', value=1), Parameter('exit_when_done', value=False)])
        nodes = [*detectors, view, replay]
        for node in nodes:
            if live:  # log lines would tear the live view; it shows the same facts
                node.get_logger().set_level(LoggingSeverity.ERROR)
            runner.add_node(node)
        llr = next((d for d in detectors if isinstance(d, LLRDetectorNode)), None)
        tele = replay.telemetry
        expected_samples = len(tele) * len(tele.wheels)
        screen = Screen(out) if live else None
        started = time.monotonic()

        def finished() -> bool:
            if not replay.done:
                return False
            return llr is None or sum(w.samples for w in llr.wheels.values()) >= \
                expected_samples
        while not finished() and time.monotonic() - started < timeout_s:
            runner.spin_once(timeout_sec=0.1)
            if screen is not None and screen.due():
                screen.draw(render(board, title='rwa_monitor demo',
                                   progress=_progress(replay, started), colour=screen.tty))
        wall = time.monotonic() - started
        drain = time.monotonic() + 1.0
        while time.monotonic() < drain:
            runner.spin_once(timeout_sec=0.05)
        if screen is not None:
            screen.draw(render(board, title='rwa_monitor demo',
                               progress=_progress(replay, started), colour=screen.tty))
        events = list(llr.events) if llr is not None else []
        if llr is not None:
            # The file has ended: each wheel's open declaration gets its final kind
            # (LLRDetector.finish, as `rwa-monitor detect` does at the end of the file).
            for wheel in llr.wheels.values():
                events.extend(wheel.runner.finish())
    finally:
        if runner is not None:
            runner.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
    others = {name: n for name, n in board.by_detector.items() if name != 'llr'}
    result = _evaluate(tele, events, wall, kind, notes, llr, others)
    result.other_events = [e for e in board.events if e['fields'].get('detector') != 'llr']
    result.gyro_faults = gyro_faults(tele)
    return result


def _evaluate(tele: Any, events: list[Any], wall: float, kind: str, notes: list[str],
              llr: Any, others: dict[str, int]) -> DemoResult:
    """Match events to the injected changes; run the file pipeline for comparison."""
    from rwa_monitor.pipelines import llr as llr_pipeline
    from rwa_monitor.sim.friction import changes_from_truth
    changes = changes_from_truth(tele)
    config = {k: llr.params[k] for k in ('window', 'k_verif', 'false_alarm_rate',
                                         'noise_std')} if llr is not None else {}
    if llr is not None and llr.params['calibration_file']:
        config['calibration_file'] = llr.params['calibration_file']
    pipeline_events = llr_pipeline.run(tele, config) if llr is not None else []
    # Attribution rule (docs/nodes.md): a declaration belongs to an injected change when
    # its estimated change time lies in [truth - W, truth + 2 W], W = one window of time.
    # The first declaration comes at most about W after the change; after it the detector
    # restarts from its change estimate, so a re-declaration of the same change may
    # estimate a change time up to about 2 W after the truth.
    window_s = config.get('window', 500) / RATE_HZ

    def near(event: Any, change: Any) -> bool:
        return (event.component == change.wheel
                and -window_s <= event.time - change.time_s <= 2 * window_s)

    first = [e for e in events if e.revision == 0]
    matches, used = [], set()
    for change in changes:
        hit = next((e for e in first if id(e) not in used and near(e, change)), None)
        if hit is not None:
            used.add(id(hit))
        matches.append((change, hit))
    attributed = {id(e) for e in first for c in changes if near(e, c)}
    repeats = [e for e in first if id(e) not in used and id(e) in attributed]
    false_alarms = [e for e in first if id(e) not in used and id(e) not in attributed]
    return DemoResult(len(tele), wall, kind, events, pipeline_events, changes, matches,
                      false_alarms, notes, repeats, others, len(tele.wheels))


def final_kind(result: DemoResult, hit: Any) -> str:
    """Return the kind of a declaration after its revisions (its last event)."""
    return [e.kind for e in result.events
            if e.component == hit.component and e.index == hit.index][-1]


def kind_counts(result: DemoResult) -> dict[str, Any]:
    """Count right and wrong kinds against the injected truth, per detector.

    LLR: each injected change is ``right`` when its declaration's kind after the
    revisions is the injected one, ``undecided`` when it stays undecided, ``wrong``
    for any other kind, ``missed`` without a declaration. FSS: each (wheel, kind) flag
    is ``right`` when that kind was injected on that wheel, else ``wrong`` (listed);
    an injected change that no window flagged is ``missed``.
    """
    llr = {'right': 0, 'wrong': 0, 'undecided': 0, 'missed': 0}
    for change, hit in result.matches:
        if hit is None:
            llr['missed'] += 1
            continue
        kind = final_kind(result, hit)
        llr['right' if kind == change.kind else
            'undecided' if kind == 'undecided' else 'wrong'] += 1
    truth = {(c.wheel, c.kind) for c in result.changes}
    flagged = {(e['component'], e['fields'].get('kind')) for e in result.other_events
               if e['fields'].get('detector') == 'fss'}
    fss: dict[str, Any] = {'ran': 'fss' in result.other_detectors,
                           'right': len(flagged & truth),
                           'wrong': sorted(flagged - truth, key=str),
                           'missed': sorted(truth - flagged, key=str)}
    return {'llr': llr, 'fss': fss}


def summary(result: DemoResult) -> str:
    """Return the end-of-demo summary: events against the truth."""
    lines = ['', 'summary: events against the injected truth (detected: first declared '
             'kind -> kind after the revisions; wheels by llr, gyro axes by vsadc)',
             f'{"where":<6} {"injected":<8} {"at t s":>8} | {"detected":<8} '
             f'{"change t s":>10} {"declared t s":>12} {"delay s":>8}']
    for change, hit in result.matches:
        left = f'{change.wheel:<6} {change.kind:<8} {change.time_s:>8.1f} | '
        if hit is None:
            lines.append(left + 'MISSED')
        else:
            final = final_kind(result, hit)
            kinds = hit.kind if final == hit.kind else f'{hit.kind}->{final}'
            lines.append(left + f'{kinds:<8} {hit.time:>10.1f} {hit.declared_time:>12.1f} '
                         f'{hit.declared_time - change.time_s:>8.1f}')
    for axis, kind, start, hit in gyro_matches(result):
        left = f'{axis:<6} {kind:<8} {start:>8.1f} | '
        if hit is None:
            lines.append(left + ('MISSED' if 'vsadc' in result.other_detectors
                                 else 'not run (no vsadc detector)'))
            continue
        change, declared = hit.get(keys.CHANGE_TIME), hit.get(keys.DECLARATION_TIME)
        lines.append(left + f'{hit.get(keys.KIND, "?"):<8} {_time_text(change):>10} '
                     f'{_time_text(declared):>12} '
                     f'{_time_text(declared - start if _is_time(declared) else None):>8}')
    lines.append(f'repeated declarations of an injected change (after the detector '
                 f'restarted; change estimate within [-1, +2] windows of it): '
                 f'{len(result.repeats)}')
    lines.append(f'false alarms (first declarations away from every injected change): '
                 f'{len(result.false_alarms)}')
    for event in result.false_alarms:
        lines.append(f'  {event.component} {event.kind} change t={event.time:.1f} s')
    # The same events, whatever the order across wheels (the node's end-of-record events
    # come after every live one; detect gives each wheel's events in turn).
    same = sorted((e.component, e.kind, e.index, e.declared_index) for e in result.events) == \
        sorted((e.component, e.kind, e.index, e.declared_index) for e in result.pipeline_events)
    lines.append(f'node events identical to `rwa-monitor detect` on the file: '
                 f'{"yes" if same else "NO"} ({len(result.events)} events incl. revisions)')
    lines.append(f'{result.rows} rows x {result.wheels} wheels in {result.wall_s:.1f} s '
                 f'({result.rows / max(result.wall_s, 1e-9):.0f} wheel messages/s, '
                 f'{result.executor} executor)')
    for axis, kind, start in result.gyro_faults:
        lines.append(f'injected gyro fault: {axis} {kind} from t={start:.1f} s')
    for name, count in sorted(result.other_detectors.items()):
        lines.append(f'{name} detector: {count} events on the anomalies topic:')
        for event in result.other_events:
            f = event['fields']
            if f.get('detector') == name:
                change, declared = f.get('change_time_s'), f.get('declaration_time_s')
                lines.append(f'  {event["component"]} {f.get("kind", "?")}'
                             + (f' change t={change:.1f} s' if isinstance(change, float)
                                else '')
                             + (f' declared t={declared:.1f} s'
                                if isinstance(declared, float) else '')
                             + f' ({LEVEL_NAMES.get(event.get("level"), "?")})')
    counts = kind_counts(result)
    llr = counts['llr']
    lines.append(f'kinds against the truth: llr right {llr["right"]}/{len(result.changes)}, '
                 f'wrong {llr["wrong"]}, undecided {llr["undecided"]}, '
                 f'missed {llr["missed"]}')
    fss = counts['fss']
    if fss['ran']:
        wrong = ', '.join(f'{w} {k}' for w, k in fss['wrong']) or 'none'
        missed = ', '.join(f'{w} {k}' for w, k in fss['missed']) or 'none'
        lines.append(f'fss flags against the truth: right {fss["right"]}/'
                     f'{len(result.changes)}, wrong {len(fss["wrong"])} ({wrong}), '
                     f'not flagged: {missed}')
    for note in result.notes:
        lines.append(f'note: {note}')
    lines.append(levels_legend())
    return '\n'.join(lines)


def gyro_matches(result: DemoResult) -> list[tuple[str, str, float, dict[str, Any] | None]]:
    """Return each injected gyro fault with the first VSADC event on its axis after it.

    The first event of another kind than ``healthy`` whose declaration comes after the
    fault began (fields of the anomalies topic), or None.
    """
    out = []
    for axis, kind, start in result.gyro_faults:
        if kind == 'healthy':
            continue
        hit = next((e['fields'] for e in result.other_events
                    if e['fields'].get(keys.DETECTOR) == 'vsadc' and e['component'] == axis
                    and e['fields'].get(keys.KIND) != 'healthy'
                    and _is_time(e['fields'].get(keys.DECLARATION_TIME))
                    and e['fields'][keys.DECLARATION_TIME] >= start), None)
        out.append((axis, kind, start, hit))
    return out


def _is_time(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _time_text(value: Any) -> str:
    return f'{value:.1f}' if _is_time(value) else 'n/a'


def run(args: argparse.Namespace) -> int:
    """Run the demo; return 0."""
    if args.file:
        path = pathlib.Path(args.file)
    else:
        directory = pathlib.Path(args.cache_dir) if args.cache_dir else cache_dir()
        if not (directory / demo_name(args.hours, args.seed, args.gyro)).is_file():
            print(f'first run: generating the seeded demo telemetry in {directory} ...',
                  flush=True)
        path = demo_file(directory, args.hours, args.seed, args.gyro)
    print(f'telemetry: {path}', flush=True)
    result = run_demo(path, domain_id=args.domain_id, executor=args.executor,
                      live=not args.quiet)
    print(summary(result))
    return 0


def register(subparsers: Any) -> None:
    """Add the ``demo`` sub-command."""
    parser = subparsers.add_parser(
        'demo', help='replay a seeded 4-wheel file through every detector node, live',
        description=__doc__.split('\n\n')[1] if __doc__ else None)
    parser.add_argument('--hours', type=float, default=DEFAULT_HOURS,
                        help=f'length of the generated record (default {DEFAULT_HOURS:g})')
    parser.add_argument('--seed', type=int, default=DEFAULT_SEED, help='simulator seed')
    parser.add_argument('--file', help='replay this telemetry file instead')
    parser.add_argument('--gyro', action=argparse.BooleanOptionalAction, default=True,
                        help='add gyro, star-tracker and reference-rate channels with a gyro '
                        'drift, input of the VSADC node (default; --no-gyro replays the '
                        'wheels alone, about twice as fast: see docs/nodes.md)')
    parser.add_argument('--cache-dir', help='where the generated file is kept '
                        '(default $RWA_MONITOR_CACHE or ~/.cache/rwa_monitor)')
    parser.add_argument('--executor', choices=('events', 'single'), default='events',
                        help='rclpy executor (default events; single is the fallback)')
    parser.add_argument('--domain-id', type=int,
                        default=int(os.environ.get('ROS_DOMAIN_ID', '0') or 0),
                        help='ROS domain id (default: $ROS_DOMAIN_ID or 0)')
    parser.add_argument('--quiet', action='store_true', help='no live view, summary only')
    parser.set_defaults(func=run)
