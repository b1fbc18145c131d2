"""A step reads its passes a block at a time: the chain is that of a pass-by-pass feed."""

from __future__ import annotations

import pathlib
import pickle

from fleet_archive import CUTS_A, rows, spacecraft_a, write_passes
import numpy as np
import pytest

from rwa_monitor.fleet import chain as chain_module
from rwa_monitor.fleet.archive import PassFile, read_pass
from rwa_monitor.fleet.chain import SpacecraftSpec, step
from rwa_monitor.fleet.records import Chain
from rwa_monitor.pipelines.llr import DEFAULTS
from rwa_monitor.pipelines.vsadc import DEFAULTS as VSADC_DEFAULTS
from rwa_monitor.telemetry import Telemetry, write_telemetry


@pytest.fixture(scope='module')
def passes(tmp_path_factory) -> list[PassFile]:
    """Return spacecraft A's passes, an unreadable one and one without rw1 and the gyro.

    In time order; A's passes hold an overlap, a gap, a gyro drift and a dry step.
    """
    root = tmp_path_factory.mktemp('blocks')
    tele = spacecraft_a(root)
    write_passes(root / 'sat-a', tele, CUTS_A)
    folder = root / 'sat-a'
    part = rows(tele, 40000, 43000).columns()          # 500 s after the last pass
    part['time'] = part['time'] + 1000.0
    write_telemetry(folder / 'no_rw1.csv', Telemetry.from_columns(
        {k: v for k, v in part.items() if k in ('time', 'rw2_speed', 'rw2_friction')}))
    (folder / 'broken.parquet').write_bytes(b'PAR1 not a parquet file')
    found = []
    for name in [c[2] for c in CUTS_A[:2]] + ['broken.parquet'] + [c[2] for c in CUTS_A[2:]] \
            + ['no_rw1.csv']:
        path = folder / name
        first = read_pass(str(path))
        found.append(PassFile(name, str(path), path.stat().st_size,
                              float(first.time[0]) if isinstance(first, Telemetry)
                              else 0.0, ()))
    return found


def _spec() -> SpacecraftSpec:
    return SpacecraftSpec('sat-a', ('rw1', 'rw2'), True, dict(DEFAULTS),
                          dict(VSADC_DEFAULTS))


def _run(monkeypatch, block_bytes: int, passes: list[PassFile], split: int) -> Chain:
    monkeypatch.setattr(chain_module, 'BLOCK_BYTES', block_bytes)
    chain = Chain(-np.inf, {})
    for group in (passes[:split], passes[split:]):
        chain = step(_spec(), chain, group, group is not passes[:split] or not passes[split:])
    return chain


@pytest.mark.parametrize('block_bytes', [200_000, 1 << 40])
@pytest.mark.parametrize('split', [3, 6])
def test_blocks_give_the_chain_of_a_pass_by_pass_feed(monkeypatch, passes, block_bytes,
                                                      split):
    """Events (in order), trend rows, pass facts, states and end-of-run events agree."""
    reference = _run(monkeypatch, 1, passes, split)
    blocked = _run(monkeypatch, block_bytes, passes, split)
    assert len(reference.events) >= 2      # the drift and the step are found
    assert {e.component for e in reference.events} >= {'rw2', 'gyro_y'}
    assert blocked.events == reference.events
    assert blocked.end_of_run == reference.end_of_run
    assert blocked.trend == reference.trend
    assert blocked.passes == reference.passes
    assert blocked.facts == reference.facts
    assert blocked.last_time == reference.last_time
    assert pickle.dumps(blocked.states) == pickle.dumps(reference.states)
    by_name = {f.name: f for f in blocked.passes}
    assert by_name['broken.parquet'].error.startswith('unreadable')
    assert by_name['no_rw1.csv'].component_errors == {
        'rw1': 'no rw1_speed and rw1_friction columns',
        'gyro': 'no gyro_x/y/z and q_x/y/z/w columns'}
    assert by_name['pass_b.parquet'].rows_dropped == 100


def test_blocks_are_runs_of_consecutive_passes_of_about_the_size(passes):
    """Each block ends at the pass that reaches the size; every pass is in one block."""
    blocks = list(chain_module._blocks(passes, 300_000))
    assert [p for b in blocks for p in b] == list(passes)
    for block in blocks[:-1]:
        assert sum(p.size for p in block) >= 300_000
        assert sum(p.size for p in block[:-1]) < 300_000
    assert [len(b) for b in chain_module._blocks(passes, 1)] == [1] * len(passes)
    assert list(chain_module._blocks([], 1)) == []
    assert pathlib.Path(passes[0].path).exists()
