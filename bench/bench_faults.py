"""``python -m bench faults``: every case of issues 24 and 36 as a scenario, its outcome tabled.

Cases come from ``bench/faults_files.py`` (outputs, names, journals, configuration,
fuzzed readers), ``bench/faults_nodes.py`` (node start-up, journal, replay) and, when
present, ``bench/faults_verdicts.py`` (honest verdicts) and ``bench/faults_audit.py``
(issue 36); each
module exposes ``CASES``: ``(name, scenario)`` pairs, ``scenario(folder)`` running in a
fresh temporary folder and returning a one-line outcome, raising AssertionError when the
behaviour is wrong. Any other exception is a failed case too (its type and message are
the outcome). Writes bench/results/faults.json and the reliability table (case, what
happens now, pass/fail) in section ``faults`` of docs/results.md, with the load average.
"""

from __future__ import annotations

import importlib
import os
import pathlib
import tempfile
import time
from typing import Any, Callable

from bench import report

MODULES = ('bench.faults_files', 'bench.faults_verdicts', 'bench.faults_nodes',
           'bench.faults_audit')


def collect() -> list[tuple[str, str, Callable[[pathlib.Path], str], str]]:
    """Return (module, case, scenario, command) of every case module present.

    ``command``: what a person runs to see the case (the module's ``COMMANDS``), or ''.
    """
    cases = []
    for name in MODULES:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name != name:
                raise
            continue
        commands = getattr(module, 'COMMANDS', {})
        cases += [(name.rsplit('.', 1)[-1], case, scenario, commands.get(case, ''))
                  for case, scenario in module.CASES]
    return cases


def run_case(scenario: Callable[[pathlib.Path], str]) -> tuple[bool, str, float]:
    """Run one scenario in a fresh folder; return (passed, outcome, seconds)."""
    start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix='rwa_fault_') as folder:
        try:
            outcome, passed = scenario(pathlib.Path(folder)), True
        except AssertionError as err:
            outcome, passed = f'WRONG: {err}', False
        except Exception as err:  # noqa: BLE001 - a crash of a scenario is a failed case
            outcome, passed = f'CRASH: {type(err).__name__}: {err}', False
        outcome = str(outcome).replace(folder + os.sep, '').replace(folder, '.')
    return passed, ' '.join(outcome.split())[:300], time.perf_counter() - start


def run(out_dir: pathlib.Path, quick: bool) -> dict[str, Any]:
    """Run every case; write faults.json and the ``faults`` section; return the results."""
    rows = []
    for module, case, scenario, command in collect():
        passed, outcome, seconds = run_case(scenario)
        rows.append({'module': module, 'case': case, 'command': command, 'outcome': outcome,
                     'passed': passed, 'seconds': seconds})
        print(f'  {"pass" if passed else "FAIL"}  {case}: {outcome}', flush=True)
    load = os.getloadavg()
    results = {'cases': rows, 'passed': sum(r['passed'] for r in rows), 'total': len(rows),
               'load_average': list(load)}
    report.write_json(out_dir, 'faults', results)
    table = report.table(['case', 'command', 'what happens now', 'result'],
                         [[r['case'], f'`{r["command"]}`' if r['command'] else '',
                           r['outcome'].replace('|', '/'),
                           'pass' if r['passed'] else '**FAIL**'] for r in rows])
    modules = sorted({r['module'] for r in rows})
    report.update_section('faults', f'''
## Reliability: the faults of issues 24 and 36

`python -m bench faults` runs each case of issues 24 and 36 as a scenario in a fresh folder
(cases from {", ".join(f"bench/{m}.py" for m in modules)});
a case fails when the behaviour is wrong or the scenario crashes.
{results["passed"]} of {results["total"]} pass. Load average during the run:
{load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1 / 5 / 15 min).

{table}
''')
    return results
