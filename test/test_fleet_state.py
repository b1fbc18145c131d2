"""The fleet's state folder (format 2): checked whole, never trusted beyond its folder.

A state that was edited, truncated, swapped, pointed outside its folder or replaced by a
FIFO is refused with a StateError naming the file (exit 2 from the command) in every
case; the unedited state resumes exactly; a commit cut short at any point leaves the old
or the new state whole, and only files the fleet wrote are removed.
"""

import json
import os
import shutil

from distributed import Client, LocalCluster
from fleet_archive import events_of, rows
from hypothesis import given, HealthCheck, settings, strategies as st
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.fleet import state
from rwa_monitor.fleet.engine import run_archive
from rwa_monitor.sim.friction import parse_anomaly, simulate_friction
from rwa_monitor.telemetry import write_telemetry


@pytest.fixture(scope='module')
def client():
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        yield c


@pytest.fixture(scope='module')
def saved(tmp_path_factory, client):
    """Return (archive, state folder after the first two passes, full run's events)."""
    root = tmp_path_factory.mktemp('state')
    tele = simulate_friction(duration_s=1500, rate_hz=10, wheels=('rw1', 'rw2'), seed=61,
                             anomalies=[parse_anomaly('rw1:dry:1000:3e-4')])
    craft = root / 'archive' / 'sat'
    craft.mkdir(parents=True)
    cuts = [(0, 4000, 'p1.csv'), (4000, 8000, 'p2.csv'), (8000, 15000, 'p3.csv')]
    for first, end, name in cuts[:2]:
        write_telemetry(craft / name, rows(tele, first, end))
    kept = root / 'state'
    run_archive(root / 'archive', client=client, state_dir=kept).commit()
    write_telemetry(craft / cuts[2][2], rows(tele, cuts[2][0], cuts[2][1]))
    full = run_archive(root / 'archive', client=client)
    return root / 'archive', kept, events_of(full, 'sat')


def _copy(kept, tmp):
    target = tmp / 'state'
    shutil.copytree(kept, target, symlinks=True)
    return target


def _generation(folder):
    return folder / json.loads((folder / state.POINTER).read_text())['generation']


def _rehash(folder):
    """Recompute the pointer's hash: an edit by someone who knows the format."""
    gen = _generation(folder)
    blobs = {name: (gen / name).read_bytes() for name in state.FILES}
    pointer = json.loads((folder / state.POINTER).read_text())
    pointer['sha256'] = state._digest(blobs)
    (folder / state.POINTER).write_text(json.dumps(pointer))


def _edit_manifest(folder, edit):
    path = _generation(folder) / 'state.json'
    document = json.loads(path.read_text())
    edit(document)
    path.write_text(json.dumps(document))
    _rehash(folder)


def _detector(document):
    return document['spacecraft']['sat']['components']['rw1']['wheel']['detector']


def test_unedited_state_resumes_exactly(saved, client, tmp_path):
    archive, kept, full = saved
    result = run_archive(archive, client=client, state_dir=_copy(kept, tmp_path))
    assert events_of(result, 'sat') == full


def _flip(path):
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))


def _outside(tmp):
    target = tmp / 'elsewhere.json'
    target.write_text('{}')
    return target


