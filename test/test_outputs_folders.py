"""Folder outputs (issue 24, item 1): built beside, swapped in whole, never over others' files.

On main 09648a8: ``simulate -o DIR`` deleted every other file of a folder holding a
metadata.yaml, ``calibrate`` and ``identify`` wrote into folders holding anything, and a
``calibrate`` failing mid-way left its folder half old, half new.
"""

import hashlib
import os
import pathlib

import numpy as np
import pytest

from rwa_monitor.cli.main import main
from rwa_monitor.exceptions import OutputError
from rwa_monitor.sim.undeclared import simulate_undeclared
from rwa_monitor.telemetry import read_telemetry, Telemetry, Wheel, write_telemetry


def digest(folder: pathlib.Path) -> dict[str, str]:
    """Return relative path -> sha256 of every file under ``folder``."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob('*')) if p.is_file()}


@pytest.fixture(scope='module')
def commissioning(tmp_path_factory) -> pathlib.Path:
    path = tmp_path_factory.mktemp('data') / 'fault_free.csv'
    write_telemetry(path, simulate_undeclared('stribeck', n=4000, seed=1))
    return path


def test_simulate_refuses_a_recording_folder_holding_other_files(tmp_path):
    out = tmp_path / 'bag'
    assert main(['simulate', 'friction', '--seconds', '20', '--wheels', '1',
                 '-o', str(out)]) == 0
    (out / 'notes.txt').write_text('mine')
    before = digest(out)
    assert main(['simulate', 'friction', '--seconds', '30', '--wheels', '1',
                 '-o', str(out)]) == 2
    assert digest(out) == before
    os.remove(out / 'notes.txt')
    assert main(['simulate', 'friction', '--seconds', '30', '--wheels', '1',
                 '-o', str(out)]) == 0
    assert len(read_telemetry(out)) == 300
    assert sorted(p.name for p in tmp_path.iterdir()) == ['bag']   # no temporary left


def test_calibrate_refuses_a_folder_holding_other_files(tmp_path, commissioning, capsys):
    out = tmp_path / 'cal'
    out.mkdir()
    (out / 'thesis.tex').write_text('mine')
    assert main(['calibrate', str(commissioning), '-o', str(out)]) == 2
    assert 'thesis.tex' in capsys.readouterr().err
    assert digest(out) == {'thesis.tex': hashlib.sha256(b'mine').hexdigest()}


def test_calibrate_failing_mid_way_leaves_the_previous_folder_byte_identical(
        tmp_path, commissioning, monkeypatch):
    out = tmp_path / 'cal'
    assert main(['calibrate', str(commissioning), '-o', str(out)]) == 0
    before = digest(out)
    other = tmp_path / 'other.csv'   # another record: its calibration.yaml differs
    write_telemetry(other, simulate_undeclared('stribeck', n=4000, seed=2))
    from rwa_monitor.pipelines import calibrated

    def broken_plot(*args, **kwargs):
        raise OutputError('disk full (simulated)')
    monkeypatch.setattr(calibrated, '_plot', broken_plot)
    assert main(['calibrate', str(other), '-o', str(out)]) == 2
    assert digest(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ['cal', 'other.csv']


def test_calibrate_through_a_link_replaces_the_target_and_keeps_the_link(
        tmp_path, commissioning):
    real = tmp_path / 'cal-2026'
    link = tmp_path / 'cal'
    real.mkdir()
    link.symlink_to(real)
    assert main(['calibrate', str(commissioning), '-o', str(link)]) == 0
    assert link.is_symlink()
    assert (real / 'calibration.yaml').is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['cal', 'cal-2026']


def test_identify_refuses_a_folder_holding_other_files(tmp_path, commissioning):
    out = tmp_path / 'id'
    out.mkdir()
    (out / 'keep').mkdir()
    (out / 'keep' / 'x.txt').write_text('mine')
    assert main(['identify', str(commissioning), '-o', str(out)]) == 2
    assert digest(out) == {'keep/x.txt': hashlib.sha256(b'mine').hexdigest()}


def test_identify_replaces_its_own_previous_output_whole(tmp_path, commissioning):
    out = tmp_path / 'id'
    assert main(['identify', str(commissioning), '-o', str(out)]) == 0
    (out / 'residuals_after.png').unlink()           # an older, partial output of identify
    assert main(['identify', str(commissioning), '-o', str(out)]) == 0
    assert (out / 'residuals_after.png').is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ['id']


def test_folder_output_swaps_whole_or_not_at_all(tmp_path):
    from rwa_monitor.telemetry.atomic import FolderOutput
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'a.txt').write_text('old')
    with pytest.raises(RuntimeError):
        with FolderOutput(out, ['*.txt']) as work:
            (work / 'a.txt').write_text('new')
            raise RuntimeError('interrupted')
    assert (out / 'a.txt').read_text() == 'old'
    with FolderOutput(out, ['*.txt']) as work:
        (work / 'b.txt').write_text('new')
    assert digest(out) == {'b.txt': hashlib.sha256(b'new').hexdigest()}
    assert sorted(p.name for p in tmp_path.iterdir()) == ['out']
    (tmp_path / 'file').write_text('x')
    with pytest.raises(OutputError, match='not a folder'):
        FolderOutput(tmp_path / 'file', ['*'])


def test_recording_writer_refuses_a_folder_of_other_files(tmp_path):
    from rwa_monitor.telemetry.rosbag_io import RecordingWriter
    out = tmp_path / 'review'
    out.mkdir()
    (out / 'metadata.yaml').write_text('x')
    (out / 'photo.jpg').write_bytes(b'\xff')
    with pytest.raises(OutputError, match='photo.jpg'):
        RecordingWriter(out)
    write_telemetry(tmp_path / 'ok', Telemetry(
        time=np.array([0.0, 1.0]), wheels={'rw1': Wheel(np.array([1.0, 2.0]))}))
    assert sorted(p.name for p in (tmp_path / 'ok').iterdir()) == ['metadata.yaml', 'ok.mcap']


def test_owned_patterns_match_per_level():
    from rwa_monitor.telemetry.atomic import foreign_files
    import tempfile
    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)
        (root / 'rw1').mkdir()
        (root / 'rw1' / 'report.json').write_text('{}')
        (root / 'wheels.md').write_text('')
        owned = ['wheels.md', '*/', '*/report.json']
        assert foreign_files(root, owned) == []
        (root / 'rw1' / 'deep').mkdir()
        (root / 'rw1' / 'notes.txt').write_text('')
        assert foreign_files(root, owned) == ['rw1/deep/', 'rw1/notes.txt']
        assert foreign_files(root, ['*']) == ['rw1/']
