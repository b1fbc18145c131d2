"""Imports run one way: the import-linter contracts of .importlinter (docs/architecture.md)."""

import pathlib
import subprocess
import sys

from conftest import REPO


def test_import_contracts_are_kept():
    lint = pathlib.Path(sys.executable).parent / 'lint-imports'
    result = subprocess.run([str(lint), '--config', str(REPO / '.importlinter'),
                             '--no-cache'], cwd=REPO, capture_output=True, text=True)
    assert result.returncode == 0, result.stdout[-4000:] + result.stderr[-2000:]
    assert 'broken' in result.stdout and ' 0 broken' in result.stdout
