"""The golden before/after cases: seeded files and the commands whose events must not change.

``python test/golden_cases.py`` writes the files and the
expected JSON into test/data/golden/; run it only when a behaviour change is intended.
Each file is simulated from its seed, then its ``truth_*`` columns are dropped to keep it
small; the tests read the stored files, so a change of a simulator does not move them.
"""

from __future__ import annotations

import csv
import json
import pathlib
import sys
from typing import Any

GOLDEN = pathlib.Path(__file__).resolve().parent / 'data' / 'golden'
CONFIG = GOLDEN / 'golden.yaml'

# name -> `rwa-monitor simulate` arguments (without -o).
FILES = {
    'friction_step': ['friction', '--wheels', '2', '--seconds', '240', '--rate', '10',
                      '--profile', 'fig3', '--anomaly', 'rw1:dry:120:+4e-4',
                      '--anomaly', 'rw2:viscous:100:+2e-6', '--seed', '11'],
    'aocs_bias': ['aocs', '--seconds', '250', '--fault', 'bias', '--fault-axis', 'y',
                  '--fault-time', '150', '--seed', '12'],
    'fss_mixed': ['fss', '--status', 'fss1,dry', '--samples', '1500', '--seed', '13'],
}
# (command, file, arguments after the file); the output path is appended.
RUNS = [
    ('detect', 'friction_step', ['--config', str(CONFIG)]),
    ('detect', 'friction_step', []),
    ('detect', 'aocs_bias', ['--config', str(CONFIG)]),
    ('detect', 'fss_mixed', ['--config', str(CONFIG)]),
    ('diagnose', 'friction_step', ['--params-file', str(CONFIG)]),
    ('diagnose', 'fss_mixed', ['--params-file', str(CONFIG)]),
    ('diagnose', 'fss_mixed', []),
]
# Wall-clock measurements and the input path differ between runs: left out on purpose.
VOLATILE_KEYS = frozenset({'runtime_s', 'timings_s', 'source'})


def data_file(name: str) -> pathlib.Path:
    """Return the stored telemetry file of a case."""
    return GOLDEN / f'{name}.csv'


def expected_file(command: str, name: str, args: list[str]) -> pathlib.Path:
    """Return the stored JSON of one run."""
    tag = 'config' if args else 'defaults'
    return GOLDEN / f'{command}_{name}_{tag}.json'


def stable(document: Any) -> Any:
    """Return ``document`` without the keys of :data:`VOLATILE_KEYS` (recursively)."""
    if isinstance(document, dict):
        return {k: stable(v) for k, v in document.items() if k not in VOLATILE_KEYS}
    if isinstance(document, list):
        return [stable(v) for v in document]
    return document


def run(command: str, name: str, args: list[str], output: pathlib.Path) -> Any:
    """Run one command on a stored file; return its JSON without volatile keys."""
    from rwa_monitor.cli.main import main
    code = main([command, str(data_file(name)), *args, '-o', str(output)])
    # detect: 0 nothing found, 1 anomaly found, 3 not everything examined (docs/usage.md)
    assert code in (0, 1, 3), (command, name, code)
    return stable(json.loads(output.read_text()))


def _drop_truth(path: pathlib.Path) -> None:
    with open(path, newline='') as handle:
        rows = list(csv.reader(handle))
    keep = [i for i, col in enumerate(rows[0]) if not col.startswith('truth_')]
    with open(path, 'w', newline='') as handle:
        csv.writer(handle, lineterminator='\n').writerows([r[i] for i in keep] for r in rows)


def regenerate() -> None:
    """Simulate every file and write the expected JSON of every run."""
    from rwa_monitor.cli.main import main
    for name, argv in FILES.items():
        assert main(['simulate', *argv, '-o', str(data_file(name))]) == 0
        _drop_truth(data_file(name))
    for command, name, args in RUNS:
        out = expected_file(command, name, args)
        document = run(command, name, args, out)
        out.write_text(json.dumps(document, indent=1, sort_keys=True) + '\n')


if __name__ == '__main__':
    sys.exit(regenerate())
