"""The fleet's report.html (fleet/report.py): self-contained, every wheel in the table."""

import base64
import datetime as dt
import re

import numpy as np
import pytest

from rwa_monitor.core.events import AnomalyEvent
from rwa_monitor.core.trend import SECONDS_PER_DAY
from rwa_monitor.fleet.report import render
from rwa_monitor.fleet.trends import add_trends, trend_limits, trend_steps, wheel_trends


def write_report(path, events, summary, rows, limits=None, epoch=None):
    """Write the page of these inputs at ``path`` (the trends fitted once, as a run does)."""
    trends = wheel_trends(rows, limits if limits is not None else
                          summary.get('trend_limits') or {})
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(render(events, summary, rows, trends, epoch))


def rows_of(craft, wheel, wear_per_day, seed, passes=30):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(passes):
        t0 = i * SECONDS_PER_DAY / 3
        out.append({'spacecraft': craft, 'wheel': wheel, 'pass': f'p{i}', 't_start': t0,
                    't_end': t0 + 600.0, 'samples': 6000,
                    'dry': 2e-4 + wear_per_day * (t0 + 300) / SECONDS_PER_DAY
                    + rng.normal(0, 1e-6), 'dry_se': 1e-6,
                    'viscous': 5e-7 + rng.normal(0, 1e-9), 'viscous_se': 1e-9,
                    'relative_to': 'zero'})
    return out


def fleet_inputs():
    rows = (rows_of('sc1', 'rw1', 0.0, 1) + rows_of('sc1', 'rw2', 2e-6, 2)
            + rows_of('sc<2>', 'rw1', 0.0, 3) + rows_of('sc<2>', 'rw2', 0.0, 4))
    events = [{'spacecraft': 'sc<2>', 'component': 'rw1', 'kind': 'dry', 'index': 7,
               'time': 4.5 * SECONDS_PER_DAY, 'declared_time': 4.6 * SECONDS_PER_DAY,
               'detector': 'llr', 'p_value': 0.0, 'delta_dry_nm': 1.5e-4, 'revision': 1,
               'final': True, 'new': True},
              {'spacecraft': 'sc<2>', 'component': 'rw1', 'kind': 'both', 'index': 7,
               'time': 4.5 * SECONDS_PER_DAY, 'declared_time': 4.6 * SECONDS_PER_DAY,
               'detector': 'llr', 'p_value': 1e-9, 'revision': 0},
              {'spacecraft': 'sc1', 'component': 'gyro_y', 'kind': 'drift', 'index': 3,
               'time': 2.25 * SECONDS_PER_DAY, 'declared_time': 2.3 * SECONDS_PER_DAY,
               'detector': 'vsadc', 'p_value': None, 'revision': 0},
              {'spacecraft': 'sc1', 'component': 'rw1', 'kind': 'viscous', 'index': 9,
               'time': 1.0 * SECONDS_PER_DAY, 'declared_time': 1.1 * SECONDS_PER_DAY,
               'detector': 'llr', 'p_value': 1e-5, 'revision': 0, 'superseded': True}]
    summary = {'spacecraft': {'sc1': {'components': {'rw1': {'health': 'healthy'},
                                                     'rw2': {'health': 'healthy'}},
                                      'not_examined': {}},
                              'sc<2>': {'components': {'rw1': {'health': 'dry'},
                                                       'rw2': {'health': 'unknown'}},
                                        'not_examined': {'pass x.csv': 'unreadable',
                                                         'rw2': 'no rows'}}},
               'engine': {'wall_s': 12.5, 'workers': 2}}
    return events, summary, rows


def test_trend_table_finds_the_wearing_wheel_and_projects_the_limit():
    *_, rows = fleet_inputs()
    table = {(t['spacecraft'], t['wheel']): t for t in wheel_trends(rows, {'dry': 2.3e-4})}
    assert sorted(table) == [('sc1', 'rw1'), ('sc1', 'rw2'), ('sc<2>', 'rw1'),
                             ('sc<2>', 'rw2')]
    wear = table[('sc1', 'rw2')]
    assert wear['dry_p_value'] < 1e-10
    assert wear['dry_slope_per_day'] == pytest.approx(2e-6, rel=0.05)
    assert wear['dry_crossing_low_s'] < 15 * SECONDS_PER_DAY < wear['dry_crossing_high_s']
    assert wear['viscous_crossing_s'] is None and wear['passes'] == 30
    for row in rows[:10]:
        row['relative_to'] = 'nominal'          # sc1 rw1: calibrated for its first passes
    mixed = wheel_trends(rows)[0]
    assert (mixed['wheel'], mixed['passes'], mixed['relative_to']) == ('rw1', 20, 'zero')


