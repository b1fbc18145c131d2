"""Daily runs with --state add up to one run over the whole archive, field for field.

For any split of an archive's passes into successive runs (each run adds the passes of
the next days), the union of the runs' events less the superseded end-of-run ones equals
the events of one run over the whole archive; a (component, change, revision) never
carries two kinds among the current events; what each run found is marked ``new``; a
superseded end-of-run event stays in the cumulative history, marked.
"""

import json
import shutil

from distributed import Client, LocalCluster
from fleet_archive import CUTS_A, CUTS_B, events_of, make_archive, references
from hypothesis import given, HealthCheck, settings, strategies as st
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.fleet import history
from rwa_monitor.fleet.engine import run_archive

ORDER = {'sat-a': [name for _, _, name in CUTS_A], 'sat-b': [name for _, _, name in CUTS_B]}


@pytest.fixture(scope='module')
def archive(tmp_path_factory):
    """Return (archive folder, spacecraft -> detect events)."""
    root = tmp_path_factory.mktemp('daily')
    joined = make_archive(root / 'archive', root / 'work')
    return root / 'archive', references(root / 'archive', joined)


@pytest.fixture(scope='module')
def client():
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        yield c


def _grow(folder, target, upto):
    """Copy into ``target`` each spacecraft's first ``upto[craft]`` passes in time order."""
    for craft, names in ORDER.items():
        (target / craft).mkdir(parents=True, exist_ok=True)
        keep = set(names[:upto[craft]]) | {'calibration.yaml'}
        for entry in (folder / craft).iterdir():
            if entry.name in keep and not (target / craft / entry.name).exists():
                shutil.copy(entry, target / craft / entry.name)


def _key(event):
    return json.dumps(event.to_json(), sort_keys=True)


def _runs(folder, client, tmp_path, steps):
    """Run the archive grown by ``steps`` (spacecraft -> passes) with one state folder."""
    grown, kept = tmp_path / 'grown', tmp_path / 'state'
    results = []
    for upto in steps:
        _grow(folder, grown, upto)
        results.append(run_archive(grown, client=client, state_dir=kept))
        results[-1].commit()
    return results


def _check_adds_up(results, reference):
    last = results[-1]
    for craft, events in reference.items():
        assert events_of(last, craft) == events, craft
    current = history.current(last.history)
    kinds = {}
    for h in current:
        key = (h.spacecraft, h.event.component, h.event.index, h.event.revision)
        assert kinds.setdefault(key, h.event.kind) == h.event.kind, key
    # Every run's new events are in the last history, unchanged, with that run's number.
    for result in results:
        mine = {_key(h.event) for h in result.history if h.run == result.run}
        assert mine <= {_key(h.event) for h in last.history if h.run == result.run}


def test_daily_runs_equal_the_full_run(archive, client, tmp_path):
    folder, reference = archive
    steps = [{'sat-a': 2, 'sat-b': 1}, {'sat-a': 3, 'sat-b': 2}, {'sat-a': 4, 'sat-b': 3}]
    results = _runs(folder, client, tmp_path, steps)
    _check_adds_up(results, reference)
    superseded = [h for h in results[-1].history if h.superseded]
    assert superseded and all(h.end_of_run and h.run < results[-1].run for h in superseded)
    rows = results[-1].rows()
    assert any(r['new'] for r in rows) and any(not r['new'] for r in rows)
    assert all(r['superseded'] == (r['end_of_run'] and r['run'] < results[-1].run)
               for r in rows if r['spacecraft'] == 'sat-a')
    # The trend covers each wheel's life: earlier passes' rows come from the state.
    full = run_archive(folder, client=client)
    assert json.dumps([r.fields() for r in results[-1].trend]) == json.dumps(
        [r.fields() for r in full.trend])
    # And so do the fitted trends, each from its wheel's confirmed step (``since_s``).
    assert json.dumps(results[-1].trends) == json.dumps(full.trends)
    assert any(t['since_s'] is not None for t in full.trends)
    # Nothing new: said so, exit 0 if everything else is fine, and the answer kept.
    again = run_archive(tmp_path / 'grown', client=client, state_dir=tmp_path / 'state')
    assert again.new_passes == 0 and again.already_processed == 7
    assert [h.event for h in history.current(again.history)] == \
        [h.event for h in history.current(results[-1].history)]


