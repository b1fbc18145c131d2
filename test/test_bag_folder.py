"""A rosbag2 writer replaces a folder only when its metadata says it is a recording (issue 24)."""

import hashlib
import sqlite3

import numpy as np
import pytest
import yaml

from rwa_monitor.exceptions import OutputError
from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel, write_telemetry
from rwa_monitor.telemetry.recording_folder import listed_files, recording_files
from rwa_monitor.telemetry.rosbag_io import RecordingWriter


def _telemetry(n=5):
    return Telemetry(time=np.arange(float(n)), wheels={'rw1': Wheel(np.ones(n), np.zeros(n))})


def _digest(folder):
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in folder.iterdir()}


def _metadata(files, **extra):
    info = {'version': 9, 'storage_identifier': 'mcap', 'relative_file_paths': files, **extra}
    return yaml.safe_dump({'rosbag2_bagfile_information': info})


def _user_database(path):
    with sqlite3.connect(path) as db:
        db.execute('create table notes (text)')
        db.execute("insert into notes values ('three years of work')")
    db.close()


@pytest.mark.parametrize('files', [
    {'data.db3': None},                                          # a user's SQLite database
    {'notes.mcap': b'my own capture'},
    {'metadata.yaml': b'title: my thesis\n', 'x.mcap': b'x'},    # metadata of another tool
    {'metadata.yaml': b'- [unclosed\n', 'x.mcap': b'x'},
    {'metadata.yaml': _metadata(['*.mcap']).encode(), 'mine.mcap': b'x'},    # a pattern
    {'metadata.yaml': _metadata(['../x.mcap']).encode(), 'x.mcap': b'x'},
    {'metadata.yaml': _metadata(['thesis.tex']).encode(), 'thesis.tex': b'x'},
    {'metadata.yaml': _metadata('a.mcap').encode(), 'a.mcap': b'x'},     # not a list
])
@pytest.mark.parametrize('writer', ['write_telemetry', 'RecordingWriter'])
def test_a_folder_that_is_not_a_recording_of_ours_is_refused_untouched(tmp_path, files, writer):
    out = tmp_path / 'rec'
    out.mkdir()
    for name, data in files.items():
        if data is None:
            _user_database(out / name)
        else:
            (out / name).write_bytes(data)
    before = _digest(out)
    with pytest.raises(OutputError, match='not part of a rosbag2 recording'):
        if writer == 'write_telemetry':
            write_telemetry(out, _telemetry())
        else:
            RecordingWriter(out).close()
    assert _digest(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['rec']


def test_a_recording_is_replaced_even_renamed_but_not_with_an_unlisted_file(tmp_path):
    write_telemetry(tmp_path / 'first', _telemetry(8))
    out = tmp_path / 'renamed'
    (tmp_path / 'first').rename(out)            # its storage file keeps the first name
    assert sorted(p.name for p in out.iterdir()) == ['first.mcap', 'metadata.yaml']
    write_telemetry(out, _telemetry(4))
    assert len(read_telemetry(out)) == 4
    assert sorted(p.name for p in out.iterdir()) == ['metadata.yaml', 'renamed.mcap']
    (out / 'other.mcap').write_bytes(b'not listed')
    before = _digest(out)
    with pytest.raises(OutputError, match=r'\(other\.mcap\)'):
        write_telemetry(out, _telemetry(3))
    assert _digest(out) == before


def test_an_empty_folder_is_written_and_a_db3_recording_owns_its_side_files(tmp_path):
    (tmp_path / 'empty').mkdir()
    write_telemetry(tmp_path / 'empty', _telemetry())
    assert len(read_telemetry(tmp_path / 'empty')) == 5
    assert recording_files(tmp_path / 'nothing') == ((), 'no metadata.yaml')
    owned, why = recording_files(_folder(tmp_path, _metadata(['b[1].db3'])))
    assert why == '' and owned == ('metadata.yaml', 'b[[]1].db3', 'b[[]1].db3-wal',
                                   'b[[]1].db3-shm', 'b[[]1].db3-journal')


def _folder(tmp_path, metadata):
    folder = tmp_path / 'bag'
    folder.mkdir()
    (folder / 'metadata.yaml').write_text(metadata)
    return folder


@pytest.mark.parametrize('document, reason', [
    (None, 'no rosbag2_bagfile_information'),
    ({'rosbag2_bagfile_information': {'relative_file_paths': []}}, 'no version'),
    ({'rosbag2_bagfile_information': {'version': 9, 'storage_identifier': 'mcap'}},
     'no relative_file_paths'),
    ({'rosbag2_bagfile_information': {'version': 9, 'storage_identifier': 'mcap',
                                      'relative_file_paths': ['sub/a.mcap']}}, 'sub/a.mcap'),
])
def test_what_is_not_rosbag2_metadata(document, reason):
    with pytest.raises(ValueError, match=reason):
        listed_files(document)
