"""The fleet's cluster started in a thread and closed in one (fleet/cluster.py ClusterStart).

A start that fails raises its error where the client is asked for; leaving the block
closes the cluster and waits for it, whether the client was used, never asked for, or
the run failed; a released cluster gives no client. The worker processes are the client
process's children, so ``multiprocessing.active_children`` shows whether they outlived
the block.
"""

import multiprocessing

from fleet_archive import events_of, make_archive, references
import pytest

from rwa_monitor.exceptions import ConfigError
from rwa_monitor.fleet.cluster import ClusterStart
from rwa_monitor.fleet.engine import run_archive


def _workers_alive() -> int:
    return len(multiprocessing.active_children())


def test_a_start_that_fails_raises_where_the_client_is_asked_for():
    with ClusterStart(workers=0) as cluster:
        with pytest.raises(ConfigError, match='--workers must be at least 1'):
            cluster.client()


def test_leaving_the_block_closes_a_cluster_never_asked_for():
    before = _workers_alive()
    with ClusterStart(workers=1):
        pass
    assert _workers_alive() == before


def test_a_released_cluster_closes_and_gives_no_client():
    before = _workers_alive()
    with ClusterStart(workers=1) as cluster:
        client = cluster.client()
        assert client.submit(sum, [1, 2]).result() == 3
        assert _workers_alive() == before + 1
        cluster.release()
        with pytest.raises(RuntimeError, match='released'):
            cluster.client()
    assert client.status == 'closed'
    assert _workers_alive() == before
    cluster.close()                     # a second close does nothing


def test_a_run_with_its_own_cluster_gives_the_events_and_leaves_no_worker(tmp_path):
    joined = make_archive(tmp_path / 'archive', tmp_path / 'work')
    before = _workers_alive()
    result = run_archive(tmp_path / 'archive', workers=1)
    assert _workers_alive() == before
    for craft, expected in references(tmp_path / 'archive', joined).items():
        assert events_of(result, craft) == expected


def test_a_run_that_fails_before_the_plan_closes_its_cluster(tmp_path):
    (tmp_path / 'archive' / 'sc1').mkdir(parents=True)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('fleet:\n  ros__parameters:\n    dry_limit: -1.0\n')
    before = _workers_alive()
    with pytest.raises(ConfigError, match='dry_limit'):
        run_archive(tmp_path / 'archive', workers=1, config=bad)
    assert _workers_alive() == before


def _loaded() -> tuple[bool, bool]:
    """Return whether this process has the engine imported and every kernel compiled."""
    import sys
    from rwa_monitor.core import jit
    return ('rwa_monitor.fleet.chain' in sys.modules,
            bool(jit._lazy) and all('_compile_for_args' not in vars(d) for d in jit._lazy))


def test_local_workers_start_with_the_engine_imported_and_the_kernels_loaded():
    # They are forks of the server that loaded them once (fleet/worker_start.py); a
    # worker spawned instead would have neither before its first task.
    with ClusterStart(workers=2) as cluster:
        found = cluster.client().run(_loaded)
    assert list(found.values()) == [(True, True), (True, True)]


def test_the_folders_are_listed_by_the_workers_or_here_with_the_same_spacecraft(tmp_path):
    from rwa_monitor.fleet import archive
    from rwa_monitor.fleet.engine import _Listing
    make_archive(tmp_path / 'archive', tmp_path / 'work')
    folders = archive.spacecraft_folders(tmp_path / 'archive')
    expected = archive.list_archive(tmp_path / 'archive')
    with ClusterStart(workers=1) as cluster:
        client = cluster.client()
        submitted = []
        cluster.when_started(submitted.append)             # started: called at once
        remote = _Listing(cluster, folders)
        assert submitted == [client] and remote._futures is not None
        assert remote.result() == expected
    with ClusterStart(workers=0) as failed:                 # never starts: listed here
        here = _Listing(failed, folders)
        assert here.result() == expected and here._futures is None
    with ClusterStart(workers=1) as starting:               # asked for before the start
        early = _Listing(starting, folders)
        found = early.result()
        assert found == expected
        starting.client()
    assert len(expected) == 2 and all(c.candidates for c in expected)


def test_a_folder_the_workers_cannot_list_is_a_clear_error(tmp_path):
    from rwa_monitor.fleet.engine import _Listing
    with ClusterStart(workers=1) as cluster:
        listing = _Listing(cluster.client(), [str(tmp_path / 'elsewhere' / 'sc1')])
        with pytest.raises(ConfigError, match='workers cannot list the archive: .*sc1'):
            listing.result()
