"""A fleet run's result: per spacecraft what it ran and found, the history, the summary.

:class:`FleetResult` is built once the chains are gathered (:meth:`FleetResult.assemble`):
the event history (the state's, its end-of-run events superseded for every spacecraft
this run continued, plus this run's), the trend rows (the state's plus this run's), the
summary (summary.json) and what the run means for the exit code. :meth:`commit` writes
the state of every spacecraft at once (fleet/state.py), after the outputs.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
import datetime as dt
import pathlib
from typing import Any, Mapping, Sequence

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.runner_facts import ComponentFacts
from rwa_monitor.fleet import history, state
from rwa_monitor.fleet.plan import Blocks, SpacecraftPlan
from rwa_monitor.fleet.records import Chain, GYRO, PassFacts, SpacecraftRecord, TrendRow
from rwa_monitor.fleet.trend_table import TrendTable

# LLR parameters an operator needs beside the events (summary.json, report.html): how
# often a healthy wheel is declared by chance depends on them (docs/fleet.md).
OPERATING_POINT = ('false_alarm_rate', 'window', 'category_level')


@dataclass(frozen=True)
class SpacecraftResult:
    """One spacecraft's run: its plan, last chain (None: nothing run) and new record."""

    plan: SpacecraftPlan
    chain: Chain | None
    record: SpacecraftRecord | None
    run: int

    @property
    def id(self) -> str:
        """Return the spacecraft's id."""
        return self.plan.id

    def not_examined(self) -> dict[str, str]:
        """Return what of this spacecraft was not examined in this run, with why."""
        p = self.plan
        missing: dict[str, str] = {}
        if p.error:
            missing['spacecraft'] = p.error
        elif p.spec is None and not p.prior and not p.passes:
            missing['spacecraft'] = 'no readable pass with a wheel friction or gyro column'
        missing.update({f'pass {name}': why for name, why in p.unreadable.items()})
        missing.update({f'pass {name}': why for name, why in p.late.items()})
        if self.chain is None:
            return missing
        for facts in self.chain.passes:
            if facts.error:
                missing[f'pass {facts.name}'] = facts.error
            for component, why in facts.component_errors.items():
                missing[f'{component} in pass {facts.name}'] = why
        for component, facts in self.chain.facts.items():
            for name, why in facts.not_examined().items():
                missing[name] = f'{facts.family}: {why}'
        return missing

    def summary(self, events: Sequence[AnomalyEvent]) -> dict[str, Any]:
        """Return the spacecraft's summary.json entry (``events``: its current ones)."""
        p = self.plan
        chain = self.chain
        passes = chain.passes if chain else ()
        components = {}
        for name, facts in (chain.facts.items() if chain else ()):
            mine = [e for e in events if _owner(e) == name]
            components[name] = {
                'detector': facts.family, 'health': health(facts, mine),
                'passes_this_run': sum(not f.error and name not in f.component_errors
                                       for f in passes),
                'events': len(mine), 'by_kind': dict(Counter(e.kind for e in mine)),
                **_facts_fields(facts)}
        return {'calibration': p.craft.calibration,
                'passes': [f.name for f in p.passes], 'already_processed': p.already,
                'unreadable': dict(p.unreadable), 'late': dict(p.late),
                'ignored': dict(p.craft.ignored),
                'rows_dropped': sum(f.rows_dropped for f in passes),
                'overlapping': {f.name: _overlap(f) for f in passes if f.rows_dropped},
                'last_time_s': self.record.last_time if self.record else None,
                'events': len(events), 'components': components,
                'not_examined': self.not_examined()}


def _overlap(facts: PassFacts) -> str:
    """Return why a pass lost rows: they repeat stamps an earlier pass already fed."""
    whole = facts.rows + facts.rows_dropped
    what = 'all' if facts.rows == 0 else f'{facts.rows_dropped} of'
    return (f'{what} {whole} rows stamped at or before the last one fed before it '
            '(it overlaps an earlier pass): not fed again')


def _owner(event: AnomalyEvent) -> str:
    """Return the fleet component of an event (gyro axes belong to the gyro)."""
    return GYRO if event.component.startswith('gyro_') else event.component


def _facts_fields(facts: ComponentFacts) -> dict[str, Any]:
    if facts.parts:
        return {'counters': dict(facts.rejected),
                'axes': {part.component: part.fields() for part in facts.parts}}
    return facts.fields()


def latest_kinds(events: Sequence[AnomalyEvent]) -> dict[tuple[str, int], AnomalyEvent]:
    """Return per (component, change index) the latest revision of each change."""
    latest: dict[tuple[str, int], AnomalyEvent] = {}
    for e in events:
        key = (e.component, e.index)
        if key not in latest or e.revision >= latest[key].revision:
            latest[key] = e
    return latest