CASES = {
    'pointer truncated': lambda f, t: (f / state.POINTER).write_text('{"format": "rwa_'),
    'pointer foreign': lambda f, t: (f / state.POINTER).write_text('{"format": "x"}'),
    'pointer version': lambda f, t: (f / state.POINTER).write_text(json.dumps(
        {**json.loads((f / state.POINTER).read_text()), 'version': 1})),
    'generation outside': lambda f, t: (f / state.POINTER).write_text(json.dumps(
        {**json.loads((f / state.POINTER).read_text()), 'generation': '../state2'})),
    'generation missing': lambda f, t: shutil.rmtree(_generation(f)),
    'generation a link': lambda f, t: (shutil.move(_generation(f), t / 'moved'),
                                       os.symlink(t / 'moved', _generation(f))),
    'pointer a FIFO': lambda f, t: ((f / state.POINTER).unlink(),
                                    os.mkfifo(f / state.POINTER)),
    'arrays a FIFO': lambda f, t: ((_generation(f) / 'arrays.npz').unlink(),
                                   os.mkfifo(_generation(f) / 'arrays.npz')),
    'manifest a link outside': lambda f, t: ((_generation(f) / 'state.json').unlink(),
                                             os.symlink(_outside(t),
                                                        _generation(f) / 'state.json')),
    'history a folder': lambda f, t: ((_generation(f) / 'history.parquet').unlink(),
                                      (_generation(f) / 'history.parquet').mkdir()),
    'arrays truncated': lambda f, t: (_generation(f) / 'arrays.npz').write_bytes(
        (_generation(f) / 'arrays.npz').read_bytes()[:100]),
    'manifest byte flipped': lambda f, t: _flip(_generation(f) / 'state.json'),
    'trend byte flipped': lambda f, t: _flip(_generation(f) / 'trend.parquet'),
    'files swapped': lambda f, t: (
        os.rename(_generation(f) / 'state.json', t / 'x'),
        os.rename(_generation(f) / 'arrays.npz', _generation(f) / 'state.json'),
        os.rename(t / 'x', _generation(f) / 'arrays.npz')),
    'detector field added': lambda f, t: _edit_manifest(
        f, lambda d: _detector(d).__setitem__('extra', 1)),
    'record version': lambda f, t: _edit_manifest(
        f, lambda d: d['records'].__setitem__('LLRState', 99)),
    'fingerprint': lambda f, t: _edit_manifest(
        f, lambda d: d['spacecraft']['sat'].__setitem__('fingerprint', '0' * 64)),
    'unknown field': lambda f, t: _edit_manifest(
        f, lambda d: d['spacecraft']['sat'].__setitem__('extra', 1)),
    'wrong type': lambda f, t: _edit_manifest(
        f, lambda d: d['spacecraft']['sat'].__setitem__('last_time', 'soon')),
    'pass log one name short': lambda f, t: _edit_manifest(
        f, lambda d: d['spacecraft']['sat']['passes']['names'].pop()),
    'pass name not a string': lambda f, t: _edit_manifest(
        f, lambda d: d['spacecraft']['sat']['passes']['names'].__setitem__(0, 7)),
    'spacecraft renamed': lambda f, t: _edit_manifest(
        f, lambda d: d['spacecraft'].__setitem__('other', d['spacecraft'].pop('sat'))),
}


@pytest.mark.parametrize('case', sorted(CASES))
def test_a_deviating_state_is_refused_naming_the_file(saved, client, tmp_path, case):
    archive, kept, _ = saved
    folder = _copy(kept, tmp_path)
    CASES[case](folder, tmp_path)
    with pytest.raises(state.StateError) as caught:
        run_archive(archive, client=client, state_dir=folder)
    assert str(folder) in str(caught.value) or 'state of sat' in str(caught.value)


def test_the_command_exits_2_with_one_line(saved, tmp_path, capsys):
    archive, kept, _ = saved
    folder = _copy(kept, tmp_path)
    CASES['arrays a FIFO'](folder, tmp_path)
    code = main(['fleet', str(archive), '-o', str(tmp_path / 'out'), '--state', str(folder),
                 '--workers', '1'])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and 'arrays.npz' in err[0]


@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(file=st.sampled_from(state.FILES + (state.POINTER,)), where=st.floats(0.0, 1.0),
       byte=st.integers(0, 255), cut=st.booleans())
def test_random_edits_and_truncations_are_refused(saved, tmp_path_factory, file, where,
                                                  byte, cut):
    _, kept, _ = saved
    folder = _copy(kept, tmp_path_factory.mktemp('fuzz'))
    path = folder / file if file == state.POINTER else _generation(folder) / file
    data = bytearray(path.read_bytes())
    at = min(int(where * len(data)), len(data) - 1)
    if cut:
        data = data[:at]
    elif data[at] == byte:
        return
    else:
        data[at] = byte
    if file == state.POINTER and _same_json(path.read_bytes(), bytes(data)):
        return      # white space of the pointer (its last newline cut): the same document
    path.write_bytes(bytes(data))
    try:
        state.load(folder)
    except state.StateError:
        return
    pytest.fail(f'an edit of {file} at {at} was accepted')


def _same_json(before: bytes, after: bytes) -> bool:
    try:
        return json.loads(before) == json.loads(after)
    except ValueError:
        return False


