"""Where the Open MCT bundle is, and how it gets there (docs/install.md, "Open MCT").

The bundle is the npm package ``openmct`` at the version pinned by ``npm/package-lock.json``
beside this module; it is never loaded from the network at run time. Looked for, in order:

1. ``$RWA_MONITOR_OPENMCT``: a folder that holds ``node_modules/openmct`` (or is it);
2. ``npm/node_modules/openmct`` beside this module: a clone after ``make openmct`` (the
   folder is ignored by git) or an editable install of it;
3. ``<data>/openmct/node_modules/openmct`` with ``<data>`` = ``$XDG_DATA_HOME/rwa_monitor``
   (``~/.local/share/rwa_monitor``): where ``rwa-monitor openmct --install`` puts it for
   a pip install, whose package holds the lock file but not the 58 MB bundle.

A folder whose ``openmct`` version differs from the lock's is passed over with a note.
"""

from __future__ import annotations

import json
import os
import pathlib
import shutil
import subprocess

from rwa_monitor.exceptions import ConfigError

HERE = pathlib.Path(__file__).resolve().parent
NPM_DIR = HERE / 'npm'
WEB_DIR = HERE / 'web'
ENV = 'RWA_MONITOR_OPENMCT'


def pinned_version() -> str:
    """Return the version of ``openmct`` that package-lock.json pins."""
    lock = json.loads((NPM_DIR / 'package-lock.json').read_text())
    return lock['packages']['node_modules/openmct']['version']


def data_dir() -> pathlib.Path:
    """Return the per-user folder for a pip install's bundle."""
    base = os.environ.get('XDG_DATA_HOME') or pathlib.Path.home() / '.local' / 'share'
    return pathlib.Path(base) / 'rwa_monitor' / 'openmct'


def candidates() -> list[pathlib.Path]:
    """Return the folders that may hold the ``openmct`` package, in the order tried."""
    found = []
    env = os.environ.get(ENV)
    if env:
        root = pathlib.Path(env).expanduser()
        found.append(root if (root / 'package.json').is_file() and root.name == 'openmct'
                     else root / 'node_modules' / 'openmct')
    found += [NPM_DIR / 'node_modules' / 'openmct', data_dir() / 'node_modules' / 'openmct']
    return found


def find_bundle() -> pathlib.Path:
    """Return the ``dist`` folder of the pinned Open MCT; ConfigError says how to install."""
    want = pinned_version()
    notes = []
    for package in candidates():
        meta = package / 'package.json'
        if not meta.is_file():
            continue
        try:
            version = json.loads(meta.read_text()).get('version')
        except (OSError, ValueError) as err:
            notes.append(f'{package}: unreadable package.json ({err})')
            continue
        if version != want:
            notes.append(f'{package}: version {version}, the lock pins {want}')
            continue
        if (package / 'dist' / 'openmct.js').is_file():
            return package / 'dist'
        notes.append(f'{package}: no dist/openmct.js')
    tried = ', '.join(str(p) for p in candidates())
    extra = f' ({"; ".join(notes)})' if notes else ''
    raise ConfigError(f'Open MCT {want} is not installed{extra}; looked in {tried}. In a '
                      f'clone run `make openmct`; after a pip install run '
                      f'`rwa-monitor openmct --install` (needs npm).')


def install(target: pathlib.Path | None = None) -> pathlib.Path:
    """Install the pinned bundle with ``npm ci`` into ``target`` (default: data_dir())."""
    target = data_dir() if target is None else target
    npm = shutil.which('npm')
    if npm is None:
        raise ConfigError('npm not found: install Node.js and npm, then run '
                          '`rwa-monitor openmct --install` again')
    target.mkdir(parents=True, exist_ok=True)
    for name in ('package.json', 'package-lock.json'):
        shutil.copyfile(NPM_DIR / name, target / name)
    done = subprocess.run([npm, 'ci', '--no-audit', '--no-fund', '--omit=dev'], cwd=target)
    if done.returncode != 0:
        raise ConfigError(f'npm ci in {target} failed (exit {done.returncode})')
    return target / 'node_modules' / 'openmct' / 'dist'