def step_event(time, kind='dry', shape='step', confirmed=True, component='rw1', revision=0):
    return AnomalyEvent('llr', component, kind, time, int(time), time + 60.0, int(time) + 600,
                        p_value=0.0, revision=revision,
                        details={'kind_shape': shape, 'kind_confirmed': confirmed})


def test_a_confirmed_step_is_fitted_as_a_jump_a_ramp_or_unconfirmed_kind_is_not(tmp_path):
    rows = rows_of('sc1', 'rw1', 2e-6, 5)                 # a wear of 2e-6 N m per day
    step = 10 * SECONDS_PER_DAY / 3                       # the start of pass 10
    for row in rows[10:]:
        row['dry'] += 1.5e-4                              # and a dry step
    across = wheel_trends(rows)[0]
    assert across['steps_s'] == [] and across['since_s'] is None
    assert across['dry_slope_per_day'] > 2e-6 + 4 * across['dry_slope_se']    # biased
    events = [('sc1', step_event(step - 900.0, kind='undecided')),
              ('sc1', step_event(step)),
              ('sc1', step_event(step + 1e5, shape='ramp')),
              ('sc1', step_event(step + 2e5, confirmed=False)),
              ('sc1', step_event(step + 3e5, component='gyro', kind='bias'))]
    steps = trend_steps(events)
    assert steps == {('sc1', 'rw1'): (step,)}
    fitted = wheel_trends(rows, steps=steps)[0]
    assert fitted['steps_s'] == [step] and fitted['since_s'] == step
    assert fitted['passes'] == 30
    # The wear, from every pass: within 4 standard errors of the truth.
    assert fitted['dry_slope_per_day'] == pytest.approx(2e-6, abs=4 * fitted['dry_slope_se'])
    assert fitted['dry_step_sizes'][0] == pytest.approx(1.5e-4, rel=0.05)
    assert trend_steps([('sc1', step_event(step, shape='ramp')),
                        ('sc1', step_event(step + 10.0, confirmed=False))]) == {}
    revised = trend_steps([('sc1', step_event(step)),         # revised to unconfirmed
                           ('sc1', step_event(step, kind='undecided', revision=1))])
    assert revised == {}
    events, summary, _ = fleet_inputs()
    summary['spacecraft']['sc1']['components']['rw1']['health'] = 'dry'
    page = tmp_path / 'report.html'
    trends = wheel_trends(rows, steps=steps)
    page.write_text(render(events, summary, rows, trends))
    assert '30 (step at day 3.33)' in page.read_text()


def test_report_is_self_contained_shows_every_wheel_and_plots_those_to_look_at(tmp_path):
    events, summary, rows = fleet_inputs()
    path = tmp_path / 'out' / 'report.html'
    write_report(path, events, summary, rows)
    text = path.read_text()
    assert not re.search(r'https?:', text) and '<script' not in text and '<link' not in text
    images = re.findall(r'src="([^"]*)"', text)
    assert len(images) == 3 and all(i.startswith('data:image/svg+xml;base64,') for i in images)
    # Drawn: the wearing wheel (trend), the one with a change, the one not examined; the
    # healthy wheel with no trend and only a superseded event is a table row only.
    drawn = re.findall(r'<h3 id="([^"]*)"', text)
    assert drawn == ['w-sc1_rw2', 'w-sc_2__rw1', 'w-sc_2__rw2'], drawn
    assert 'href="#w-sc1_rw1"' not in text and 'the other 1 are healthy' in text
    figures = [base64.b64decode(i.split(',', 1)[1]).decode() for i in images]
    assert all(f.startswith('<svg xmlns="http://www.w3.org/2000/svg" width="1170"')
               and f.endswith('</svg>') for f in figures)
    for craft, wheel in [('sc1', 'rw1'), ('sc1', 'rw2'), ('sc&lt;2&gt;', 'rw1')]:
        assert f'<td>{wheel}</td>' in text and craft in text
    assert 'sc<2>' not in text                       # names are escaped
    assert 'healthy; trend (dry)' in text and '<td>dry</td>' in text
    assert 'unknown (not examined)' in text
    assert 'rw2: no rows' in text and 'pass x.csv: unreadable' in text
    events = text.split('<h2>Events</h2>')[1].split('</table>')[0]
    # One row per change at its latest revision; the superseded event is not shown.
    assert events.count('<tr') == 3 and 'viscous' not in events and 'both' not in events
    assert '&lt; 1e-300' in events and 'n/a' in events and '+1.50e-04 N m dry' in events
    assert 'day 4.500' in events and 'the archive has no epoch' in text


def test_report_gives_calendar_times_with_an_epoch(tmp_path):
    events, summary, rows = fleet_inputs()
    epoch = dt.datetime(2026, 1, 1, tzinfo=dt.timezone.utc)
    write_report(tmp_path / 'report.html', events, summary, rows, epoch=epoch)
    text = (tmp_path / 'report.html').read_text()
    assert '2026-01-05 12:00:00 UTC' in text and 'Data from 2026-01-01 00:00:00 UTC' in text