def test_a_commit_cut_short_leaves_a_whole_state(saved, client, tmp_path, monkeypatch):
    archive, kept, full = saved
    before = _copy(kept, tmp_path / 'a')
    result = run_archive(archive, client=client, state_dir=before)
    calls = {'n': 0}
    real = {'replace': os.replace, 'write': state._write, 'text': state.write_text_atomic}

    def failing(name):
        def call(*args, **kwargs):
            calls['n'] += 1
            if calls['n'] == limit:
                raise OSError(28, 'No space left on device')
            return real[name](*args, **kwargs)
        return call

    for limit in range(1, 8):
        folder = _copy(kept, tmp_path / f'cut{limit}')
        calls['n'] = 0
        monkeypatch.setattr(state.os, 'replace', failing('replace'))
        monkeypatch.setattr(state, '_write', failing('write'))
        monkeypatch.setattr(state, 'write_text_atomic', failing('text'))
        result.state_dir = folder
        try:
            result.commit()
        except state.StateError:
            pass
        monkeypatch.undo()
        loaded = state.load(folder)
        assert loaded is not None and loaded.generation in (1, 2)
        again = run_archive(archive, client=client, state_dir=folder)
        assert events_of(again, 'sat') == full


def test_commit_removes_only_what_it_wrote(saved, client, tmp_path):
    archive, kept, _ = saved
    folder = _copy(kept, tmp_path)
    old = _generation(folder)
    mine = [folder / 'sat.mybackup.npz', folder / 'notes.txt', old / 'notes.txt']
    for path in mine:
        path.write_text('user file')
    run_archive(archive, client=client, state_dir=folder).commit()
    assert all(path.read_text() == 'user file' for path in mine)
    assert _generation(folder) != old and old.is_dir()     # kept: it holds a user file
    assert sorted(p.name for p in old.iterdir()) == ['notes.txt']


def test_a_second_run_on_a_state_in_use_is_refused_naming_the_holder(
        saved, tmp_path, capsys):
    archive, kept, full = saved
    folder = _copy(kept, tmp_path)
    before = (folder / state.POINTER).read_bytes()
    args = ['fleet', str(archive), '-o', str(tmp_path / 'out'), '--state', str(folder),
            '--workers', '1']
    with state.locked(folder):                   # another run holds it
        assert main(args) == 2
    assert f'in use by another fleet run (process {os.getpid()})' in capsys.readouterr().err
    assert (folder / state.POINTER).read_bytes() == before
    assert main(args) in (0, 1)                  # released: the run goes on
    assert (folder / state.POINTER).read_bytes() != before


def test_a_lock_that_is_a_link_is_refused(tmp_path):
    folder = tmp_path / 'state'
    folder.mkdir()
    (folder / state.LOCK).symlink_to(tmp_path / 'elsewhere')
    with pytest.raises(state.StateError, match='cannot open the lock'):
        with state.locked(folder):
            pass
    assert not (tmp_path / 'elsewhere').exists()


def test_a_commit_after_another_run_moved_the_state_on_is_refused(saved, client, tmp_path):
    """Two runs that both loaded generation N: the second commit would undo the first's."""
    archive, kept, full = saved
    folder = _copy(kept, tmp_path)
    first = run_archive(archive, client=client, state_dir=folder)
    second = run_archive(archive, client=client, state_dir=folder)
    first.commit()
    moved = (folder / state.POINTER).read_bytes()
    with pytest.raises(state.StateError, match='another run moved the state on'):
        second.commit()
    assert (folder / state.POINTER).read_bytes() == moved
    assert events_of(run_archive(archive, client=client, state_dir=folder), 'sat') == full


def test_the_pass_log_keeps_passes_in_order_as_columns():
    from rwa_monitor.core.records import decode, encode, RecordError
    from rwa_monitor.fleet.records import PassLog, PassRecord
    passes = [PassRecord('b.parquet', 10, 5.0, 6.5), PassRecord('a.parquet', 12, 7.0, 8.0)]
    log = PassLog().plus(passes[:1]).plus(passes[1:]).plus([])
    assert list(log) == passes and log[-1] == passes[1] and len(log) == 2
    assert log.keys() == {('b.parquet', 10), ('a.parquet', 12)}
    tree, arrays = encode(log)
    assert tree['names'] == ['b.parquet', 'a.parquet'] and arrays['PassLog.sizes'].dtype == 'int64'
    assert decode(PassLog, json.loads(json.dumps(tree)), arrays) == log
    with pytest.raises(RecordError, match='lengths 1, 2, 2, 2'):
        decode(PassLog, {**tree, 'names': ['b.parquet']}, arrays)
