"""Every reader, given arbitrary bytes or a damaged valid file, raises only its own errors.

Issue 24, item 7: CSV, MCAP, rosbag2 folder (metadata and storage), parameters YAML,
calibration, friction model, FSS classifier model and alarm journal. A reader may accept
a damaged file (a cut CSV is still a CSV) but may never raise anything but the package's
own errors (RwaMonitorError); the journal reader may never change a file it refuses.
"""

import contextlib
import pathlib
import tempfile

from fuzz_inputs import garbage, mutated, READER_SETTINGS, seeds
from hypothesis import given, strategies as st
import pytest

from rwa_monitor.core.schema import SCHEMAS
from rwa_monitor.exceptions import RwaMonitorError
from rwa_monitor.telemetry import read_telemetry
from rwa_monitor.telemetry.alarms import AlarmStore
from rwa_monitor.telemetry.calibration_file import load, load_gyro_calibration
from rwa_monitor.telemetry.parameters_file import block_values, read_parameters_file

SEEDS = seeds(pathlib.Path(tempfile.mkdtemp(prefix='rwa-fuzz-seeds-')))


def damaged(kind: str) -> st.SearchStrategy[bytes]:
    """Arbitrary bytes, or a damaged copy of the valid file of ``kind``."""
    return st.one_of(garbage, mutated(SEEDS[kind]))


@contextlib.contextmanager
def file_of(data: bytes, name: str):
    with tempfile.TemporaryDirectory() as folder:
        path = pathlib.Path(folder) / name
        path.write_bytes(data)
        yield path


def only_own_errors(call) -> None:
    """Run ``call``; a package error is a refusal, anything else fails the test."""
    try:
        call()
    except RwaMonitorError:
        pass


@READER_SETTINGS
@given(damaged('csv'))
def test_csv_reader(data):
    with file_of(data, 'in.csv') as path:
        only_own_errors(lambda: read_telemetry(path))


@READER_SETTINGS
@given(damaged('mcap'))
def test_mcap_reader(data):
    with file_of(data, 'in.mcap') as path:
        only_own_errors(lambda: read_telemetry(path))


@READER_SETTINGS
@given(st.one_of(damaged('metadata').map(lambda d: (d, SEEDS['bag_mcap'])),
                 damaged('bag_mcap').map(lambda d: (SEEDS['metadata'], d))))
def test_rosbag2_folder_reader(files):
    metadata, storage = files
    with tempfile.TemporaryDirectory() as folder:
        bag = pathlib.Path(folder) / 'seed_bag'
        bag.mkdir()
        (bag / 'metadata.yaml').write_bytes(metadata)
        (bag / 'seed_bag_0.mcap').write_bytes(storage)
        only_own_errors(lambda: read_telemetry(bag))


@READER_SETTINGS
@given(damaged('parameters'))
def test_parameters_reader(data):
    with file_of(data, 'params.yaml') as path:
        def read():
            document = read_parameters_file(path)
            for schema in SCHEMAS.values():
                block_values(document, schema, path)
        only_own_errors(read)


@READER_SETTINGS
@given(damaged('calibration'))
def test_calibration_reader(data):
    with file_of(data, 'calibration.yaml') as path:
        only_own_errors(lambda: load(path))
        only_own_errors(lambda: load_gyro_calibration(path))


@READER_SETTINGS
@given(damaged('friction_model'))
def test_friction_model_reader(data):
    from fuzz_inputs import small_telemetry
    from rwa_monitor.pipelines.llr import friction_model
    tele = small_telemetry(20)
    with file_of(data, 'friction_model.yaml') as path:
        only_own_errors(lambda: friction_model(str(path), tele))


@READER_SETTINGS
@given(damaged('fss_model'))
def test_fss_model_reader(data):
    from rwa_monitor.telemetry.fss_model import load_model
    with file_of(data, 'model.json') as path:
        only_own_errors(lambda: load_model(path))


@READER_SETTINGS
@given(damaged('journal'))
def test_journal_reader_never_raises_else_and_never_changes_what_it_refuses(data):
    with file_of(data, 'events.jsonl') as path:
        store = AlarmStore(path)
        try:
            store.load()
        except RwaMonitorError:
            assert path.read_bytes() == data


@pytest.mark.parametrize('kind', sorted(SEEDS))
def test_the_seeds_are_valid(kind):
    """The damaged files start from files every reader accepts."""
    with tempfile.TemporaryDirectory() as folder:
        folder = pathlib.Path(folder)
        if kind in ('csv', 'mcap'):
            path = folder / f'in.{kind}'
            path.write_bytes(SEEDS[kind])
            assert len(read_telemetry(path)) == 400
        elif kind == 'calibration':
            path = folder / 'c.yaml'
            path.write_bytes(SEEDS[kind])
            assert load(path)['wheels']
        elif kind == 'journal':
            path = folder / 'e.jsonl'
            path.write_bytes(SEEDS[kind])
            AlarmStore(path).load()
        elif kind == 'parameters':
            path = folder / 'p.yaml'
            path.write_bytes(SEEDS[kind])
            assert 'llr_detector' in read_parameters_file(path)


values = st.one_of(st.none(), st.booleans(), st.integers(), st.floats(), st.text(max_size=5),
                   st.lists(st.floats(), max_size=3), st.dictionaries(st.text(max_size=3),
                                                                      st.integers(), max_size=2))


@st.composite
def edited_document(draw, text: bytes):
    """Return the YAML document of ``text`` with one value anywhere replaced (a strategy)."""
    import yaml
    document = yaml.safe_load(text)
    node, parents = document, []
    while isinstance(node, (dict, list)) and node and draw(st.integers(0, 5)):
        key = draw(st.sampled_from(list(node) if isinstance(node, dict)
                                   else list(range(len(node)))))
        parents.append((node, key))
        node = node[key]
    if parents:
        holder, key = parents[-1]
        holder[key] = draw(values)
    return yaml.safe_dump(document).encode()


@READER_SETTINGS
@given(st.one_of(edited_document(SEEDS['calibration']).map(lambda d: ('calibration', d)),
                 edited_document(SEEDS['friction_model']).map(lambda d: ('model', d)),
                 edited_document(SEEDS['parameters']).map(lambda d: ('parameters', d))))
def test_yaml_readers_with_one_value_of_another_type(case):
    kind, data = case
    from fuzz_inputs import small_telemetry
    from rwa_monitor.pipelines.llr import friction_model
    with file_of(data, 'file.yaml') as path:
        if kind == 'calibration':
            only_own_errors(lambda: load(path))
        elif kind == 'model':
            only_own_errors(lambda: friction_model(str(path), small_telemetry(20)))
        else:
            only_own_errors(lambda: [block_values(read_parameters_file(path), s, path)
                                     for s in SCHEMAS.values()])