@settings(max_examples=4, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(a=st.lists(st.integers(1, 4), min_size=1, max_size=3),
       b=st.lists(st.integers(1, 3), min_size=1, max_size=3))
def test_any_split_into_runs_adds_up(archive, client, tmp_path_factory, a, b):
    folder, reference = archive
    a, b = sorted(a) + [4], sorted(b) + [3]
    steps = [{'sat-a': a[min(i, len(a) - 1)], 'sat-b': b[min(i, len(b) - 1)]}
             for i in range(max(len(a), len(b)))]
    _check_adds_up(_runs(folder, client, tmp_path_factory.mktemp('split'), steps),
                   reference)


def test_late_pass_and_no_new_pass(archive, tmp_path, capsys):
    folder, _ = archive
    grown, kept, out = tmp_path / 'grown', tmp_path / 'state', tmp_path / 'out'
    _grow(folder, grown, {'sat-a': 4, 'sat-b': 1})
    shutil.move(grown / 'sat-a' / 'pass_z.csv', tmp_path / 'pass_z.csv')
    assert main(['fleet', str(grown), '-o', str(out), '--state', str(kept),
                 '--workers', '1']) in (0, 1)
    shutil.move(tmp_path / 'pass_z.csv', grown / 'sat-a' / 'pass_z.csv')   # arrives late
    code = main(['fleet', str(grown), '-o', str(out), '--state', str(kept), '--workers', '1'])
    printed = capsys.readouterr().out
    summary = json.loads((out / 'summary.json').read_text())['spacecraft']['sat-a']
    assert 'pass_z.csv' in summary['late'] and 'late' in summary['not_examined'][
        'pass pass_z.csv']
    assert code == 3 and 'not examined: sat-a pass pass_z.csv: late' in printed
    assert ('not calibrated (no calibration.yaml: friction tested without a nominal model, '
            'trends in absolute levels): sat-a\n') in printed          # sat-b is calibrated
    assert 'changes tested at false-alarm rate r = 3e-06 per test (parameters: ' in printed
    (grown / 'sat-a' / 'pass_z.csv').unlink()
    assert main(['fleet', str(grown), '-o', str(out), '--state', str(kept),
                 '--workers', '1']) in (0, 1)
    assert 'no new passes; 4 already processed' in capsys.readouterr().out


def test_a_state_of_other_parameters_is_refused_naming_the_file(archive, tmp_path, capsys):
    """A state made at detect's parameters, then a run at the fleet's own: refused (exit 2)."""
    from rwa_monitor import paths
    folder, _ = archive
    kept = tmp_path / 'state'
    assert main(['fleet', str(folder), '-o', str(tmp_path / 'one'), '--state', str(kept),
                 '--workers', '1', '--config', str(paths.config_file())]) in (0, 1, 3)
    capsys.readouterr()
    code = main(['fleet', str(folder), '-o', str(tmp_path / 'two'), '--state', str(kept),
                 '--workers', '1'])
    err = capsys.readouterr().err
    assert code == 2 and 'saved with other parameters' in err, err
    assert err.rstrip().endswith('fleet.yaml'), err


def test_the_printed_line_counts_current_and_superseded_events():
    from rwa_monitor.cli.cmd_fleet import _history
    assert _history({'events': 2, 'superseded': 1}) == \
        '2 current events in the history, 1 superseded by later revisions'
    assert _history({'events': 3, 'superseded': 0}) == '3 current events in the history'


def test_a_history_read_back_is_written_again_byte_for_byte():
    from rwa_monitor.core.events import AnomalyEvent
    events = [AnomalyEvent('llr', 'rw1', kind, 10.0 * i, i, 12.0 * i, i + 2, 1e-9, 0,
                           {'final': i == 2, 'z_dry': float('inf')})
              for i, kind in enumerate(('dry', 'undecided', 'both'), start=1)]
    first = (history.entries('sc1', events[:2], 1)
             + history.entries('sc1', events[2:], 1, end_of_run=True))
    data = history.to_parquet(first)
    back = history.from_parquet(data)
    assert back == first and all(h.event_json for h in back)
    assert history.to_parquet(back) == data
    moved = history.supersede(back, ['sc1'])
    assert [h.superseded for h in moved] == [False, False, True]
    fresh = [history.Entry(h.spacecraft, h.event, h.run, h.end_of_run, h.superseded)
             for h in moved]
    assert history.to_parquet(moved) == history.to_parquet(fresh)
