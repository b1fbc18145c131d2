"""Writing benchmark results: JSON, plots, and one section of docs/results.md per bench."""

from __future__ import annotations

import datetime
import json
import os
import pathlib
import platform
import re
from typing import Any

import numpy as np

from rwa_monitor.telemetry.atomic import write_text_atomic

REPO = pathlib.Path(__file__).resolve().parents[1]
RESULTS_MD = REPO / 'docs' / 'results.md'
RESULTS_DIR = REPO / 'bench' / 'results'


def machine() -> dict[str, Any]:
    """Return the facts about this machine that a result depends on."""
    return {'python': platform.python_version(), 'cpus': os.cpu_count(),
            'platform': platform.platform(), 'numpy': np.__version__,
            'date': datetime.datetime.now(datetime.timezone.utc).isoformat(timespec='seconds')}


def _plain(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return _plain(value.tolist())
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


def write_json(out_dir: pathlib.Path, name: str, results: dict[str, Any]) -> pathlib.Path:
    """Write ``results`` (with machine facts) to ``out_dir/<name>.json``; return the path."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / f'{name}.json'
    text = json.dumps(_plain({'machine': machine(), **results}), indent=2) + '\n'
    write_text_atomic(path, text)
    return path


def update_section(name: str, markdown: str, path: pathlib.Path = RESULTS_MD) -> None:
    """Replace (or append) the section of docs/results.md between this bench's markers."""
    begin, end = f'<!-- BEGIN {name} -->', f'<!-- END {name} -->'
    block = f'{begin}\n{markdown.strip()}\n{end}'
    text = path.read_text() if path.exists() else '# Results\n'
    pattern = re.compile(re.escape(begin) + r'.*?' + re.escape(end), re.S)
    text = pattern.sub(lambda _: block, text) if pattern.search(text) else (
        text.rstrip() + '\n\n' + block + '\n')
    write_text_atomic(path, text)


def table(header: list[str], rows: list[list[Any]]) -> str:
    """Return a markdown table."""
    def cell(v: Any) -> str:
        return f'{v:.4g}' if isinstance(v, float) else str(v)
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(cell(v) for v in row) + ' |' for row in rows]
    return '\n'.join(lines)