def health(facts: ComponentFacts, events: Sequence[AnomalyEvent]) -> str:
    """Return a component's current verdict: the kind of its latest change, or its state.

    A wheel with changes: the latest change's kind at its latest revision (e.g. ``dry``);
    without: ``healthy`` if examined, else ``unknown``. The gyro: each axis's final state.
    """
    if facts.parts:
        return ', '.join(f'{p.component[-1]}: {p.details.get("final_state", "unknown")}'
                         for p in facts.parts)
    changes = sorted(latest_kinds(events).values(), key=lambda e: (e.time, e.index))
    if changes:
        return changes[-1].kind
    return 'healthy' if facts.examined else 'unknown'


@dataclass
class FleetResult:
    """A fleet run (module docstring)."""

    crafts: list[SpacecraftResult]
    history: list[history.Entry]
    trend: TrendTable
    summary: dict[str, Any]
    timings: dict[str, Any]
    run: int = 0
    epoch: dt.datetime | None = None
    state_dir: pathlib.Path | None = None
    loaded: state.Loaded | None = None
    saved: Mapping[str, SpacecraftRecord] = field(default_factory=dict)
    trends: list[dict[str, Any]] = field(default_factory=list)

    @classmethod
    def assemble(cls, crafts: list[SpacecraftResult], blocks: Blocks,
                 engine: dict[str, Any], *, run: int, epoch: dt.datetime | None,
                 state_dir: str | pathlib.Path | None, loaded: state.Loaded | None,
                 saved: Mapping[str, SpacecraftRecord],
                 prior_history: list[history.Entry], prior_trend: TrendTable,
                 timings: dict[str, Any], config: str) -> 'FleetResult':
        """Return the result of the gathered spacecraft (history, trend, summary)."""
        continued = [c.id for c in crafts if c.chain is not None]
        found: list[history.Entry] = []
        new_rows: list[TrendRow] = []
        for c in crafts:
            if c.chain is not None:
                found += history.entries(c.id, c.chain.events, run)
                found += history.entries(c.id, c.chain.end_of_run, run, end_of_run=True)
                new_rows += c.chain.trend
        past = history.supersede(prior_history, continued)
        full = history.order(past + found)
        trend = prior_trend.plus(new_rows).sorted()
        result = cls(crafts, full, trend, {}, timings, run, epoch,
                     None if state_dir is None else pathlib.Path(state_dir), loaded, saved)
        result.summary = result._summary(blocks, engine, config)
        return result

    def current_events(self) -> list[AnomalyEvent]:
        """Return the events of the history that are not superseded."""
        return [h.event for h in history.current(self.history)]

    @property
    def new_passes(self) -> int:
        """Return the passes this run fed."""
        return sum(len(c.plan.passes) for c in self.crafts if c.chain is not None)

    @property
    def already_processed(self) -> int:
        """Return the passes skipped as processed by earlier runs."""
        return sum(c.plan.already for c in self.crafts)

    @property
    def anomaly(self) -> bool:
        """Return True if this run found an anomaly: a new event that is not a recovery."""
        return any(h.event.kind != 'healthy' and h.run == self.run
                   for h in history.current(self.history))

    @property
    def incomplete(self) -> bool:
        """Return True if something of this run was not examined."""
        return any(c.not_examined() for c in self.crafts)

    def rows(self) -> list[dict[str, Any]]:
        """Return the events table of the history, ``new`` marking this run's events."""
        return history.rows(self.history, self.run, self.epoch)

    def _summary(self, blocks: Blocks, engine: dict[str, Any],
                 config: str) -> dict[str, Any]:
        from rwa_monitor.fleet.trends import (add_trends, trend_limits, trend_steps,
                                              wheel_trends)
        current = history.current(self.history)
        events: dict[str, list[AnomalyEvent]] = {}
        for h in current:
            events.setdefault(h.spacecraft, []).append(h.event)
        crafts = {c.id: c.summary(events.get(c.id, [])) for c in self.crafts}
        summary = {'spacecraft': crafts, 'run': self.run,
                   'events': len(current),
                   'new_events': sum(h.run == self.run for h in current),
                   'superseded': sum(h.superseded for h in self.history),
                   'new_passes': self.new_passes,
                   'already_processed': self.already_processed,
                   'epoch_utc': history.utc(self.epoch, 0.0) if self.epoch else None,
                   'engine': {**engine, **self.timings}, 'config': config,
                   'operating_point': {name: blocks['llr'][name] for name in OPERATING_POINT},
                   'state': None if self.state_dir is None else str(self.state_dir)}
        limits = trend_limits(blocks['fleet'])
        starts = trend_steps((h.spacecraft, h.event) for h in current)
        self.trends = wheel_trends(self.trend, limits, starts)
        add_trends(summary, self.trends, limits)
        return summary

    def commit(self) -> None:
        """Write every spacecraft's state at once into the ``--state`` folder (if any)."""
        if self.state_dir is None:
            return
        records = dict(self.saved)
        for c in self.crafts:
            if c.record is not None:
                records[c.id] = c.record
        from rwa_monitor.fleet.history import to_parquet
        state.commit(self.state_dir, self.loaded, records, self.trend.to_parquet(),
                     to_parquet(self.history))