def test_report_of_an_empty_fleet_and_of_unusable_passes(tmp_path):
    write_report(tmp_path / 'empty.html', [], {}, [])
    assert 'Fleet friction report' in (tmp_path / 'empty.html').read_text()
    nan_rows = [{'spacecraft': 'sc1', 'wheel': 'rw1', 'pass': 'a', 't_start': float('nan'),
                 't_end': float('nan'), 'samples': 0, 'dry': float('nan'),
                 'dry_se': float('nan'), 'viscous': None, 'viscous_se': None}]
    write_report(tmp_path / 'nan.html', [], {}, nan_rows)
    assert 'rw1' in (tmp_path / 'nan.html').read_text()


def test_summary_trends_are_the_report_numbers(tmp_path):
    """summary.json's per-wheel trend and report.html show the same slope, p and crossing."""
    events, summary, rows = fleet_inputs()
    summary['spacecraft']['sc1']['components'] = {'rw1': {}, 'rw2': {}}
    limits = trend_limits({'dry_limit': 2.3e-4, 'viscous_limit': 0.0})
    assert limits.as_dict() == {'dry': 2.3e-4} and limits.viscous is None
    add_trends(summary, wheel_trends(rows, limits), limits)
    assert summary['trend_limits'] == {'dry': 2.3e-4}
    wear = summary['spacecraft']['sc1']['components']['rw2']['trend']
    table = {(t['spacecraft'], t['wheel']): t for t in wheel_trends(rows, limits)}
    assert wear['dry_slope_per_day'] == table[('sc1', 'rw2')]['dry_slope_per_day']
    assert wear['dry_crossing_s'] == table[('sc1', 'rw2')]['dry_crossing_s']
    assert wear['viscous_crossing_s'] is None and wear['viscous_limit'] is None
    assert summary['spacecraft']['sc<2>']['components']['rw2']['trend']['passes'] == 30
    path = tmp_path / 'report.html'
    write_report(path, events, summary, rows)
    text = path.read_text()
    days = [wear[f'dry_crossing{s}_s'] / SECONDS_PER_DAY for s in ('', '_low', '_high')]
    assert f'{days[0]:.1f} ({days[1]:.1f} .. {days[2]:.1f})' in text
    assert f'{wear["dry_slope_per_day"]:.3g} &plusmn; {wear["dry_slope_se"]:.3g}' in text
    assert f'{wear["dry_p_value"]:.3g}' in text


def test_a_wheel_plot_draws_every_level_its_errors_trend_and_changes():
    from rwa_monitor.fleet.report import _plot
    from rwa_monitor.fleet.trend_table import TrendTable
    events, _, rows = fleet_inputs()
    entries = {(e['spacecraft'], e['wheel']): e for e in wheel_trends(rows, {})}
    groups = TrendTable.of(rows).by_wheel()
    key = ('sc<2>', 'rw1')
    changes = [events[0], events[0] | {'time': 7 * SECONDS_PER_DAY, 'kind': 'viscous'}]
    svg = base64.b64decode(_plot(key, groups[key], entries[key], changes, None)).decode()
    finite = int(np.isfinite(groups[key]['dry']).sum())
    dots = re.findall(r'<path d="([^"]*)" stroke="#1f77b4"', svg)
    assert [d.count('h0') for d in dots] == [finite, int(np.isfinite(
        groups[key]['viscous']).sum())]
    assert svg.count('stroke="#999999" stroke-width="1"') == 2       # error bars, per panel
    kinds = re.findall(r'rotate\(-90\)" text-anchor="end" font-size="12" fill="#d62728">'
                       r'([a-z]+)<', svg)
    assert kinds == [events[0]['kind'], 'viscous'] * 2
    assert 'sc&lt;2&gt; / rw1' in svg and svg.count('pass level ± 1 s.e.') == 2
    assert _plot(key, groups[key], entries[key], changes, None) == base64.b64encode(
        svg.encode()).decode()                                       # the same every time


@pytest.mark.parametrize('low, high, expected, power', [
    (0.0, 10.0, [0, 2, 4, 6, 8, 10], 0),
    (1.7e-4, 4.2e-4, [2.0, 2.5, 3.0, 3.5, 4.0], -4),
    (-3.0, 7.5, [-2, 0, 2, 4, 6], 0),
    (12000.0, 480000.0, [1, 2, 3, 4], 5),
])
def test_ticks_are_round_numbers_spanning_the_range(low, high, expected, power):
    from rwa_monitor.fleet.svg_plot import nice_ticks, tick_texts
    ticks = nice_ticks(low, high)
    texts, found = tick_texts(ticks)
    assert found == power and ticks.min() >= low and ticks.max() <= high
    assert np.allclose([float(t) for t in texts], expected)
